#include "daemon/db/write_queue.hpp"

#include <spdlog/spdlog.h>

#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

namespace {
// A bound on what a disk that stays full can make the daemon keep: beyond it the oldest deferred
// writes are given up, each in the log (events and counters; never more than a handful of state
// changes are among them).
constexpr std::size_t kMaxDeferred = 100'000;
}  // namespace

bool WriteQueue::write(const std::string& what, std::function<void()> write) {
  std::lock_guard lock(mutex_);
  if (writes_.empty()) {
    try {
      write();
      return true;
    } catch (const std::exception& e) {
      if (!is_database_failure(e)) throw;
      spdlog::error("daemon database: {} kept in memory, to be stored when the database can be written: {}", what,
                    e.what());
    }
  }
  if (writes_.size() >= kMaxDeferred) {
    spdlog::error("daemon database: {} given up: {} writes wait already", writes_.front().first, kMaxDeferred);
    writes_.pop_front();
  }
  writes_.emplace_back(what, std::move(write));
  return false;
}

bool WriteQueue::write_now_or_later(const std::string& what, const std::function<bool()>& now,
                                    std::function<void()> later) {
  {
    std::lock_guard lock(mutex_);
    if (writes_.empty()) {
      try {
        return now();
      } catch (const std::exception& e) {
        if (!is_database_failure(e)) throw;
        spdlog::error("daemon database: {} kept in memory, to be stored when the database can be written: {}", what,
                      e.what());
      }
    }
  }
  write(what, std::move(later));
  return true;
}

bool WriteQueue::retry() {
  std::lock_guard lock(mutex_);
  while (!writes_.empty()) {
    try {
      writes_.front().second();
    } catch (const std::exception& e) {
      if (is_database_failure(e)) return false;  // still full: the next call tries again
      spdlog::error("daemon database: {} given up: {}", writes_.front().first, e.what());
    }
    writes_.pop_front();
    if (writes_.empty()) spdlog::info("daemon database: every deferred write is stored");
  }
  return true;
}

std::size_t WriteQueue::size() const {
  std::lock_guard lock(mutex_);
  return writes_.size();
}

void WriteQueue::give_up() {
  std::lock_guard lock(mutex_);
  for (const auto& write : writes_) spdlog::error("daemon database: not stored at shutdown: {}", write.first);
  writes_.clear();
}

}  // namespace imucal::daemon
