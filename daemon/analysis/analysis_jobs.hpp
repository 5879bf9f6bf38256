// The results computed from a finished run (Allan deviation, thermal plots, Schuler test, the
// recording bundle, a recalibration) and a campaign's plan as jobs:
// on threads of their own, never on the HTTP I/O threads (a 2 h run at 200 Hz takes seconds, and
// every request and live socket of every operator would wait behind it). A request either finds
// the answer ready, or starts the job (or joins the one already running for the same key) and
// is told how far it has come; the caller asks again. Answers are kept, a bounded number of them.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

namespace imucal::daemon {

class AnalysisJobs {
 public:
  // What identifies an answer: the campaign, the analysis, and the run's state (an interrupted
  // run that is resumed later gets a fresh answer).
  struct Key {
    std::int64_t campaign = 0;
    std::string analysis, state;
    auto operator<=>(const Key&) const = default;
  };
  // Reports the fraction done (0..1); throws Cancelled when the daemon is stopping.
  using Progress = std::function<void(double fraction)>;
  // The HTTP status and body of the answer.
  using Compute = std::function<std::pair<int, nlohmann::json>(const Progress& progress)>;
  struct Cancelled : std::exception {
    const char* what() const noexcept override { return "the daemon is stopping"; }
  };

  struct Answer {
    bool ready = false;
    int status = 0;          // ready: the answer's status
    std::string body;        // ready: the answer's body
    nlohmann::json pending;  // not ready: {"state": "queued"|"computing", "progress", "elapsed_s", "queue_position"}
  };

  // `publish`: each job's state and progress as it changes (the live WebSocket), from a job thread.
  // `max_pending`: jobs queued or computing at once; a request that would start one more is
  // answered 429 at once (a client cannot pile up work, each job holding a run's worth of memory).
  AnalysisJobs(int threads, std::size_t kept_answers, std::function<void(const nlohmann::json&)> publish,
               std::size_t max_pending = 16);
  ~AnalysisJobs();  // running jobs are cancelled at their next progress report; queued ones dropped
  AnalysisJobs(const AnalysisJobs&) = delete;
  AnalysisJobs& operator=(const AnalysisJobs&) = delete;

  // The answer for `key` if it is ready; else starts `compute` (unless a job for the key is queued
  // or running: then joins it) and says how far it is.
  Answer request(const Key& key, Compute compute);
  // The answer for `key`, or how far its job has come, when there is one (queued, running or
  // kept); starts nothing. For a request whose preconditions its own answer changes (a
  // recalibration supersedes the certificate that called for it): asked again, it finds its answer.
  std::optional<Answer> find(const Key& key) const;
  // Drops the finished answer kept for `key` (a job queued or running stays): for a job whose
  // answer lives elsewhere (the recording bundle is a file), so that a failure is tried again
  // at the next request rather than repeated from memory.
  void forget(const Key& key);

 private:
  struct Job;
  void worker();
  nlohmann::json describe(const Job& job) const;  // the pending state (mutex held)
  Answer answer_of(const Job& job) const;          // (mutex held)
  void publish(const Job& job);

  std::function<void(const nlohmann::json&)> publish_;
  std::size_t kept_answers_;
  std::size_t max_pending_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::map<Key, std::shared_ptr<Job>> jobs_;  // queued, running and finished
  std::deque<std::shared_ptr<Job>> queue_;
  std::deque<Key> finished_order_;  // oldest first: the first to go when too many are kept
  std::vector<std::thread> threads_;
};

}  // namespace imucal::daemon
