// Campaigns as data: a motion program (built-in, inline, or several in a row), a chamber set-point
// profile, the estimators to run online, and for simulated devices the IMU truth, rate, seed,
// time scale and injected faults. Checked completely before anything is stored or moves: every
// problem is listed (docs/api.md, "Campaign JSON").
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "daemon/config/config.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

// The chamber's part of a campaign: the set point over program time in the one profile model of
// motion_programs/chamber.hpp (the simulator's, `imucal simulate`'s), and the suspender's band.
struct CampaignChamber {
  motion::ChamberProfile profile;  // no steps: a constant set point, start_C
  double tolerance_C = 2.0;        // suspender band around the profile's set point

  double setpoint_at(double program_time_s) const { return profile.setpoint_C(program_time_s); }
  // Whether the set point changes gradually somewhere inside (t0_s, t1_s): a segment overlapping a
  // ramp cannot be redone as it was (the chamber's history cannot be repeated).
  bool ramps_within(double t0_s, double t1_s) const { return motion::ramps_within(profile, t0_s, t1_s); }
};

struct SimFault {
  enum class Kind {
    ChamberOffset,
    ImuDropout,
    ImuCorrupt,
    ImuDrop,         // `frames` samples lost on the link (never sent)
    Disconnect,
    DropConnection,  // sim-wire: the table or chamber controller closes its connections
    TableFault,
    RelayStuck,
    DiskFull,        // the daemon's disk full (storage::disk_fault) for duration_s of device time
    ImuBytesDrop,    // sim-wire: one byte cut out of each of `frames` samples on the link
    ChamberCorrupt,  // sim-wire: `frames` Modbus replies of the chamber garbled (wrong transaction id)
  } kind = Kind::ChamberOffset;
  std::string device;       // Disconnect: table, chamber or imu; DropConnection: table or chamber
  double at_s = 0.0;        // program time of the first pass
  double duration_s = 0.0;  // simulated (device) seconds
  double offset_C = 0.0;    // ChamberOffset
  std::int64_t frames = 1;  // ImuCorrupt, ImuDrop, ImuBytesDrop; ChamberCorrupt: replies
};

// The unit a campaign calibrates (docs/api.md, "Campaign JSON", `imu`). Empty serial: the campaign
// names no unit (the run file then records the serial the bench reports) and no unit's history
// holds it.
struct ImuIdentity {
  std::string serial, part_number, firmware, customer, notes;
};

struct CampaignSpec {
  std::string name;
  ImuIdentity imu;
  std::string program_label;  // "direct", "direct+navigation", or "inline:<name>"
  std::string program_json;   // the program actually run (several joined into one), JSON text
  std::vector<std::string> estimators;
  double rate_hz = 100.0;
  double time_scale = 10.0;
  std::uint64_t seed = 1;
  ImuModel truth;                            // resolved (files are read when the campaign is posted)
  std::optional<ImuModel> navigation_model;  // for the "navigation" estimator (default: ideal)
  // The model the first calibration estimator starts from (stage 3 alone: the stage-1 model it
  // refines): a model file or object, or a previous campaign's model by its id (resolved when the
  // run starts). Ideal by default.
  std::optional<ImuModel> start_model;
  std::optional<std::int64_t> start_model_campaign;
  CampaignChamber chamber;
  SuspenderSettings suspenders;
  std::vector<SimFault> faults;
  nlohmann::json normalized;  // the stored form: defaults filled in, files resolved inline

  bool has_estimator(const std::string& estimator) const;
};

struct CampaignCheck {
  std::optional<CampaignSpec> spec;  // set when there is no problem
  std::vector<std::string> problems;
  bool malformed = false;  // problems of form (400) rather than of content (422)
  double duration_s = 0.0;
  std::vector<SegmentInfo> segments;
};

// The calibration stages that run online (pipeline::StageDescriptor::estimator: direct, lever-arm,
// stage3) and the free-inertial display `navigation`.
const std::vector<std::string>& known_estimators();

// Parses and validates a campaign against the configuration (limits, defaults). Never throws for
// bad input. Models are named (config.named_models) or inline; a path is a problem of form
// (malformed) unless config.campaign_file_paths.
CampaignCheck check_campaign(const nlohmann::json& campaign, const DaemonConfig& config);
CampaignCheck check_campaign_text(const std::string& json_text, const DaemonConfig& config);

// The largest model file of the truths folder read (larger ones are skipped with a warning).
inline constexpr std::uintmax_t kNamedModelMaxBytes = 1 << 20;
// Reads the truths folder (config.sim.truths_dir, made absolute) into config.named_models and
// sim.truth's model into default_truth_json, once, before any campaign is checked: afterwards
// checking a campaign reads no file (unless campaign_file_paths). Throws ConfigError when
// sim.truth names neither a model of the folder nor a readable file.
void resolve_named_models(DaemonConfig& config);

// The truths a simulated campaign may name (GET /api/status, limits.campaign.truths): "ideal" (an
// error-free, noise-free IMU), the built-in "nav-grade" (examples/truth-nav-grade.json: a realistic
// navigation-grade FOG IMU with noise, compiled in) and every model of the truths folder (a file
// NAME.json there replaces a built-in of the same name). Each with what it is, for the builder.
struct NamedTruth {
  std::string name;
  std::string description;
  bool builtin = false;
};
inline constexpr const char* kBuiltinNavGradeTruth = "nav-grade";
std::vector<NamedTruth> named_truths(const DaemonConfig& config);

class DaemonDb;
// Stores a checked campaign in state `created` with its unit's identity (the one way the API and
// `imucal campaign run` store campaigns). Returns its id.
std::int64_t store_campaign(DaemonDb& db, const CampaignCheck& check, const std::string& reason);

// The program of a checked campaign, compiled (cannot fail for a spec from check_campaign).
motion::Program compile_campaign_program(const CampaignSpec& spec, const DaemonConfig& config);


}  // namespace imucal::daemon
