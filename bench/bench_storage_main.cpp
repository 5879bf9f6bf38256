// bench_storage record|read: the storage benchmarks of `imucal bench`, without the rest of the CLI.
#include <CLI/CLI.hpp>

#include "bench/storage_bench.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Storage benchmarks (the same as `imucal bench record|read`)"};
  imucal::bench::add_storage_bench_commands(app);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
