#include "daemon/analysis/analysis_jobs.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>

#include <spdlog/spdlog.h>

#include "core/json_reader.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

struct AnalysisJobs::Job {
  Key key;
  Compute compute;
  enum class State { Queued, Running, Done } state = State::Queued;
  double progress = 0.0;  // written by the job's thread under the mutex
  Clock::time_point queued_at = Clock::now(), started_at{};
  int status = 0;
  std::string body;
  double published_progress = -1.0;
  Clock::time_point published_at{};
};

AnalysisJobs::AnalysisJobs(int threads, std::size_t kept_answers, std::function<void(const json&)> publish,
                           std::size_t max_pending)
    : publish_(std::move(publish)), kept_answers_(std::max<std::size_t>(1, kept_answers)),
      max_pending_(std::max<std::size_t>(1, max_pending)) {
  for (int i = 0; i < std::max(1, threads); ++i) threads_.emplace_back([this] { worker(); });
}

AnalysisJobs::~AnalysisJobs() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

json AnalysisJobs::describe(const Job& job) const {
  json out = {{"campaign", job.key.campaign},
              {"analysis", job.key.analysis},
              {"state", job.state == Job::State::Queued ? "queued" : job.state == Job::State::Running ? "computing" : "done"},
              {"progress", job.progress}};
  const auto now = Clock::now();
  if (job.state == Job::State::Queued) {
    const auto it = std::find_if(queue_.begin(), queue_.end(), [&](const auto& j) { return j.get() == &job; });
    out["queue_position"] = it == queue_.end() ? 0 : static_cast<int>(it - queue_.begin()) + 1;
    out["elapsed_s"] = 0.0;
  } else {
    out["elapsed_s"] = std::chrono::duration<double>(now - job.started_at).count();
  }
  return out;
}

void AnalysisJobs::publish(const Job& job) {
  if (!publish_) return;
  json e;
  {
    std::lock_guard lock(mutex_);
    e = describe(job);
  }
  e["type"] = "analysis";
  try {
    publish_(e);
  } catch (const std::exception& ex) {
    spdlog::warn("analysis progress not published: {}", ex.what());
  }
}

AnalysisJobs::Answer AnalysisJobs::answer_of(const Job& job) const {
  Answer a;
  if (job.state == Job::State::Done) {
    a.ready = true;
    a.status = job.status;
    a.body = job.body;
  } else {
    a.pending = describe(job);
  }
  return a;
}

std::optional<AnalysisJobs::Answer> AnalysisJobs::find(const Key& key) const {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(key);
  if (it == jobs_.end()) return std::nullopt;
  return answer_of(*it->second);
}

void AnalysisJobs::forget(const Key& key) {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(key);
  if (it == jobs_.end() || it->second->state != Job::State::Done) return;
  jobs_.erase(it);
  finished_order_.erase(std::remove(finished_order_.begin(), finished_order_.end(), key), finished_order_.end());
}

AnalysisJobs::Answer AnalysisJobs::request(const Key& key, Compute compute) {
  std::shared_ptr<Job> job;
  Answer a;
  {
    std::lock_guard lock(mutex_);
    // Joined: the job already queued or running answers both.
    if (const auto it = jobs_.find(key); it != jobs_.end()) return answer_of(*it->second);
    const auto pending = std::count_if(jobs_.begin(), jobs_.end(),
                                       [](const auto& entry) { return entry.second->state != Job::State::Done; });
    if (static_cast<std::size_t>(pending) >= max_pending_) {
      a.ready = true;
      a.status = 429;
      a.body = json_text({{"error", "too many analyses under way (" + std::to_string(pending) +
                                        " jobs of analyses, plans and recording exports queued or computing); "
                                        "ask again when one has finished"}});
      return a;
    }
    job = std::make_shared<Job>();
    job->key = key;
    job->compute = std::move(compute);
    jobs_[key] = job;
    queue_.push_back(job);
    a.pending = describe(*job);
  }
  cv_.notify_one();
  publish(*job);
  return a;
}

void AnalysisJobs::worker() {
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = queue_.front();
      queue_.pop_front();
      job->state = Job::State::Running;
      job->started_at = Clock::now();
    }
    publish(*job);
    // Progress: kept for the pollers at every report, published when it moved 5 % or 1 s passed.
    const Progress progress = [&](double fraction) {
      bool send = false;
      {
        std::lock_guard lock(mutex_);
        if (stopping_) throw Cancelled();
        job->progress = std::clamp(fraction, 0.0, 1.0);
        const auto now = Clock::now();
        if (job->progress - job->published_progress >= 0.05 || now - job->published_at >= std::chrono::seconds(1)) {
          job->published_progress = job->progress;
          job->published_at = now;
          send = true;
        }
      }
      if (send) publish(*job);
    };
    int status = 500;
    json body;
    try {
      std::tie(status, body) = job->compute(progress);
    } catch (const Cancelled&) {
      std::lock_guard lock(mutex_);
      jobs_.erase(job->key);
      return;
    } catch (const std::exception& e) {
      spdlog::error("campaign {}: {} failed: {}", job->key.campaign, job->key.analysis, e.what());
      status = 500;
      body = {{"error", job->key.analysis + " failed: " + e.what()}};
    }
    // Each job's time in the log: a request that seems to hang is told apart from a slow queue.
    const auto now = Clock::now();
    spdlog::info("campaign {}: {} answered {} after {:.1f} s ({:.1f} s of it queued)", job->key.campaign,
                 job->key.analysis, status, std::chrono::duration<double>(now - job->queued_at).count(),
                 std::chrono::duration<double>(job->started_at - job->queued_at).count());
    {
      std::lock_guard lock(mutex_);
      job->status = status;
      job->body = json_text(body);
      job->state = Job::State::Done;
      job->progress = 1.0;
      job->compute = nullptr;
      finished_order_.push_back(job->key);
      // Bounded: the oldest answers go first (computed again when asked).
      while (finished_order_.size() > kept_answers_) {
        jobs_.erase(finished_order_.front());
        finished_order_.pop_front();
      }
    }
    publish(*job);
  }
}

}  // namespace imucal::daemon
