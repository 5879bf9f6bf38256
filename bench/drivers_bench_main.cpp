// imucal_drivers_bench: a simulated campaign through the three real drivers at full IMU rate
// (bench/bench_campaign.hpp). Not run in CI; its figures go to docs/drivers.md.
#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>

#include "bench/bench_campaign.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Simulated campaign through the table, chamber and IMU drivers on loopback"};
  imucal::bench::CampaignOptions o;
  app.add_option("--duration", o.duration_s, "seconds of campaign")->check(CLI::PositiveNumber);
  app.add_option("--rate", o.imu_rate_hz, "IMU rate, Hz (above 200 Hz: CAN FD)")->check(CLI::PositiveNumber);
  app.add_option("--table-read-rate", o.table_read_hz, "table position reads per second")->check(CLI::PositiveNumber);
  app.add_flag("--progress", o.progress, "a line every 10 s");
  CLI11_PARSE(app, argc, argv);
  try {
    const auto r = imucal::bench::run_driver_campaign(o);
    std::printf("%s", r.to_text().c_str());
    return r.imu_lost == 0 && r.imu_crc_failures == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "imucal_drivers_bench: %s\n", e.what());
    return 2;
  }
}
