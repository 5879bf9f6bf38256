// What a calibration program will deliver, before the table moves (issue 16, `imucal plan`):
// the program's motion simulated with the IMU's own noise (its model's `noise` keys) and run
// through the same calibration pipeline as a recording, so the prediction is the sigma each
// estimator will report on data of that program: stage 1's least squares from its residuals and
// design, stage 3's filter from its covariance (which depends on the motion, not on the noise
// drawn). Also what the program leaves weakly observable, by name, and the motion that would fix it.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "core/table.hpp"
#include "motion_programs/program.hpp"
#include "pipeline/pipeline.hpp"
#include "plan/budget.hpp"

namespace imucal::plan {

struct Options {
  double rate_hz = 100.0;
  std::uint64_t seed = 1;
  // A stage-3 state whose sigma the program shrinks by less than this factor is weakly observable.
  double weak_reduction = 2.0;
  // Stage 1 and the lever arms report a sigma from their residuals, which scatters from run to
  // run (about 13 % with the direct program's 34 statics): the prediction is the RMS of this many
  // simulated runs' sigmas. Stage 3's sigma is its covariance, the same for every run: one run.
  int residual_stage_runs = 4;
  // What the stages are told, as on the bench: above all the table's reference accuracy
  // (settings.navigation: attitude, velocity and position noise), which bounds what stage 3 can
  // see of the delays and proof masses. The defaults are a real table's (docs/stage3.md).
  pipeline::Settings settings;
  // The bench the program runs on, as its runs record it: the table's certificate (its 1-sigma
  // puts the table's errors in stage 1's budget; its geometry, when given, moves the simulated
  // table and the reference removes it) and the site (a measured g: gravity_mps2). The defaults:
  // an ideal table of unknown uncertainty (no table sources) at the simulator's site, normal gravity.
  std::optional<table::TableCertificate> table;
  Site site;
  // Called with the fraction done (0..1) as the simulated runs are read; may throw to cancel.
  std::function<void(double fraction)> progress;
};

struct Weak {
  std::string stage;        // "direct", "navigation"
  std::string coefficient;  // "gyro.delay_us.y" (a model's key with its unit), or the stage's message
  std::string why;
  std::string fix;          // the motion that would determine it
};

struct StagePrediction {
  std::string stage;   // direct, lever-arm, navigation
  std::string status;  // done, undetermined, failed
  std::string message;
  std::optional<ImuModel> model;  // its sigma section is the prediction (instrument frame for direct)
  nlohmann::json history;         // navigation: {"t_s": [...], "sigma": {coefficient: [...]}}
  // Stage 1 and stage 3 (issue 34): the model's budget per coefficient with its dominant source,
  // and the bench's requirements for the stage's limits (`limits`: direct::Limits, navfilter::
  // Limits; empty for the other stages): per bench source of the budget, its 1-sigma here and the
  // largest at which every coefficient still meets its limit. Stage 3's budget is its filter's
  // (the consider parameters): its requirements assume each source's share scales with its sigma,
  // which errs on the safe side (a larger table error weighs the table's attitude less).
  std::vector<CoefficientBudget> budget;
  Targets limits;
  struct Requirement {
    std::string source;             // "table.outer_tilt_arcsec", "site.gravity_mps2"
    double sigma = 0.0;             // its 1-sigma in this prediction, its unit (arcsec; m/s^2)
    SourceRequirement alone;        // scaled, the other bench sources taken out (its own limit)
    SourceRequirement with_others;  // scaled, the other bench sources as they are
  };
  std::vector<Requirement> requirements;
  // Every table source scaled by one factor (the certificate as a whole), the site's g taken out.
  std::optional<SourceRequirement> whole_table;
};

struct Prediction {
  std::string program;
  double duration_s = 0.0;
  double rate_hz = 0.0;
  std::vector<StagePrediction> stages;
  std::vector<Weak> weak;
  // The nonlinear terms no stage of the program determines (stage 1 and stage 3 take them from
  // the model), each with the program that would: why says whether the model given has it.
  std::vector<Weak> from_model;
  // The nonlinear terms the program's tumble determines less well than the unit needs
  // (nonlinear_shortfall against the seed's bias figures), each with the longer program.
  std::vector<Weak> short_of_needs;
  nlohmann::json to_json() const;
};

// The tumble's terms whose uncertainty falls short of the unit's needs (issue 34): K2, K3 and the
// g-sensitivity act as a bias of their size at 1 g, so a term whose sigma at 1 g exceeds the
// bias figure of `bias` ("accel.bias_mps2", "gyro.bias_dph"; the seed's) leaves the unit a bias
// error larger than it is calibrated to. One entry per such coefficient, stage "tumble".
std::vector<Weak> nonlinear_shortfall(const ImuModel& tumble_model, const Targets& bias);

// A certificate stating `sigma_arcsec` for every parameter of the table's geometry and a first and
// a second encoder harmonic of that amplitude on each axis, no values (`imucal plan
// --table-sigma-arcsec`): the question "what if my table were certified to this?".
table::TableCertificate uniform_table_certificate(double sigma_arcsec);

// Stage 3's states that are coefficients of the model: {"gyro.bias_dph.x": ["gyro_bias_radps", 0],
// ...}, the block as a stage's `uncertainty_reduction` names it and the index in the block.
nlohmann::json stage3_states_json();

// `imu`: the unit's model, its `noise` section required (the prediction scales with it); for a
// program without stage 1 (navigation alone) it is also the model stage 3 starts from.
Prediction predict(const motion::Program& program, const ImuModel& imu, const Options& options = {});

}  // namespace imucal::plan
