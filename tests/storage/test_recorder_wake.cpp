// A batch larger than the queue's room, pushed while the recorder's writer is idle (no batch open,
// so no commit deadline wakes it): the writer is woken by each slice queued and makes room for the
// next. Found as a hang of RecorderTest.RecordsEverythingOnceInOrderAndClosesTheSessionCleanly on a
// loaded machine (2026-11-29): the producer waited for room while the writer slept, never told of
// the slices before. (A file of its own: test_recorder.cpp is a long analysis for the static check.)
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <future>
#include <span>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "storage/recorder.hpp"
#include "storage/run_db.hpp"
#include "tests/storage/crash_frames.hpp"
#include "tests/test_paths.hpp"

namespace imucal::storage {
namespace {

TEST(RecorderWake, ABatchLargerThanTheQueueWakesAnIdleWriter) {
  const std::filesystem::path dir =
      std::filesystem::path(imucaltest::test_tmp_dir()) / "storage" / ("recorder-wake." + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::int64_t block = RunDb::kFramesPerChunk;
  std::vector<ImuFrame> frames;
  for (std::int64_t k = 0; k < 3 * block; ++k) frames.push_back(test::expected_frame(k));
  RecorderOptions options;
  options.commit_interval_s = 0.02;
  options.wait_when_full = true;
  options.queue_capacity_frames = 2 * block;  // two slices fit, the third waits for room
  Recorder recorder(RunDb::create((dir / "run.db").string(), test::crash_meta()), options, {}, {});
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the writer asleep, nothing queued
  auto pushed = std::async(std::launch::async, [&] { return recorder.push(std::span(frames)); });
  if (pushed.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
    ADD_FAILURE() << "the push of 3 blocks into a queue of 2 waited 60 s for room the idle writer never made";
    (void)recorder.close();  // closing wakes the producer (Push::Failed)
  }
  EXPECT_EQ(pushed.get(), Recorder::Push::Queued);
  ASSERT_TRUE(recorder.commit_and_wait());
  EXPECT_EQ(recorder.stats().committed_frames, 3 * block);
  EXPECT_TRUE(recorder.close());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace imucal::storage
