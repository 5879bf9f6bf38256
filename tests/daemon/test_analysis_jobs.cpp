// Analyses as jobs (issue 20): off the I/O threads, joined when asked twice, kept once done, and
// the daemon's status answering while one computes.
#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "daemon/analysis/analysis_jobs.hpp"
#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemon;
using namespace imucal::daemontest;
using Clock = std::chrono::steady_clock;

namespace {

AnalysisJobs::Key key(std::int64_t id, const std::string& what) {
  AnalysisJobs::Key k;
  k.campaign = id;
  k.analysis = what;
  k.state = "done";
  return k;
}

// Waits (without a time bound on the machine's speed, only a hang guard) for a ready answer.
AnalysisJobs::Answer wait_ready(AnalysisJobs& jobs, const AnalysisJobs::Key& k, const AnalysisJobs::Compute& c) {
  const auto deadline = Clock::now() + std::chrono::seconds(120);
  AnalysisJobs::Answer a = jobs.request(k, c);
  while (!a.ready && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    a = jobs.request(k, c);
  }
  return a;
}

}  // namespace

TEST(AnalysisJobs, ASecondRequestJoinsTheFirstAndTheAnswerIsKept) {
  std::atomic<int> computed{0};
  std::atomic<bool> release{false};
  std::vector<nlohmann::json> published;
  std::mutex published_mutex;
  AnalysisJobs jobs(1, 10, [&](const nlohmann::json& e) {
    std::lock_guard lock(published_mutex);
    published.push_back(e);
  });
  const AnalysisJobs::Compute compute = [&](const AnalysisJobs::Progress& progress) {
    ++computed;
    progress(0.5);
    while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return std::make_pair(200, nlohmann::json{{"answer", 42}});
  };
  const auto first = jobs.request(key(1, "allan"), compute);
  EXPECT_FALSE(first.ready);
  EXPECT_TRUE(first.pending.contains("progress"));
  // Joined: the job is queued or running, not started again.
  const auto second = jobs.request(key(1, "allan"), compute);
  EXPECT_FALSE(second.ready);
  // The job reports its progress: the poller sees it.
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  AnalysisJobs::Answer mid = jobs.request(key(1, "allan"), compute);
  while (mid.pending.value("progress", 0.0) < 0.5 && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    mid = jobs.request(key(1, "allan"), compute);
  }
  EXPECT_EQ(mid.pending.at("state"), "computing");
  EXPECT_DOUBLE_EQ(mid.pending.at("progress").get<double>(), 0.5);
  release = true;
  const auto done = wait_ready(jobs, key(1, "allan"), compute);
  ASSERT_TRUE(done.ready);
  EXPECT_EQ(done.status, 200);
  EXPECT_EQ(nlohmann::json::parse(done.body).at("answer"), 42);
  EXPECT_EQ(computed.load(), 1);
  // Kept: asked again, not computed again.
  EXPECT_TRUE(jobs.request(key(1, "allan"), compute).ready);
  EXPECT_EQ(computed.load(), 1);
  // Published for the live socket: queued or computing, then done, each tagged.
  std::lock_guard lock(published_mutex);
  ASSERT_GE(published.size(), 2u);
  EXPECT_EQ(published.back().at("type"), "analysis");
  EXPECT_EQ(published.back().at("state"), "done");
  EXPECT_EQ(published.back().at("campaign"), 1);
}

TEST(AnalysisJobs, AFailureIsAnAnswerAndOldAnswersGo) {
  AnalysisJobs jobs(2, 2, nullptr);
  const AnalysisJobs::Compute boom = [](const AnalysisJobs::Progress&) -> std::pair<int, nlohmann::json> {
    throw std::runtime_error("the run file is unreadable");
  };
  const auto a = wait_ready(jobs, key(7, "thermal"), boom);
  ASSERT_TRUE(a.ready);
  EXPECT_EQ(a.status, 500);
  EXPECT_NE(a.body.find("the run file is unreadable"), std::string::npos);
  std::atomic<int> n{0};
  const AnalysisJobs::Compute ok = [&](const AnalysisJobs::Progress&) {
    ++n;
    return std::make_pair(200, nlohmann::json::object());
  };
  for (std::int64_t id = 10; id < 13; ++id) ASSERT_TRUE(wait_ready(jobs, key(id, "allan"), ok).ready);
  EXPECT_EQ(n.load(), 3);
  // Two answers are kept: the oldest (campaign 7's, then 10's) were dropped and are computed again.
  EXPECT_FALSE(jobs.request(key(10, "allan"), ok).ready);
}

TEST(AnalysisJobs, StoppingCancelsARunningJob) {
  std::atomic<bool> started{false};
  auto jobs = std::make_unique<AnalysisJobs>(1, 4, nullptr);
  const AnalysisJobs::Compute endless = [&](const AnalysisJobs::Progress& progress) -> std::pair<int, nlohmann::json> {
    started = true;
    for (;;) {
      progress(0.1);  // throws Cancelled once the jobs are stopping
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  };
  EXPECT_FALSE(jobs->request(key(3, "evaluation"), endless).ready);
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  while (!started && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ASSERT_TRUE(started);
  jobs.reset();  // returns: the job stopped at its next progress report
  SUCCEED();
}
