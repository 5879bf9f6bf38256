// The lab's shared archive's subscriber (issue 38; production/lab.hpp): when a run has
// ended (done, failed or aborted: not interrupted, which may resume), its recording's bundle is
// written to the archive, on this subscriber's own thread (a long run's bundle takes minutes; the
// run engine's thread never waits on it, nor on a slow network share). One at a time, in the order
// the runs ended; the service's stop waits for the one being written and drops the rest (the
// next run's end, or an operator's request of the bundle, is not affected).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

#include "daemon/run/documents.hpp"

namespace imucal::daemon {

class ArchiveSubscriber final : public RunSubscriber {
 public:
  // Writes campaign `id`'s bundle to the archive; may throw (logged, the run is unharmed).
  using Archive = std::function<void(std::int64_t id)>;

  explicit ArchiveSubscriber(Archive archive);
  ~ArchiveSubscriber() override;
  ArchiveSubscriber(const ArchiveSubscriber&) = delete;
  ArchiveSubscriber& operator=(const ArchiveSubscriber&) = delete;

  void transition(const Transition& transition) override;
  // Waits until every run ended so far is archived (tests, and an orderly shutdown's log).
  void drain();

 private:
  void work();

  Archive archive_;
  std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::deque<std::int64_t> queue_;
  bool busy_ = false, stopping_ = false;
  std::thread thread_;
};

}  // namespace imucal::daemon
