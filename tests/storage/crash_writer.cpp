// Helper process of the storage tests (not a test itself):
//
//   storage_crash_writer record RUN COMMIT_INTERVAL_S RATE_HZ
//     Opens RUN for writing (recovering it if the last writer died), continues the deterministic
//     frame sequence (frame k is expected_frame(k), see crash_frames.hpp) from the frames already
//     in the run, and records paced at RATE_HZ with a storage::Recorder until it is killed.
//     After every push it prints "accepted K" (frames accepted so far in the run) on stdout, and
//     after every commit "committed K S" (frames in the run after it, seconds the commit took).
//   storage_crash_writer try-write RUN
//     Tries to become RUN's writer; prints the error and exits 3 when another writer holds it,
//     exits 0 when it could write.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "storage/recorder.hpp"
#include "storage/run_db.hpp"
#include "tests/storage/crash_frames.hpp"

using namespace imucal;

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "try-write") {
    try {
      storage::RunDb db = storage::RunDb::open(argv[2], storage::OpenMode::Write);
      return 0;
    } catch (const storage::StorageError& e) {
      std::printf("%s\n", e.what());
      return 3;
    }
  }
  if (argc != 5 || std::string(argv[1]) != "record") {
    std::fprintf(stderr, "usage: storage_crash_writer record RUN COMMIT_INTERVAL_S RATE_HZ | try-write RUN\n");
    return 2;
  }
  const std::string path = argv[2];
  const double interval_s = std::atof(argv[3]);
  const double rate_hz = std::atof(argv[4]);
  try {
    storage::RunDb db = storage::RunDb::open(path, storage::OpenMode::Write);
    std::int64_t k = db.frame_count();
    storage::RecorderOptions options;
    options.commit_interval_s = interval_s;
    options.wait_when_full = true;
    storage::Recorder recorder(std::move(db), options, {}, [](const storage::RecorderStats& stats) {
      std::printf("committed %lld %.6f\n", static_cast<long long>(stats.stored_frames), stats.last_commit_s);
      std::fflush(stdout);
    });
    std::printf("ready %lld\n", static_cast<long long>(k));
    std::fflush(stdout);
    // Batches every 5 ms of wall time, as a device reader would hand them over.
    const auto period = std::chrono::milliseconds(5);
    const auto batch = static_cast<std::int64_t>(rate_hz * 0.005);
    auto next = std::chrono::steady_clock::now();
    std::vector<ImuFrame> frames;
    for (;;) {
      frames.clear();
      for (std::int64_t i = 0; i < batch; ++i) frames.push_back(test::expected_frame(k + i));
      if (recorder.push(frames) != storage::Recorder::Push::Queued) {
        std::fprintf(stderr, "push failed: %s\n", recorder.error().value_or("?").c_str());
        return 1;
      }
      k += batch;
      std::printf("accepted %lld\n", static_cast<long long>(k));
      std::fflush(stdout);
      next += period;
      std::this_thread::sleep_until(next);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "storage_crash_writer: %s\n", e.what());
    return 1;
  }
}
