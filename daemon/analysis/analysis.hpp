// What the results page shows beyond the model, computed from a finished run's file with the
// library code of `imucal calibrate` and `imucal evaluate` (docs/api.md): the Allan deviation
// (estimators/noise), the thermal plots (estimators/thermal), the Schuler test of model variants
// (estimators/evaluate), and the recording bundle as one tar file (storage/bundle). Each reads the
// run on its own read-only connection; none writes to it. No HTTP in here. `progress`, when given,
// hears the share done (0..1) now and then (AnalysisJobs shows it).
#pragma once

#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::daemon {

// The run cannot give this result (it lacks the segments or the data it needs); what() says what
// it would need, for the operator.
struct NotAvailable : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Overlapping Allan deviation per channel from the run's static segments (>= 10 s each):
// {"gyro_x": {"tau_s": [...], "adev": [...], "unit": "deg/h"}, ... "accel_z": {...},
//  "arw_deg_rth": [x, y, z], "vrw_mps_rth": [x, y, z], "bias_instability_dph": [...],
//  "bias_instability_mps2": [...], "longest_static_s", "total_static_s", "notes": [...]}.
using AnalysisProgress = std::function<void(double fraction)>;
nlohmann::json allan_from_run(const std::string& run_path, const AnalysisProgress& progress = {});

// Stage 2 on a run of the thermal program (table cycles named cycle-NNN/ and a chamber profile):
// per coefficient, per used cycle, the temperature, the stage-1 estimate ("before") and the
// estimate less the fitted thermal part ("after"). `input`: the campaign's stage-1 model.
nlohmann::json thermal_from_run(const std::string& run_path, const ImuModel& input,
                                const AnalysisProgress& progress = {});

struct Variant {
  std::string name, source;
  ImuModel model;
};
// The Schuler test (the evaluate program's tilt and coning segments) of each variant.
nlohmann::json evaluation_from_run(const std::string& run_path, const std::vector<Variant>& variants,
                                   const AnalysisProgress& progress = {});

// The run's calibration stages (`estimators`, as its campaign lists them; the others are skipped)
// run again from its recording as its online estimators ran them, from `start`, with the site's g
// taken from `gravity_mps2` (absent: normal gravity) instead of the one the run recorded: a survey
// corrected the site's g after the run. Each stage's report under its estimator's name, and the
// model of the last stage done (none when no stage was).
struct Recalibration {
  nlohmann::json results = nlohmann::json::object();
  std::optional<ImuModel> model;
};
Recalibration calibrate_again(const std::string& run_path, const std::vector<std::string>& estimators,
                              const ImuModel& start, std::optional<double> gravity_mps2,
                              const AnalysisProgress& progress = {});

// The run's truth model (simulated runs), if the run file carries one.
std::optional<ImuModel> truth_of_run(const std::string& run_path);
std::string imu_serial_of_run(const std::string& run_path);

// Writes the run as an imucal-recording/1 bundle into a POSIX tar file at `tar_path` (replaced
// atomically), every file under the folder `top_dir`/, telling `progress` how far it is.
void write_recording_tar(const std::string& run_path, const std::string& tar_path, const std::string& top_dir,
                         const AnalysisProgress& progress = {});

// Keeps the bundles (*.tar) of the exports folder `dir` within `max_bytes`: the least recently
// written go first, never `keep` (the one just written, even alone over the bound). A bundle
// removed is written again when asked. Returns how many were removed.
int prune_exports(const std::string& dir, const std::string& keep, std::int64_t max_bytes);

}  // namespace imucal::daemon
