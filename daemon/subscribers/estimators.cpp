#include "daemon/subscribers/estimators.hpp"

#include <spdlog/spdlog.h>

#include "daemon/campaign/campaign.hpp"

namespace imucal::daemon {

EstimatorsSubscriber::~EstimatorsSubscriber() {
  if (auto worker = take()) worker->cancel();
}

std::shared_ptr<EstimatorWorker> EstimatorsSubscriber::take() {
  std::lock_guard lock(mutex_);
  return std::move(worker_);
}

void EstimatorsSubscriber::start(const RunStart& start) {
  if (auto earlier = take()) earlier->cancel();  // a run that ended without its RunEnding
  EstimatorWorker::Spec spec = estimator_spec(*start.spec, db_);
  auto worker = std::make_shared<EstimatorWorker>(
      start.run_file, std::move(spec), start.committed_t_ns,
      [this, id = start.campaign](const std::string& name, double t_s, const nlohmann::json& progress) {
        documents_.emit(&RunSubscriber::progress, EstimatorProgress{id, name, t_s, progress});
      });
  std::lock_guard lock(mutex_);
  worker_ = std::move(worker);
}

void EstimatorsSubscriber::frames_committed(const FramesCommitted& committed) {
  std::shared_ptr<EstimatorWorker> worker;
  {
    std::lock_guard lock(mutex_);
    worker = worker_;
  }
  if (worker) worker->committed(committed.t_ns);
}

void EstimatorsSubscriber::ending(const RunEnding& ending) {
  const std::shared_ptr<EstimatorWorker> worker = take();
  if (!worker) return;  // the run failed before its estimators started
  if (!ending.results) {
    worker->cancel();
    return;
  }
  RunResults out{ending.campaign, nlohmann::json::object(), std::nullopt, false};
  try {
    EstimatorWorker::Results r = worker->finish(ending.last_t_ns, ending.while_waiting);
    out.results = std::move(r.results);
    if (r.model) out.model_json = imu_model_to_json_text(*r.model);
  } catch (const std::exception& e) {
    // A run ending on an error must still end: the error is kept with the run.
    spdlog::error("campaign {}: the estimators could not finish: {}", ending.campaign, e.what());
    out.results = {{"error", std::string("the estimators could not finish: ") + e.what()}};
    out.failed = true;
  }
  documents_.emit(&RunSubscriber::results, out);
}

}  // namespace imucal::daemon
