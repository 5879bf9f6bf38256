// Crash test of the recorder: a writer process (storage_crash_writer) records a deterministic
// stream into one run and is killed with SIGKILL at random moments, IMUCAL_CRASH_KILLS times; the
// next writer continues the same run. After every kill the run must open (the open recovers it:
// full integrity_check), hold every frame up to the last commit exactly once and bit for bit,
// and report how many accepted frames were lost: at most one commit interval's worth plus what
// arrived while the slowest commit of that writer ran (frames queue meanwhile and join the next
// batch), plus a small allowance for scheduling. The commit's duration is the writer's own report:
// on a loaded machine a commit took a fifth of a second, and a bound in wall time alone failed.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "storage/run_db.hpp"
#include "tests/storage/crash_frames.hpp"
#include "tests/test_paths.hpp"

extern char** environ;

namespace imucal::storage {
namespace {

namespace fs = std::filesystem;

constexpr double kCommitIntervalS = 0.25;
constexpr double kRateHz = 20'000.0;
// A writer thread that a loaded two-core machine schedules late.
constexpr double kAllowanceS = 0.1;

struct Child {
  pid_t pid = -1;
  int out_fd = -1;
};

Child spawn_writer(const std::string& run) {
  int fds[2];
  if (::pipe(fds) != 0) throw std::runtime_error("pipe failed");
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
  posix_spawn_file_actions_addclose(&actions, fds[0]);
  posix_spawn_file_actions_addclose(&actions, fds[1]);
  const std::string interval = std::to_string(kCommitIntervalS), rate = std::to_string(kRateHz);
  std::vector<char*> argv = {const_cast<char*>(imucaltest::program("storage_crash_writer").c_str()), const_cast<char*>("record"),
                             const_cast<char*>(run.c_str()), const_cast<char*>(interval.c_str()),
                             const_cast<char*>(rate.c_str()), nullptr};
  Child child;
  const int rc = ::posix_spawn(&child.pid, imucaltest::program("storage_crash_writer").c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  if (rc != 0) throw std::runtime_error("posix_spawn failed");
  child.out_fd = fds[0];
  return child;
}

// Everything the child printed (it is dead: read to EOF).
std::string drain(int fd) {
  std::string out;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof(buf));
    if (n <= 0) break;
    out.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return out;
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

bool same(const ImuFrame& a, const ImuFrame& b) {
  if (a.t_ns != b.t_ns) return false;
  for (int k = 0; k < 3; ++k) {
    if (bits(a.dtheta_rad(k)) != bits(b.dtheta_rad(k)) || bits(a.dv_mps(k)) != bits(b.dv_mps(k)) ||
        bits(a.table_deg(k)) != bits(b.table_deg(k))) {
      return false;
    }
  }
  return true;
}

void kill_at_random_moments() {
  const fs::path dir = fs::path(imucaltest::test_tmp_dir()) / "storage" / ("crash." + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string run = (dir / "run.db").string();
  { RunDb created = RunDb::create(run, test::crash_meta()); }

  std::mt19937 rng(IMUCAL_CRASH_SEED);
  std::uniform_int_distribution<int> kill_after_ms(30, 1000);
  double worst_lost_intervals = 0.0;
  std::int64_t total_lost = 0;
  int recoveries = 0;

  for (int cycle = 0; cycle < IMUCAL_CRASH_KILLS; ++cycle) {
    SCOPED_TRACE("kill " + std::to_string(cycle + 1));
    Child child = spawn_writer(run);
    std::this_thread::sleep_for(std::chrono::milliseconds(kill_after_ms(rng)));
    ::kill(child.pid, SIGKILL);
    int status = 0;
    ::waitpid(child.pid, &status, 0);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the writer ended by itself (status " << status << ")";
    const std::string out = drain(child.out_fd);
    bool ready = false;
    std::int64_t reported_accepted = 0, reported_committed = 0;
    double slowest_commit_s = 0.0;
    std::istringstream lines(out);
    for (std::string line; std::getline(lines, line);) {
      std::istringstream words(line);
      std::string word;
      std::int64_t value = 0;
      words >> word >> value;
      if (word == "ready") {
        ready = true;
        reported_accepted = value;
      }
      if (word == "accepted") reported_accepted = std::max(reported_accepted, value);
      double took_s = 0.0;
      if (word == "committed" && (words >> took_s)) {
        reported_committed = std::max(reported_committed, value);
        slowest_commit_s = std::max(slowest_commit_s, took_s);
      }
    }

    // The open recovers: integrity_check (it throws on a damaged file), then the loss report.
    const RunDb db = RunDb::open(run, OpenMode::Read);
    const std::int64_t frames = db.frame_count();
    std::int64_t k = 0;
    bool all_match = true;
    db.for_each_block([&](std::span<const ImuFrame> block) {
      for (const auto& f : block) {
        if (all_match && !same(f, test::expected_frame(k))) {
          ADD_FAILURE() << "frame " << k << " is not the expected one (t_ns " << f.t_ns << ")";
          all_match = false;
        }
        ++k;
      }
    });
    ASSERT_TRUE(all_match);
    ASSERT_EQ(k, frames);
    // A commit the writer reported survived its death.
    EXPECT_GE(frames, reported_committed);
    if (!ready) continue;  // killed before it became the writer: nothing to recover
    ASSERT_TRUE(db.recovery().has_value()) << "a writer died but open() reported no recovery";
    const RecoveryReport& rec = *db.recovery();
    ++recoveries;
    EXPECT_EQ(rec.integrity, "ok");
    ASSERT_TRUE(rec.lost_uncommitted_frames.has_value());
    const std::int64_t lost = *rec.lost_uncommitted_frames;
    // The report never undercounts what the writer told us it had accepted.
    EXPECT_GE(frames + lost, reported_accepted);
    EXPECT_LE(static_cast<double>(lost), kRateHz * (kCommitIntervalS + slowest_commit_s + kAllowanceS))
        << lost << " frames lost; one commit interval is " << kRateHz * kCommitIntervalS
        << ", the slowest commit took " << slowest_commit_s << " s";
    worst_lost_intervals = std::max(worst_lost_intervals, static_cast<double>(lost) / (kRateHz * kCommitIntervalS));
    total_lost += lost;
    const auto sessions = db.sessions();
    ASSERT_FALSE(sessions.empty());
    EXPECT_TRUE(sessions.back().unclean);
    EXPECT_EQ(sessions.back().lost_uncommitted_frames, lost);
  }
  std::printf("%d kills, %d recoveries, %lld frames lost in all, worst %.2f commit intervals\n", IMUCAL_CRASH_KILLS,
              recoveries, static_cast<long long>(total_lost), worst_lost_intervals);
  ::testing::Test::RecordProperty("worst_lost_commit_intervals", std::to_string(worst_lost_intervals));
  EXPECT_GT(recoveries, IMUCAL_CRASH_KILLS / 2);
  if (!::testing::Test::HasFailure()) fs::remove_all(dir);
}

// Distinct names, so that ctest tells the two builds of this file apart.
#if IMUCAL_CRASH_KILLS > 20
TEST(RecorderCrashLong, KillNineManyTimes) { kill_at_random_moments(); }
#else
TEST(RecorderCrash, KillNineAtRandomMomentsLosesAtMostOneCommitInterval) { kill_at_random_moments(); }

TEST(RecorderCrash, SecondProcessGetsAClearErrorWhileAWriterRecords) {
  const fs::path dir = fs::path(imucaltest::test_tmp_dir()) / "storage" / ("second." + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string run = (dir / "run.db").string();
  { RunDb created = RunDb::create(run, test::crash_meta()); }
  Child writer = spawn_writer(run);
  // Wait for "ready": the writer holds the run from then on.
  std::string seen;
  char c = 0;
  while (seen.find("ready") == std::string::npos && ::read(writer.out_fd, &c, 1) == 1) seen.push_back(c);

  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
  posix_spawn_file_actions_addclose(&actions, fds[0]);
  posix_spawn_file_actions_addclose(&actions, fds[1]);
  std::vector<char*> argv = {const_cast<char*>(imucaltest::program("storage_crash_writer").c_str()), const_cast<char*>("try-write"),
                             const_cast<char*>(run.c_str()), nullptr};
  pid_t second = -1;
  ASSERT_EQ(::posix_spawn(&second, imucaltest::program("storage_crash_writer").c_str(), &actions, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  int status = 0;
  ::waitpid(second, &status, 0);
  const std::string message = drain(fds[0]);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 3) << "status " << status << ": " << message;
  EXPECT_NE(message.find("being recorded by process " + std::to_string(writer.pid)), std::string::npos) << message;

  // A reader in a third place (this process) still reads while the writer records.
  {
    const RunDb reader = RunDb::open(run);
    EXPECT_GE(reader.frame_count(), 0);
  }
  ::kill(writer.pid, SIGKILL);
  ::waitpid(writer.pid, &status, 0);
  drain(writer.out_fd);
  if (!HasFailure()) fs::remove_all(dir);
}
#endif

}  // namespace
}  // namespace imucal::storage
