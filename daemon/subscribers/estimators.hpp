// The online estimators' subscriber: at a run's start it resolves the campaign's estimators (its
// start model, possibly another campaign's, from the service database) and starts an
// EstimatorWorker that tails the run file; it follows the run file's commits, emits each
// estimator's progress, and at the run's end finishes them (or cancels them) and emits their
// results. A start model that cannot be found fails the run at its start (the exception leaves the
// RunStart document).
#pragma once

#include <memory>
#include <mutex>

#include "daemon/db/daemon_db.hpp"
#include "daemon/run/documents.hpp"
#include "daemon/subscribers/estimator_worker.hpp"

namespace imucal::daemon {

class EstimatorsSubscriber final : public RunSubscriber {
 public:
  // `documents`: where the progress and the results go (the subscribers this one is among).
  EstimatorsSubscriber(DaemonDb& db, const Documents& documents) : db_(db), documents_(documents) {}
  ~EstimatorsSubscriber() override;

  void start(const RunStart& start) override;
  void frames_committed(const FramesCommitted& committed) override;
  void ending(const RunEnding& ending) override;

 private:
  std::shared_ptr<EstimatorWorker> take();

  DaemonDb& db_;
  const Documents& documents_;
  std::mutex mutex_;  // guards worker_: the recording's writer thread reaches it too
  std::shared_ptr<EstimatorWorker> worker_;
};

}  // namespace imucal::daemon
