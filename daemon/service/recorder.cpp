#include "daemon/service/recorder.hpp"

#include <chrono>

#include <spdlog/spdlog.h>

namespace imucal::daemon {

using Clock = std::chrono::steady_clock;

Recorder::Recorder(storage::RunDb db, double commit_interval_s, std::int64_t queue_frames, CommitListener on_commit)
    : db_(std::move(db)),
      path_(db_.path()),
      commit_interval_s_(commit_interval_s),
      queue_capacity_frames_(queue_frames),
      on_commit_(std::move(on_commit)) {
  appended_frames_ = db_.frame_count();
  stats_.committed_frames = appended_frames_;
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() { close(); }

Recorder::Push Recorder::enqueue(Item item, std::int64_t frames, bool wait_when_full) {
  std::unique_lock lock(mutex_);
  if (error_ || closing_) return Push::Failed;
  if (frames > 0 && stats_.queued_frames + frames > queue_capacity_frames_ && !queue_.empty()) {
    if (!wait_when_full) {
      stats_.dropped_frames += frames;
      return Push::Dropped;
    }
    cv_space_.wait(lock, [&] {
      return error_ || closing_ || queue_.empty() || stats_.queued_frames + frames <= queue_capacity_frames_;
    });
    if (error_ || closing_) return Push::Failed;
  }
  stats_.queued_frames += frames;
  stats_.high_water_frames = std::max(stats_.high_water_frames, stats_.queued_frames);
  queue_.push_back(std::move(item));
  cv_work_.notify_one();
  return Push::Queued;
}

Recorder::Push Recorder::push_frames(std::vector<ImuFrame> frames, bool wait_when_full) {
  if (frames.empty()) return Push::Queued;
  const auto n = static_cast<std::int64_t>(frames.size());
  Item item;
  item.kind = Item::Kind::Frames;
  item.frames = std::move(frames);
  return enqueue(std::move(item), n, wait_when_full);
}

bool Recorder::push_temps(std::vector<TempSample> temps) {
  if (temps.empty()) return true;
  Item item;
  item.kind = Item::Kind::Temps;
  item.temps = std::move(temps);
  return enqueue(std::move(item), 0, true) == Push::Queued;
}

void Recorder::set_extra(const std::string& key, const std::string& json_text) {
  Item item;
  item.kind = Item::Kind::Extra;
  item.key = key;
  item.text = json_text;
  (void)enqueue(std::move(item), 0, true);
}

bool Recorder::commit_and_wait() {
  std::unique_lock lock(mutex_);
  if (error_) return false;
  if (closing_) return !error_;
  Item item;
  item.kind = Item::Kind::Barrier;
  item.barrier = next_barrier_++;
  const std::uint64_t mine = item.barrier;
  queue_.push_back(std::move(item));
  cv_work_.notify_one();
  cv_barrier_.wait(lock, [&] { return error_ || done_barrier_ >= mine; });
  return !error_;
}

void Recorder::close() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
  }
  cv_work_.notify_all();
  cv_space_.notify_all();
  if (thread_.joinable()) thread_.join();
}

RecorderStats Recorder::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

std::optional<std::string> Recorder::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

void Recorder::run() {
  const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(commit_interval_s_));
  auto last_commit = Clock::now();
  bool dirty = false;

  // Commits (flushes the open chunk) and publishes; called without the lock.
  auto commit = [&]() {
    // Temperatures (a few a second) go in with the frames' commit rather than in a transaction
    // of their own each.
    if (!pending_temps_.empty()) {
      db_.append_temps(pending_temps_);
      pending_temps_.clear();
    }
    db_.flush();
    dirty = false;
    last_commit = Clock::now();
    RecorderStats snapshot;
    {
      std::lock_guard lock(mutex_);
      stats_.committed_frames = appended_frames_;
      stats_.committed_t_ns = appended_t_ns_;
      ++stats_.commits;
      snapshot = stats_;
    }
    if (on_commit_) on_commit_(snapshot);
  };

  std::unique_lock lock(mutex_);
  try {
    for (;;) {
      if (dirty) {
        cv_work_.wait_until(lock, last_commit + interval, [&] { return !queue_.empty() || closing_; });
      } else {
        cv_work_.wait(lock, [&] { return !queue_.empty() || closing_; });
      }
      if (queue_.empty()) {
        if (closing_) break;
        if (dirty && Clock::now() >= last_commit + interval) {
          lock.unlock();
          commit();
          lock.lock();
        }
        continue;
      }
      Item item = std::move(queue_.front());
      queue_.pop_front();
      stats_.queued_frames -= static_cast<std::int64_t>(item.frames.size());
      cv_space_.notify_all();
      lock.unlock();
      switch (item.kind) {
        case Item::Kind::Frames:
          db_.append(item.frames);
          appended_frames_ += static_cast<std::int64_t>(item.frames.size());
          appended_t_ns_ = item.frames.back().t_ns;
          dirty = true;
          break;
        case Item::Kind::Temps:
          pending_temps_.insert(pending_temps_.end(), item.temps.begin(), item.temps.end());
          dirty = true;
          break;
        case Item::Kind::Extra:
          db_.set_extra(item.key, item.text);
          break;
        case Item::Kind::Barrier:
          commit();
          break;
      }
      if (dirty && Clock::now() >= last_commit + interval) commit();
      lock.lock();
      if (item.kind == Item::Kind::Barrier) {
        done_barrier_ = item.barrier;
        cv_barrier_.notify_all();
      }
    }
    lock.unlock();
    if (dirty) commit();
    lock.lock();
  } catch (const std::exception& e) {
    if (!lock.owns_lock()) lock.lock();
    error_ = e.what();
    spdlog::error("recorder: {}", e.what());
    queue_.clear();
    stats_.queued_frames = 0;
  }
  // Wake every waiter: barriers are satisfied (or failed), producers must not wait for space.
  done_barrier_ = next_barrier_;
  cv_barrier_.notify_all();
  cv_space_.notify_all();
}

}  // namespace imucal::daemon
