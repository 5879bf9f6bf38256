// A campaign's stored model and its recording as the API hands them out, decided here rather than
// in the HTTP handlers (issue 37: the HTTP layer translates, the room that owns a decision makes
// it): which stage's model, in which frame, against which truth; the recording's temperatures and
// plot series read from its file.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "daemon/analysis/analysis.hpp"
#include "daemon/analysis/run_series.hpp"

namespace imucal::daemon {

// A stored model (its own frame) against a stored truth (instrument frame), compared in the
// model's frame: GET /api/campaigns/{id}/truth (docs/api.md).
nlohmann::json truth_comparison_json(const std::string& model_text, const std::string& truth_text);

// The model a client asks for: the campaign's (`model_text`), or one stage's as kept in its
// results (`stage`: an estimator's name), in the instrument or the body frame.
struct ModelView {
  int status = 200;  // 400: no such stage or frame; 404: the campaign kept no model of that stage
  std::string text;  // the model's JSON text, or what is wrong
};
ModelView stored_model_view(const std::string& model_text, const std::optional<std::string>& results_text,
                            const std::optional<std::string>& stage, const std::optional<std::string>& frame);

// Each calibration stage's model the campaign kept with its results (a `full` campaign: direct,
// lever-arm, stage3), as variants for the evaluation, in the stages' order.
std::vector<Variant> stage_model_variants(const std::optional<std::string>& results_text);

// The recording's temperature samples (read-only beside its writer).
std::vector<TempSample> run_temperatures(const std::string& run_path);
// The recording's plot series (run_series.hpp), read-only beside its writer.
nlohmann::json run_series_of(const std::string& run_path, const SeriesRange& range);

}  // namespace imucal::daemon
