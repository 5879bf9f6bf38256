#include "daemon/analysis/model_views.hpp"

#include "estimators/direct_calibration.hpp"
#include "estimators/truth_comparison.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

using nlohmann::json;

json truth_comparison_json(const std::string& model_text, const std::string& truth_text) {
  const TruthComparison cmp = compare_with_truth(imu_model_from_json_text(model_text, "stored model"),
                                                 imu_model_from_json_text(truth_text, "the campaign's truth"));
  json rows = json::array();
  json by_definition = json::array();
  for (const TruthComparisonRow& r : cmp.rows) {
    if (r.by_definition) by_definition.push_back(r.key);
    rows.push_back({{"key", r.key}, {"estimate", r.estimate}, {"sigma", r.sigma}, {"truth", r.truth}, {"error", r.error},
                    {"error_over_sigma", r.error_over_sigma ? json(*r.error_over_sigma) : json(nullptr)},
                    {"by_definition", r.by_definition}});
  }
  return {{"frame", cmp.frame}, {"truth_frame", cmp.truth_frame}, {"converted", cmp.converted},
          {"truth", json::parse(imu_model_to_json_text(cmp.truth))}, {"zero_by_definition", by_definition},
          {"rows", rows}};
}

ModelView stored_model_view(const std::string& model_text, const std::optional<std::string>& results_text,
                            const std::optional<std::string>& stage, const std::optional<std::string>& frame) {
  std::string text = model_text;
  if (stage) {
    if (!pipeline::stage_of_estimator(*stage)) {
      std::string names;
      for (const pipeline::StageDescriptor& n : pipeline::stage_registry()) names += (names.empty() ? "" : ", ") + std::string(n.estimator);
      return {400, "stage must be one of " + names};
    }
    const json results = results_text ? json::parse(*results_text, nullptr, false) : json::object();
    if (!results.is_object() || !results.contains(*stage) || !results.at(*stage).contains("model"))
      return {404, "no model of stage " + *stage};
    text = results.at(*stage).at("model").dump();
  }
  if (frame && *frame == "body") {
    text = imu_model_to_json_text(direct::to_body_frame(imu_model_from_json_text(text, "stored model")));
  } else if (frame && *frame != "instrument") {
    return {400, "frame must be instrument or body"};
  }
  return {200, text};
}

std::vector<Variant> stage_model_variants(const std::optional<std::string>& results_text) {
  std::vector<Variant> stages;
  if (!results_text) return stages;
  const json results = json::parse(*results_text, nullptr, false);
  for (const pipeline::StageDescriptor& n : pipeline::stage_registry()) {
    if (!results.is_object() || !results.contains(n.estimator)) continue;
    const json& r = results.at(n.estimator);
    if (!r.is_object() || !r.contains("model")) continue;
    stages.push_back({std::string("stage ") + n.estimator, std::string("this campaign's model after stage ") + n.name,
                      imu_model_from_json_text(r.at("model").dump(), std::string("the ") + n.estimator + " model")});
  }
  return stages;
}

std::vector<TempSample> run_temperatures(const std::string& run_path) {
  return storage::RunDb::open(run_path, storage::OpenMode::Read).temps();
}

json run_series_of(const std::string& run_path, const SeriesRange& range) {
  // Read-only beside a writer (WAL): a running campaign's recording so far.
  const auto run = storage::RunDb::open(run_path, storage::OpenMode::Read);
  return run_series_json(run, range);
}

}  // namespace imucal::daemon
