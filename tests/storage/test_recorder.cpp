// Tests of the recorder and of the run database's writer guarantees: batches and commit cadence,
// backpressure (high water, drops, alarms, stored in the run), one writer at a time, a full disk,
// a damaged file, an unclean end, schema migration, and plot decimation.
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <new>
#include <random>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "storage/recorder.hpp"
#include "storage/run_db.hpp"
#include "storage/writer_lease.hpp"
#include "tests/storage/crash_frames.hpp"
#include "tests/test_paths.hpp"

namespace imucal::storage {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using test::expected_frame;

fs::path scratch_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return fs::path(imucaltest::test_tmp_dir()) / "storage" /
         (std::string(info->test_suite_name()) + "." + info->name() + "." + std::to_string(::getpid()));
}

class RecorderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::remove_all(scratch_dir());
    fs::create_directories(scratch_dir());
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(scratch_dir());
  }
  std::string path(const std::string& name = "run.db") const { return (scratch_dir() / name).string(); }
};

std::vector<ImuFrame> frames_from(std::int64_t first, std::int64_t n) {
  std::vector<ImuFrame> out;
  out.reserve(static_cast<std::size_t>(n));
  for (std::int64_t k = first; k < first + n; ++k) out.push_back(expected_frame(k));
  return out;
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

void expect_frames_identical(const std::vector<ImuFrame>& expected, const std::vector<ImuFrame>& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const ImuFrame& e = expected[i];
    const ImuFrame& a = actual[i];
    bool same = e.t_ns == a.t_ns;
    for (int k = 0; k < 3; ++k) {
      same = same && bits(e.dtheta_rad(k)) == bits(a.dtheta_rad(k)) && bits(e.dv_mps(k)) == bits(a.dv_mps(k)) &&
             bits(e.table_deg(k)) == bits(a.table_deg(k));
    }
    ASSERT_TRUE(same) << "frame " << i << " differs (t_ns " << e.t_ns << " vs " << a.t_ns << ")";
  }
}

template <class Fn>
std::string error_message(Fn&& fn) {
  try {
    fn();
  } catch (const StorageError& e) {
    return e.what();
  }
  return "(no StorageError thrown)";
}

// Collects alarms from any thread.
struct Alarms {
  std::mutex mutex;
  std::vector<RecorderAlarm> seen;
  Recorder::AlarmHandler handler() {
    return [this](const RecorderAlarm& a) {
      std::lock_guard lock(mutex);
      seen.push_back(a);
    };
  }
  int count(RecorderAlarmKind kind) {
    std::lock_guard lock(mutex);
    return static_cast<int>(std::count_if(seen.begin(), seen.end(), [&](const auto& a) { return a.kind == kind; }));
  }
  std::string message(RecorderAlarmKind kind) {
    std::lock_guard lock(mutex);
    for (const auto& a : seen) {
      if (a.kind == kind) return a.message;
    }
    return {};
  }
};

TEST_F(RecorderTest, RecordsEverythingOnceInOrderAndClosesTheSessionCleanly) {
  const auto frames = frames_from(0, 50'000);
  std::vector<TempSample> temps(5);
  for (std::size_t i = 0; i < temps.size(); ++i) temps[i].t_ns = static_cast<std::int64_t>(i) * 200'000'000;
  RecorderOptions options;
  options.commit_interval_s = 0.02;
  options.wait_when_full = true;
  options.queue_capacity_frames = 8192;  // smaller than the stream: the producer waits
  std::atomic<int> commits_seen{0};
  {
    Recorder recorder(RunDb::create(path(), test::crash_meta()), options, {},
                      [&](const RecorderStats&) { ++commits_seen; });
    std::size_t done = 0;
    std::mt19937 rng(1);
    std::uniform_int_distribution<std::size_t> batch(1, 9000);  // also batches above one block
    while (done < frames.size()) {
      const std::size_t n = std::min(batch(rng), frames.size() - done);
      ASSERT_EQ(recorder.push(std::span(frames).subspan(done, n)), Recorder::Push::Queued);
      done += n;
    }
    EXPECT_TRUE(recorder.push_temps(temps));
    EXPECT_TRUE(recorder.set_segments({{"s1", "static", 0.0, 0.5}}));
    EXPECT_TRUE(recorder.set_extra("note", R"({"ok": true})"));
    ASSERT_TRUE(recorder.commit_and_wait());
    const RecorderStats stats = recorder.stats();
    EXPECT_EQ(stats.committed_frames, 50'000);
    EXPECT_EQ(stats.accepted_frames, 50'000);
    EXPECT_EQ(stats.committed_t_ns, frames.back().t_ns);
    EXPECT_LE(stats.high_water_frames, options.queue_capacity_frames);
    EXPECT_EQ(stats.dropped_frames, 0);
    EXPECT_TRUE(recorder.close());
  }
  EXPECT_GE(commits_seen.load(), 1);
  EXPECT_FALSE(fs::exists(WriterLease::lease_path(path())));  // a clean close removes the lease
  const RunDb db = RunDb::open(path());
  EXPECT_FALSE(db.recovery().has_value());
  expect_frames_identical(frames, db.read_frames());
  EXPECT_EQ(db.temps().size(), temps.size());
  EXPECT_EQ(db.meta().segments.size(), 1U);
  EXPECT_EQ(db.extra("note"), std::optional<std::string>(R"({"ok": true})"));
  const auto sessions = db.sessions();
  ASSERT_EQ(sessions.size(), 1U);
  EXPECT_TRUE(sessions[0].closed_unix_ms.has_value());
  EXPECT_FALSE(sessions[0].unclean);
  EXPECT_EQ(sessions[0].committed_frames, 50'000);
  EXPECT_EQ(sessions[0].pid, ::getpid());
  EXPECT_GE(sessions[0].commits, 1);
}

TEST_F(RecorderTest, CommitsWithinTheIntervalWithoutBeingAsked) {
  RecorderOptions options;
  options.commit_interval_s = 0.05;
  Recorder recorder(RunDb::create(path(), test::crash_meta()), options);
  const auto frames = frames_from(0, 1000);  // far less than a chunk: only a commit writes them
  ASSERT_EQ(recorder.push(frames), Recorder::Push::Queued);
  // Another connection (as the estimators and the web plots use) sees the frames once committed.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  std::int64_t seen = 0;
  while (seen < 1000 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    seen = RunDb::open(path(), OpenMode::Read).frame_count();
  }
  EXPECT_EQ(seen, 1000);
  EXPECT_GE(recorder.stats().commits, 1);
  EXPECT_TRUE(recorder.close());
}

TEST_F(RecorderTest, AFullQueueDropsCountsAlarmsAndRecordsTheGap) {
  Alarms alarms;
  RecorderOptions options;
  options.commit_interval_s = 0.001;
  options.queue_capacity_frames = 8192;
  // The commit listener blocks the writer thread until the test lets it go: a writer that
  // stalls (a slow disk) while the device keeps delivering.
  std::mutex gate_mutex;
  std::condition_variable gate_cv;
  bool writer_stalled = false, release_writer = false;
  auto on_commit = [&](const RecorderStats&) {
    std::unique_lock lock(gate_mutex);
    writer_stalled = true;
    gate_cv.notify_all();
    gate_cv.wait(lock, [&] { return release_writer; });
  };
  Recorder recorder(RunDb::create(path(), test::crash_meta()), options, alarms.handler(), on_commit);
  ASSERT_EQ(recorder.push(frames_from(0, 100)), Recorder::Push::Queued);
  {
    std::unique_lock lock(gate_mutex);
    gate_cv.wait(lock, [&] { return writer_stalled; });
  }
  ASSERT_EQ(recorder.push(frames_from(100, 8000)), Recorder::Push::Queued);  // fills the queue
  EXPECT_EQ(alarms.count(RecorderAlarmKind::QueueHighWater), 1);
  EXPECT_EQ(recorder.push(frames_from(8100, 500)), Recorder::Push::Dropped);
  EXPECT_EQ(recorder.push(frames_from(8600, 500)), Recorder::Push::Dropped);  // one span, one alarm
  EXPECT_EQ(alarms.count(RecorderAlarmKind::FramesDropped), 1);
  EXPECT_THAT(alarms.message(RecorderAlarmKind::FramesDropped), HasSubstr("queue is full"));
  {
    std::lock_guard lock(gate_mutex);
    release_writer = true;
  }
  gate_cv.notify_all();
  const RecorderStats stats = recorder.stats();
  EXPECT_EQ(stats.dropped_frames, 1000);
  // The first 100 frames count until the stalled writer has them in the RunDb, or not.
  EXPECT_GE(stats.high_water_frames, 8000);
  EXPECT_LE(stats.high_water_frames, 8100);
  ASSERT_EQ(recorder.push(frames_from(9100, 100)), Recorder::Push::Queued);
  EXPECT_TRUE(recorder.close());
  const std::int64_t final_high_water = recorder.stats().high_water_frames;

  const RunDb db = RunDb::open(path());
  std::vector<ImuFrame> expected = frames_from(0, 8100);
  const auto tail = frames_from(9100, 100);
  expected.insert(expected.end(), tail.begin(), tail.end());
  expect_frames_identical(expected, db.read_frames());
  const auto spans = db.dropped_spans();
  ASSERT_EQ(spans.size(), 1U);
  EXPECT_EQ(spans[0].t0_ns, expected_frame(8100).t_ns);
  EXPECT_EQ(spans[0].t1_ns, expected_frame(9099).t_ns);
  EXPECT_EQ(spans[0].frames, 1000);
  const auto sessions = db.sessions();
  ASSERT_EQ(sessions.size(), 1U);
  EXPECT_EQ(sessions[0].dropped_frames, 1000);
  EXPECT_EQ(sessions[0].queue_high_water_frames, final_high_water);
}

TEST_F(RecorderTest, RejectsTimesThatDoNotIncrease) {
  Recorder recorder(RunDb::create(path(), test::crash_meta()));
  ASSERT_EQ(recorder.push(frames_from(10, 10)), Recorder::Push::Queued);
  EXPECT_EQ(recorder.push(frames_from(19, 2)), Recorder::Push::Rejected);  // frame 19 again
  EXPECT_EQ(recorder.push(frames_from(20, 2)), Recorder::Push::Queued);
  EXPECT_TRUE(recorder.close());
  EXPECT_EQ(recorder.push(frames_from(30, 1)), Recorder::Push::Failed);  // closed
  EXPECT_EQ(RunDb::open(path()).frame_count(), 12);
}

// A reader that finds a dead writer's run recovers it under the writer lease for a moment; a
// writer opening the run meanwhile (imucald resuming the run after a crash while a viewer's
// request opens it) waits for it instead of failing: the chaos soak of issue 33 saw the resumed
// run fail with "the run is being recorded by process ..." (the dead one).
TEST_F(RecorderTest, AWriterWaitsForAReaderThatHoldsTheLeaseForAMoment) {
  { RunDb::create(path(), test::crash_meta()); }
  auto held = WriterLease::acquire(path());  // what a recovering reader holds
  std::thread reader([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    held->release(true);
  });
  std::string failure;
  try {
    RunDb writer = RunDb::open(path(), OpenMode::Write);
    EXPECT_TRUE(writer.is_writer());
  } catch (const std::exception& e) {
    failure = e.what();
  }
  reader.join();
  EXPECT_EQ(failure, "");
}

TEST_F(RecorderTest, OneWriterAtATimeAndReadersAlongside) {
  Recorder recorder(RunDb::create(path(), test::crash_meta()));
  ASSERT_EQ(recorder.push(frames_from(0, 5000)), Recorder::Push::Queued);
  ASSERT_TRUE(recorder.commit_and_wait());
  const std::string second = error_message([&] { RunDb::open(path(), OpenMode::Write); });
  EXPECT_THAT(second, HasSubstr(path()));
  EXPECT_THAT(second, HasSubstr("being recorded by process " + std::to_string(::getpid())));
  // A reader (default mode) reads what is committed; its first write is refused clearly.
  RunDb reader = RunDb::open(path());
  EXPECT_FALSE(reader.recovery().has_value());  // the writer is alive: nothing to recover
  EXPECT_EQ(reader.frame_count(), 5000);
  EXPECT_THAT(error_message([&] { reader.append(frames_from(5000, 1)); }), HasSubstr("being recorded by process"));
  RunDb read_only = RunDb::open(path(), OpenMode::Read);
  EXPECT_THAT(error_message([&] { read_only.set_extra("x", "1"); }), HasSubstr("opened for reading only"));
  EXPECT_TRUE(recorder.close());
  // The writer gone, the run can be continued: a second session.
  {
    RunDb again = RunDb::open(path(), OpenMode::Write);
    again.append(frames_from(5000, 10));
  }
  const RunDb db = RunDb::open(path());
  EXPECT_EQ(db.frame_count(), 5010);
  ASSERT_EQ(db.sessions().size(), 2U);
  EXPECT_EQ(db.sessions()[1].frames_at_open, 5000);
  EXPECT_EQ(db.sessions()[1].committed_frames, 10);
}

TEST_F(RecorderTest, ContinuesARunAndCountsStoredFramesAcrossSessions) {
  {
    Recorder first(RunDb::create(path(), test::crash_meta()));
    ASSERT_EQ(first.push(frames_from(0, 700)), Recorder::Push::Queued);
    EXPECT_TRUE(first.close());
  }
  Recorder second(RunDb::open(path(), OpenMode::Write));
  EXPECT_EQ(second.stats().stored_frames, 700);
  // Refused at the push, against the frames already in the run, not later by the writer.
  EXPECT_EQ(second.push(frames_from(699, 1)), Recorder::Push::Rejected);
  ASSERT_EQ(second.push(frames_from(700, 300)), Recorder::Push::Queued);
  ASSERT_TRUE(second.commit_and_wait());
  EXPECT_EQ(second.stats().stored_frames, 1000);
  EXPECT_EQ(second.stats().committed_frames, 300);
  EXPECT_TRUE(second.close());
  expect_frames_identical(frames_from(0, 1000), RunDb::open(path()).read_frames());
}

// A file that reaches its size limit for good (SQLite's max_page_count): the recorder holds what
// it could not commit and refuses more; closed meanwhile, it gives up with a clear error and the
// next open counts exactly the frames it had accepted and never committed.
TEST_F(RecorderTest, ADiskThatStaysFullEndsWithTheHeldFramesCountedAsLost) {
  Alarms alarms;
  RunDb db = RunDb::create(path(), test::crash_meta());
  db.set_size_limit_bytes(3'000'000);  // ~55 k frames
  RecorderOptions options;
  options.commit_interval_s = 0.01;
  options.wait_when_full = true;
  Recorder recorder(std::move(db), options, alarms.handler());
  std::int64_t pushed = 0;
  Recorder::Push last = Recorder::Push::Queued;
  for (; pushed < 2'000'000; pushed += 1000) {
    last = recorder.push(frames_from(pushed, 1000));
    if (last != Recorder::Push::Queued) break;
    if (pushed % 20'000 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(15));  // several commits
  }
  ASSERT_LT(pushed, 2'000'000) << "the size limit never hit";
  EXPECT_EQ(last, Recorder::Push::Refused);
  const auto problem = recorder.write_problem();  // one reading: the writer thread may change it
  ASSERT_TRUE(problem.has_value());
  EXPECT_THAT(*problem, HasSubstr("disk full: at least"));
  EXPECT_THAT(*problem, HasSubstr("MB free needed"));
  EXPECT_FALSE(recorder.commit_and_wait());
  EXPECT_GT(recorder.stats().held_frames, 0);
  // The alarm is raised on the writer thread just after the problem is visible to push().
  for (int i = 0; i < 500 && alarms.count(RecorderAlarmKind::WriteHeld) == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(alarms.count(RecorderAlarmKind::WriteHeld), 1);

  EXPECT_FALSE(recorder.close());
  const auto error = recorder.error();
  ASSERT_TRUE(error.has_value());
  EXPECT_THAT(*error, HasSubstr("disk is full"));
  EXPECT_THAT(*error, HasSubstr(path()));
  EXPECT_THAT(*error, HasSubstr("closed while it held"));
  EXPECT_EQ(alarms.count(RecorderAlarmKind::WriteFailed), 1);
  const std::int64_t committed = recorder.stats().committed_frames;
  EXPECT_GT(committed, 0);

  // The next open finds the session unclosed, checks the file and accounts for the loss.
  const RunDb reopened = RunDb::open(path());
  const auto& recovery = reopened.recovery();
  ASSERT_TRUE(recovery.has_value());
  EXPECT_EQ(recovery->integrity, "ok");
  const auto stored = reopened.read_frames();
  EXPECT_EQ(static_cast<std::int64_t>(stored.size()), committed);
  expect_frames_identical(frames_from(0, committed), stored);
  const auto lost = recovery->lost_uncommitted_frames;
  ASSERT_TRUE(lost.has_value());
  EXPECT_EQ(*lost, recorder.stats().accepted_frames - committed);
  EXPECT_GT(*lost, 0);
}

// The producer of the full-disk test: frames pushed in batches, the disk made full after 100,000,
// emptied again once the recorder has refused three times (with what it holds checked then); after
// each refusal the producer takes up after the last frame the recorder holds. Whether the disk was
// filled and emptied; a failure (a push neither queued nor refused, no progress for 60 s) is
// reported and ends the run.
struct FullDiskRun {
  bool filled = false, emptied = false;
};

// The first frame after the last one the recorder holds (the producer's restart after a refusal).
std::int64_t first_frame_not_taken(const Recorder& recorder, std::int64_t frames) {
  const auto taken = recorder.last_accepted_t_ns();
  if (!taken) {
    ADD_FAILURE() << "a refusal before any frame was taken";
    return frames;
  }
  const std::int64_t taken_t_ns = *taken;
  std::int64_t next = 0;
  while (next < frames && expected_frame(next).t_ns <= taken_t_ns) ++next;
  return next;
}

FullDiskRun push_through_a_full_disk(Recorder& recorder, const RecorderOptions& options, std::int64_t frames) {
  constexpr std::int64_t kBatch = 1000;
  FullDiskRun run;
  std::int64_t next = 0;  // the first frame not yet taken by the recorder
  int refusals = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (next < frames) {
    if (std::chrono::steady_clock::now() >= deadline) {
      ADD_FAILURE() << "no progress; next frame " << next;
      return run;
    }
    if (!run.filled && next >= 100'000) {
      run.filled = true;
      disk_fault::set_full(true);
    }
    const auto pushed = recorder.push(frames_from(next, std::min(kBatch, frames - next)));
    if (pushed == Recorder::Push::Queued) {
      next += std::min(kBatch, frames - next);
      continue;
    }
    if (pushed != Recorder::Push::Refused) {
      ADD_FAILURE() << "a push neither queued nor refused at frame " << next;
      return run;
    }
    ++refusals;
    next = first_frame_not_taken(recorder, frames);
    if (!run.emptied && refusals >= 3) {
      // Still held after several failed attempts: nothing lost, nothing committed meanwhile.
      EXPECT_GT(recorder.stats().held_frames, 0);
      EXPECT_LE(recorder.stats().queued_frames, options.queue_capacity_frames);
      EXPECT_FALSE(recorder.commit_and_wait());
      std::this_thread::sleep_for(std::chrono::milliseconds(200));  // a few failed retries
      run.emptied = true;
      disk_fault::set_full(false);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return run;
}

// The run file after the full disk: every frame once, in one clean writer session.
void expect_every_frame_once(const std::string& path, std::int64_t frames) {
  const RunDb db = RunDb::open(path, OpenMode::Read);
  EXPECT_FALSE(db.recovery().has_value());
  ASSERT_EQ(db.sessions().size(), 1u);
  EXPECT_FALSE(db.sessions().front().unclean);
  expect_frames_identical(frames_from(0, frames), db.read_frames());
}

// The disk made full (storage::disk_fault, the VFS every connection goes through) while frames
// stream in, then given space again: the recorder holds the failed batch and what was queued,
// refuses the rest (the producer supplies it again from last_accepted_t_ns(), as the daemon's redo
// does), and once space is back the run holds every frame exactly once, in one writer session.
TEST_F(RecorderTest, AFullDiskHoldsTheUncommittedFramesAndWritesThemOnceSpaceReturns) {
  struct Restore {
    ~Restore() { disk_fault::set_full(false); }
  } restore;
  Alarms alarms;
  RecorderOptions options;
  options.commit_interval_s = 0.01;
  options.retry_interval_s = 0.05;
  options.wait_when_full = true;
  options.queue_capacity_frames = 65'536;
  std::atomic<int> commits{0};
  Recorder recorder(RunDb::create(path(), test::crash_meta()), options, alarms.handler(),
                    [&](const RecorderStats&) { ++commits; });
  constexpr std::int64_t kFrames = 400'000;
  const FullDiskRun run = push_through_a_full_disk(recorder, options, kFrames);
  ASSERT_TRUE(run.filled && run.emptied) << "the disk was never made full while recording";
  EXPECT_TRUE(recorder.commit_and_wait());
  EXPECT_FALSE(recorder.write_problem().has_value());
  EXPECT_TRUE(recorder.close());
  EXPECT_EQ(alarms.count(RecorderAlarmKind::WriteHeld), 1);
  EXPECT_THAT(alarms.message(RecorderAlarmKind::WriteHeld), HasSubstr("disk full: at least"));
  EXPECT_EQ(alarms.count(RecorderAlarmKind::WriteFailed), 0);
  EXPECT_EQ(recorder.stats().dropped_frames, 0);
  expect_every_frame_once(path(), kFrames);
}

TEST_F(RecorderTest, UncleanEndIsRecoveredWithIntegrityCheckAndLossReport) {
  // A writer that dies: the RunDb is leaked with its lease released as a crash leaves it (the
  // kernel drops the lock; the lease page stays).
  {
    RunDb db = RunDb::create(path(), test::crash_meta());
    db.append(frames_from(0, 10'000));  // two chunks committed, 1808 frames buffered
    db.lease()->release(false);
    // Never destroyed (no flush, no session close -- as after kill -9); kept in static storage so
    // that the leak checker sees it reachable.
    alignas(RunDb) static unsigned char crashed[sizeof(RunDb)];
    new (crashed) RunDb(std::move(db));
  }
  const RunDb db = RunDb::open(path(), OpenMode::Read);
  const auto& recovery = db.recovery();
  ASSERT_TRUE(recovery.has_value());
  EXPECT_EQ(recovery->pid, ::getpid());
  EXPECT_EQ(recovery->committed_frames, 8192);
  EXPECT_EQ(recovery->lost_uncommitted_frames, std::optional<std::int64_t>(10'000 - 8192));
  EXPECT_EQ(recovery->accepted_t_ns, std::optional<std::int64_t>(expected_frame(9999).t_ns));
  EXPECT_EQ(db.frame_count(), 8192);
  const auto sessions = db.sessions();
  ASSERT_EQ(sessions.size(), 1U);
  EXPECT_TRUE(sessions[0].unclean);
  EXPECT_EQ(sessions[0].integrity, "ok");
  EXPECT_EQ(sessions[0].lost_uncommitted_frames, std::optional<std::int64_t>(1808));
  // Recovered once: the next open has nothing to do.
  EXPECT_FALSE(RunDb::open(path()).recovery().has_value());
}

TEST_F(RecorderTest, ADamagedFileIsAClearErrorAndIsLeftAsItIs) {
  {
    RunDb db = RunDb::create(path(), test::crash_meta());
    db.append(frames_from(0, 100'000));
    db.flush();
  }
  // Mark an unclean end (as a dead writer leaves it), then overwrite a b-tree page.
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path().c_str(), &raw), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(raw, "UPDATE recorder_session SET closed_unix_ms = NULL", nullptr, nullptr, nullptr),
            SQLITE_OK);
  int page_bytes = 0;
  {
    sqlite3_stmt* stmt = nullptr;
    sqlite3_prepare_v2(raw, "PRAGMA page_size", -1, &stmt, nullptr);
    sqlite3_step(stmt);
    page_bytes = sqlite3_column_int(stmt, 0);
    sqlite3_finalize(stmt);
  }
  sqlite3_close(raw);
  {
    std::fstream file(path(), std::ios::in | std::ios::out | std::ios::binary);
    // Page 2 onward holds tables and chunk data; garbage over a page header breaks the b-tree.
    for (int page : {2, 3, 4}) {
      file.seekp(static_cast<std::streamoff>(page - 1) * page_bytes);
      const std::string garbage(64, '\xA5');
      file.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
    }
  }
  const auto size_before = fs::file_size(path());
  std::string message;
  try {
    const RunDb db = RunDb::open(path());
    message = "(opened)";
    db.read_frames();  // if the damage escaped the open, reading must report it
  } catch (const StorageError& e) {
    message = e.what();
  }
  EXPECT_THAT(message, HasSubstr(path()));
  EXPECT_THAT(message, ::testing::AnyOf(HasSubstr("integrity_check"), HasSubstr("damaged")));
  EXPECT_EQ(fs::file_size(path()), size_before);
}

TEST_F(RecorderTest, MigratesAVersion1File) {
  const auto frames = frames_from(0, 9000);
  {
    RunDb db = RunDb::create(path(), test::crash_meta());
    db.append(frames);
  }
  // Turn it into what imucal wrote before version 2.
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path().c_str(), &raw), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(raw,
                         "DROP TABLE recorder_session; DROP TABLE dropped_span; "
                         "ALTER TABLE imu_chunk DROP COLUMN summary; ALTER TABLE temp_sample DROP COLUMN "
                         "coil_sensors_C; PRAGMA user_version = 1;",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(raw);

  {
    RunDb db = RunDb::open(path());
    expect_frames_identical(frames, db.read_frames());
    EXPECT_TRUE(db.sessions().empty());
    // v1 chunks have no summary: the plot decodes them and still gets the right extremes.
    const auto columns = db.decimate(frames.front().t_ns, frames.back().t_ns + 1, 3);
    double max_dv_x = -1e300;
    for (const auto& f : frames) max_dv_x = std::max(max_dv_x, f.dv_mps.x());
    EXPECT_EQ(std::max({columns[0].max[3], columns[1].max[3], columns[2].max[3]}), max_dv_x);
    db.append(frames_from(9000, 10));
  }
  raw = nullptr;
  ASSERT_EQ(sqlite3_open(path().c_str(), &raw), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(raw, "PRAGMA user_version", -1, &stmt, nullptr);
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_EQ(sqlite3_column_int(stmt, 0), RunDb::kSchemaVersion);
  sqlite3_finalize(stmt);
  sqlite3_close(raw);
  EXPECT_EQ(RunDb::open(path()).frame_count(), 9010);
}

TEST_F(RecorderTest, DecimationMatchesBruteForceMinMax) {
  const auto frames = frames_from(0, 30'000);
  RunDb db = RunDb::create(path(), test::crash_meta());
  db.append(std::span(frames).first(29'000));
  db.flush();                                 // an open, partial chunk row
  db.append(std::span(frames).subspan(29'000));  // and frames only in the buffer
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<std::int64_t> t(0, frames.back().t_ns + 50'000);
  for (int trial = 0; trial < 40; ++trial) {
    std::int64_t a = t(rng), b = t(rng);
    if (a > b) std::swap(a, b);
    if (a == b) ++b;
    const int columns = trial == 0 ? 1 : 1 + static_cast<int>(rng() % 700);
    if (trial == 1) {  // the whole run into few columns: the summary path
      a = frames.front().t_ns;
      b = frames.back().t_ns + 1;
    }
    const auto got = db.decimate(a, b, columns);
    ASSERT_EQ(got.size(), static_cast<std::size_t>(columns));
    EXPECT_EQ(got.front().t0_ns, a);
    EXPECT_EQ(got.back().t1_ns, b);
    for (const auto& column : got) {
      PlotColumn want;
      want.min.fill(std::numeric_limits<double>::infinity());
      want.max.fill(-std::numeric_limits<double>::infinity());
      for (const auto& f : frames) {
        if (f.t_ns < column.t0_ns || f.t_ns >= column.t1_ns) continue;
        const std::array<double, 9> v = {f.dtheta_rad.x(), f.dtheta_rad.y(), f.dtheta_rad.z(),
                                         f.dv_mps.x(),     f.dv_mps.y(),     f.dv_mps.z(),
                                         f.table_deg.x(),  f.table_deg.y(),  f.table_deg.z()};
        for (std::size_t c = 0; c < 9; ++c) {
          want.min[c] = std::min(want.min[c], v[c]);
          want.max[c] = std::max(want.max[c], v[c]);
        }
        ++want.frames;
      }
      ASSERT_EQ(column.frames, want.frames) << "column [" << column.t0_ns << ", " << column.t1_ns << ")";
      if (want.frames == 0) continue;
      for (std::size_t c = 0; c < 9; ++c) {
        ASSERT_EQ(column.min[c], want.min[c]) << "channel " << c;
        ASSERT_EQ(column.max[c], want.max[c]) << "channel " << c;
      }
    }
  }
  EXPECT_THAT(error_message([&] { db.decimate(10, 10, 5); }), HasSubstr("non-empty"));
  EXPECT_THAT(error_message([&] { db.decimate(0, 10, 0); }), HasSubstr("positive"));
}

}  // namespace
}  // namespace imucal::storage
