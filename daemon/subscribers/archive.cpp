#include "daemon/subscribers/archive.hpp"

#include <spdlog/spdlog.h>

namespace imucal::daemon {

ArchiveSubscriber::ArchiveSubscriber(Archive archive) : archive_(std::move(archive)), thread_([this] { work(); }) {}

ArchiveSubscriber::~ArchiveSubscriber() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void ArchiveSubscriber::transition(const Transition& t) {
  if (!is_final(t.to)) return;  // done, failed, aborted; an interrupted run may resume
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(t.campaign);
  }
  wake_.notify_one();
}

void ArchiveSubscriber::drain() {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [this] { return (queue_.empty() && !busy_) || stopping_; });
}

void ArchiveSubscriber::work() {
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (stopping_) break;
    const std::int64_t id = queue_.front();
    queue_.pop_front();
    busy_ = true;
    lock.unlock();
    try {
      archive_(id);
    } catch (const std::exception& e) {
      // The bundle is still this stand's to give (GET /api/campaigns/{id}/recording).
      spdlog::error("campaign {}: its recording could not be archived: {}", id, e.what());
    } catch (...) {
      spdlog::error("campaign {}: its recording could not be archived: unknown error", id);
    }
    lock.lock();
    busy_ = false;
    if (queue_.empty()) idle_.notify_all();
  }
  if (!queue_.empty()) spdlog::warn("{} ended run(s) not archived at shutdown", queue_.size());
  idle_.notify_all();
}

}  // namespace imucal::daemon
