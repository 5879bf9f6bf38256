// Writes to the daemon database that a full disk (or an I/O error) must not turn into a failed
// run, a lost audit entry or a dead daemon: done now when the database takes them, else kept in
// memory in order and tried again (retry(), from the sequencer's queue runner and the run's
// snapshots) while the run goes on with its state in memory. Later writes queue behind a deferred
// one, so the database sees them in their order. One queue for the whole service: the run's
// subscribers, the sequencer and the audit trail write through it.
#pragma once

#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <utility>

namespace imucal::daemon {

class WriteQueue {
 public:
  // Does `write` now, or keeps it (named by `what` in the log) when the database cannot be
  // written or writes wait already. Returns whether it was stored now. Other errors propagate.
  bool write(const std::string& what, std::function<void()> write);
  // `now` when nothing waits and the database takes it (its answer returned); else `later` queued
  // behind the writes that wait, as write() does, and true returned (taken as done): for a write
  // whose caller needs the database's answer when it can have one (a state change).
  bool write_now_or_later(const std::string& what, const std::function<bool()>& now, std::function<void()> later);
  // Tries the deferred writes again, oldest first, up to the first that still fails. True when
  // none is left.
  bool retry();
  // How many writes wait in memory for the database (0 unless it could not be written).
  std::size_t size() const;
  // What is still not stored, each named in the log; the queue is emptied (at shutdown: the
  // closures may refer to what is going away).
  void give_up();

 private:
  mutable std::mutex mutex_;  // guards writes_ and orders the writes through it
  std::deque<std::pair<std::string, std::function<void()>>> writes_;
};

}  // namespace imucal::daemon
