#include "daemon/campaign/campaign.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <filesystem>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "core/expect_value.hpp"
#include "core/json_reader.hpp"
#include "core/number_text.hpp"
#include "core/units.hpp"
#include "daemon/campaign/builtin_truths.hpp"
#include "daemon/db/daemon_db.hpp"
#include "motion_programs/chamber.hpp"
#include "pipeline/pipeline.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {
// The calibration stages imucald runs online, as the run file grows; thermal and noise are
// analyses of the finished run (GET .../thermal, .../allan), on request.
constexpr std::array<pipeline::Stage, 7> kOnlineStages = {
    pipeline::Stage::Direct,     pipeline::Stage::RateSteps, pipeline::Stage::Tumble,       pipeline::Stage::LeverArm,
    pipeline::Stage::Navigation, pipeline::Stage::WarmUp,    pipeline::Stage::Repeatability};
}  // namespace

const std::vector<std::string>& known_estimators() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto stage : kOnlineStages) n.emplace_back(pipeline::names_of(stage).estimator);
    n.emplace_back("navigation");
    return n;
  }();
  return names;
}

bool CampaignSpec::has_estimator(const std::string& estimator) const {
  return std::find(estimators.begin(), estimators.end(), estimator) != estimators.end();
}

// ------------------------------------------------------------------------------------------------

namespace {

// A string that names a file rather than a model: a client of the API names models, never paths
// on the daemon's machine (a path could name /dev/zero, a FIFO or a secret).
bool looks_like_path(const std::string& text) {
  return text.find('/') != std::string::npos || text.find('\\') != std::string::npos || text.starts_with('.') ||
         text.starts_with('~');
}

std::string named_model_list(const DaemonConfig& config) {
  std::string list = "ideal";
  for (const auto& [name, text] : config.named_models) list += ", " + name;
  return list;
}

// An IMU model given as "ideal", a name of the truths folder, an inline object, or (imucal
// campaign run only) a file path. A path from a client is a problem of form: `malformed`.
std::optional<ImuModel> read_model(const json& v, const std::string& where, const DaemonConfig& config,
                                   std::vector<std::string>& problems, bool& malformed) {
  try {
    if (v.is_string()) {
      const auto text = v.get<std::string>();
      if (text == "ideal") return ImuModel{};
      if (const auto it = config.named_models.find(text); it != config.named_models.end())
        return imu_model_from_json_text(it->second, where + " '" + text + "'");
      if (config.campaign_file_paths) return read_imu_model_file(text);
      if (looks_like_path(text)) {
        malformed = true;
        problems.push_back(where + ": a path is not accepted; name a model of the daemon's truths folder (" +
                           named_model_list(config) + ") or give the model inline as an object");
      } else {
        problems.push_back(where + ": no model named \"" + text + "\" (known: " + named_model_list(config) +
                           "; the truths folder is " + config.sim.truths_dir + ")");
      }
      return std::nullopt;
    }
    if (v.is_object()) return imu_model_from_json_text(v.dump(), where);
    malformed = true;
    problems.push_back(where + " must be \"ideal\", a model's name (the truths folder) or a model object");
  } catch (const std::exception& e) {
    problems.push_back(where + ": " + e.what());
  }
  return std::nullopt;
}

json model_json(const ImuModel& m) { return json::parse(imu_model_to_json_text(m)); }

// The JSON of one program item (a built-in name or an inline object), or nothing with a problem.
std::optional<json> program_item(const json& item, const std::string& where, std::vector<std::string>& problems,
                                 bool& malformed) {
  if (item.is_string()) {
    const auto name = item.get<std::string>();
    const auto names = motion::builtin_program_names();
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      problems.push_back(where + ": unknown built-in program \"" + name + "\" (known: " + list + ")");
      return std::nullopt;
    }
    return json::parse(motion::builtin_program_json(name));
  }
  if (item.is_object()) return item;
  malformed = true;
  problems.push_back(where + " must be a built-in program name, a program object or a list of those");
  return std::nullopt;
}

std::string item_name(const json& program, std::size_t index) {
  if (program.contains("name") && program.at("name").is_string()) return program.at("name").get<std::string>();
  return "part" + std::to_string(index + 1);
}

// Joins several programs into one: segment names get the part's name as prefix and a move to each
// part's start pose is inserted, so the table never jumps.
std::optional<json> join_programs(const std::vector<json>& parts, const motion::TableLimits& limits,
                                  std::vector<std::string>& problems) {
  json joined = {{"name", ""}, {"segments", json::array()}};
  std::string name;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const json& part = parts[i];
    const std::string part_name = item_name(part, i);
    name += (name.empty() ? "" : "+") + part_name;
    try {
      // Each part alone first, so that a problem names the part it is in.
      (void)motion::compile_program(part.dump(), limits);
    } catch (const std::exception& e) {
      problems.push_back("campaign.program[" + std::to_string(i) + "]: " + e.what());
      return std::nullopt;
    }
    if (i == 0) {
      if (part.contains("start_deg")) joined["start_deg"] = part.at("start_deg");
    } else {
      const json start = part.contains("start_deg") ? part.at("start_deg") : json::array({0.0, 0.0, 0.0});
      joined["segments"].push_back({{"type", "move"}, {"name", part_name + "/to-start"}, {"to_deg", start}});
    }
    if (part.contains("segments") && part.at("segments").is_array()) {
      for (json seg : part.at("segments")) {
        if (seg.is_object() && seg.contains("name") && seg.at("name").is_string())
          seg["name"] = part_name + "/" + seg.at("name").get<std::string>();
        joined["segments"].push_back(std::move(seg));
      }
    }
  }
  joined["name"] = name;
  joined["comment"] = "joined by imucald: " + name;
  return joined;
}

// `imu`: {"serial", "part_number", "firmware", "customer", "notes"}, the serial required. A serial
// names the unit in file names, URLs and certificates: printable, without slashes, at most 64
// characters.
void check_imu(const json& j, ImuIdentity& imu, std::vector<std::string>& problems) {
  ObjectReader r(j, "campaign.imu", problems);
  if (auto v = r.string("serial", true)) {
    const bool printable = std::all_of(v->begin(), v->end(), [](char c) {
      return static_cast<unsigned char>(c) >= 0x20 && c != 0x7f && c != '/' && c != '\\';
    });
    const bool padded = !v->empty() && (v->front() == ' ' || v->back() == ' ');
    // "." and ".." would be path steps in the unit's URL (GET /api/imus/{serial}).
    const bool dots = v->find_first_not_of('.') == std::string::npos;
    if (v->empty() || v->size() > 64 || !printable || padded || dots)
      problems.push_back("campaign.imu.serial must have 1 to 64 printable characters, no slash, not only dots and "
                         "no leading or trailing space");
    else
      imu.serial = *v;
  }
  constexpr std::size_t kMaxText = 2000;
  auto text = [&](const char* key, std::string& out) {
    if (auto v = r.string(key)) {
      if (v->size() > kMaxText) problems.push_back(std::string("campaign.imu.") + key + " is longer than 2000 characters");
      out = *v;
    }
  };
  text("part_number", imu.part_number);
  text("firmware", imu.firmware);
  text("customer", imu.customer);
  text("notes", imu.notes);
  r.finish();
}

// The tolerance of a campaign run along a chamber profile that ramps, unless it gives its own: a
// chamber's air lags a 1 C/min ramp by about 3 C (docs/daemon.md).
constexpr double kProfileToleranceMin_C = 5.0;

// A chamber profile in the format of motion_programs/chamber.hpp (soaks, ramps, sets): a built-in
// name or an inline object. Sets `profile` and returns true, or names the problem.
bool read_profile(const json& spec, const std::string& where, const DaemonConfig& config, motion::ChamberProfile& profile,
                  std::vector<std::string>& problems, bool& malformed) {
  std::string names;
  for (const auto& n : motion::builtin_chamber_names()) names += (names.empty() ? "" : ", ") + n;
  if (spec.is_string() && !config.campaign_file_paths && !motion::is_builtin_chamber(spec.get<std::string>())) {
    const bool path = looks_like_path(spec.get<std::string>());
    malformed = malformed || path;
    problems.push_back(where + (path ? ": a path is not accepted" : ": no built-in profile \"" + spec.get<std::string>() + "\"") +
                       "; name a built-in profile (" + names + ") or give the profile inline as an object (docs/thermal.md)");
    return false;
  }
  if (!spec.is_string() && !spec.is_object()) {
    problems.push_back(where + " must be a built-in chamber profile's name (" + names + ") or a profile object (docs/thermal.md)");
    return false;
  }
  try {
    profile = spec.is_string() ? motion::load_chamber_profile(spec.get<std::string>())
                               : motion::compile_chamber_profile(spec.dump());
    return true;
  } catch (const std::exception& e) {
    problems.push_back(where + ": " + e.what());
    return false;
  }
}

// A set point the chamber cannot hold, named by where it is written.
void check_setpoint(double setpoint_C, const std::string& where, const motion::ChamberLimits& lim,
                    std::vector<std::string>& problems) {
  if (setpoint_C < lim.min_C || setpoint_C > lim.max_C)
    problems.push_back(where + ": " + celsius_text(setpoint_C) + " is outside the chamber's limits " + celsius_text(lim.min_C) +
                       " .. " + celsius_text(lim.max_C));
}

// `chamber.steps`: set-point changes (motion::SetpointChange), each checked where it is written.
std::vector<motion::SetpointChange> read_changes(const json& steps, const motion::ChamberLimits& lim, double duration_s,
                                                 std::vector<std::string>& problems) {
  std::vector<motion::SetpointChange> out;
  if (!steps.is_array()) {
    problems.push_back("campaign.chamber.steps must be an array");
    return out;
  }
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const std::string where = "campaign.chamber.steps[" + std::to_string(i) + "]";
    ObjectReader sr(steps[i], where, problems);
    const auto at = sr.number_in("at_s", 0, std::nullopt, true);
    const auto sp = sr.number("setpoint_C", true);
    const double ramp = sr.number_in("ramp_C_per_min", 0).value_or(0.0);
    if (!at || !sp) continue;
    check_setpoint(*sp, where + ".setpoint_C", lim, problems);
    if (ramp > lim.max_ramp_C_per_min)
      problems.push_back(where + ".ramp_C_per_min: " + number_text(ramp) + " °C/min exceeds the chamber's limit " +
                         number_text(lim.max_ramp_C_per_min) + " °C/min");
    if (*at > duration_s)
      problems.push_back(where + ".at_s: " + number_text(*at) + " s is after the program's end (" + number_text(duration_s) + " s)");
    if (!out.empty() && *at <= out.back().at_s) problems.push_back(where + ".at_s must be later than the previous step's");
    out.push_back({*at, *sp, ramp});
  }
  return out;
}

// `chamber`: {"setpoint_C", "tolerance_C", "steps": [...]} or {"profile": NAME|OBJECT,
// "tolerance_C"}, or just the profile's name. Either way one motion::ChamberProfile.
void check_chamber(const json& j, const DaemonConfig& config, double duration_s, CampaignChamber& chamber,
                   std::vector<std::string>& problems, bool& malformed) {
  const motion::ChamberLimits& lim = config.chamber.limits;
  const json* named = &j;
  const json* steps = nullptr;
  std::string where = "campaign.chamber";
  std::optional<double> start_C, tolerance_C;
  if (!j.is_string()) {
    ObjectReader r(j, "campaign.chamber", problems);
    named = r.get("profile");
    steps = r.get("steps");
    where = "campaign.chamber.profile";
    if (named != nullptr && steps != nullptr) {
      problems.push_back("campaign.chamber: give either a profile or steps, not both");
      return;
    }
    if (named != nullptr && r.has("setpoint_C"))
      problems.push_back("campaign.chamber.setpoint_C: a profile starts at its own start_C");
    start_C = r.number("setpoint_C");
    if (start_C) check_setpoint(*start_C, "campaign.chamber.setpoint_C", lim, problems);
    tolerance_C = r.number_in("tolerance_C", 0.01, 50);
  }
  if (tolerance_C) chamber.tolerance_C = *tolerance_C;
  else if (named != nullptr) chamber.tolerance_C = std::max(chamber.tolerance_C, kProfileToleranceMin_C);
  if (named != nullptr) {
    motion::ChamberProfile p;
    if (!read_profile(*named, where, config, p, problems, malformed)) return;
    for (const std::string& problem : motion::validate_chamber_profile(p, lim)) problems.push_back(where + ": " + problem);
    for (const motion::ChamberStep& s : p.steps)
      if (s.t0_s > duration_s)
        problems.push_back(where + ": step '" + s.name + "' starts at " + number_text(s.t0_s) + " s, after the program's end (" +
                           number_text(duration_s) + " s)");
    chamber.profile = std::move(p);
    return;
  }
  const double from_C = start_C.value_or(chamber.profile.start_C);
  const auto changes = steps != nullptr ? read_changes(*steps, lim, duration_s, problems) : std::vector<motion::SetpointChange>{};
  chamber.profile = motion::profile_of_changes(from_C, changes, duration_s);
}

void check_faults(const json& j, double duration_s, std::vector<SimFault>& faults, std::vector<std::string>& problems) {
  if (!j.is_array()) {
    problems.push_back("campaign.sim_faults must be an array");
    return;
  }
  std::size_t i = 0;
  for (const json& f : j) {
    const std::string where = "campaign.sim_faults[" + std::to_string(i++) + "]";
    ObjectReader r(f, where, problems);
    SimFault fault;
    const auto kind = r.string("kind", true);
    if (auto v = r.number_in("at_s", 0, duration_s, true)) fault.at_s = *v;
    if (auto v = r.number_in("duration_s", 0, 86400)) fault.duration_s = *v;
    if (!kind) continue;
    if (*kind == "chamber_offset") {
      fault.kind = SimFault::Kind::ChamberOffset;
      if (auto v = r.number_in("offset_C", -100, 100, true)) fault.offset_C = *v;
    } else if (*kind == "imu_dropout") {
      fault.kind = SimFault::Kind::ImuDropout;
    } else if (*kind == "imu_corrupt") {
      fault.kind = SimFault::Kind::ImuCorrupt;
      if (auto v = r.integer("frames", 1, 1000000)) fault.frames = *v;
    } else if (*kind == "imu_drop") {
      fault.kind = SimFault::Kind::ImuDrop;
      if (auto v = r.integer("frames", 1, 1000000)) fault.frames = *v;
    } else if (*kind == "imu_bytes_drop") {
      fault.kind = SimFault::Kind::ImuBytesDrop;
      if (auto v = r.integer("frames", 1, 1000000)) fault.frames = *v;
    } else if (*kind == "chamber_corrupt") {
      fault.kind = SimFault::Kind::ChamberCorrupt;
      if (auto v = r.integer("replies", 1, 1000000)) fault.frames = *v;
    } else if (*kind == "drop_connection") {
      fault.kind = SimFault::Kind::DropConnection;
      if (auto v = r.string("device", true)) {
        if (*v != "table" && *v != "chamber") problems.push_back(where + ".device must be table or chamber");
        fault.device = *v;
      }
    } else if (*kind == "disk_full") {
      fault.kind = SimFault::Kind::DiskFull;
    } else if (*kind == "disconnect") {
      fault.kind = SimFault::Kind::Disconnect;
      if (auto v = r.string("device", true)) {
        if (*v != "table" && *v != "chamber" && *v != "imu")
          problems.push_back(where + ".device must be table, chamber or imu");
        fault.device = *v;
      }
    } else if (*kind == "table_fault") {
      fault.kind = SimFault::Kind::TableFault;
    } else if (*kind == "relay_stuck") {
      fault.kind = SimFault::Kind::RelayStuck;
    } else {
      problems.push_back(where + ".kind \"" + *kind +
                         "\" is not one of chamber_offset, imu_dropout, imu_corrupt, imu_drop, imu_bytes_drop, disconnect, "
                         "drop_connection, chamber_corrupt, table_fault, relay_stuck, disk_full");
    }
    faults.push_back(fault);
  }
}

// The pieces of check_campaign, in the order it reads a campaign. Each reads a few keys: small
// functions also keep clang-tidy's optional-access analysis fast (it runs per function, and its
// cost grows steeply with the branches on optionals in one function).

// What a campaign does not say: the daemon's settings.
CampaignSpec default_spec(const DaemonConfig& config) {
  CampaignSpec spec;
  // Real devices: the IMU samples at its own configured rate, which the frame grid must follow.
  spec.rate_hz = config.device_addresses ? config.device_addresses->imu.rate_hz : config.sim.rate_hz;
  spec.time_scale = config.sim.time_scale;
  spec.seed = config.sim.seed;
  spec.chamber.profile.start_C = config.chamber.safe_setpoint_C;
  spec.chamber.tolerance_C = config.chamber.tolerance_C;
  spec.suspenders = config.suspenders;
  return spec;
}

// `rate_hz`, `time_scale`, `seed`: each the daemon's unless given.
void read_run_settings(ObjectReader& r, CampaignSpec& spec) {
  if (auto v = r.number_in("rate_hz", 1e-3)) spec.rate_hz = *v;
  if (auto v = r.number_in("time_scale", 0, 1e6)) spec.time_scale = *v;
  if (auto v = r.integer("seed", 0, std::numeric_limits<std::int64_t>::max())) spec.seed = static_cast<std::uint64_t>(*v);
}

// `estimators`: known names, each once (in place of those the program's parts would choose).
void read_estimator_list(const json& estimators, CampaignSpec& spec, std::vector<std::string>& problems) {
  spec.estimators.clear();
  if (!estimators.is_array()) {
    problems.push_back("campaign.estimators must be an array of names");
    return;
  }
  for (const json& e : estimators) {
    if (!e.is_string()) {
      problems.push_back("campaign.estimators must hold names (strings)");
      continue;
    }
    const auto name = e.get<std::string>();
    const auto& known = known_estimators();
    if (std::find(known.begin(), known.end(), name) == known.end()) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      problems.push_back("campaign.estimators: unknown estimator \"" + name + "\" (known: " + list + ")");
    } else if (spec.has_estimator(name)) {
      problems.push_back("campaign.estimators: \"" + name + "\" is listed twice");
    } else {
      spec.estimators.push_back(name);
    }
  }
}

// The program's parts (one, or a list), each a built-in name or an inline program; `malformed`
// when one is not of either form. Empty when any part is missing.
std::vector<json> program_parts(const json& program_spec, std::vector<std::string>& problems, bool& malformed) {
  std::vector<json> parts;
  if (program_spec.is_array()) {
    if (program_spec.empty()) {
      problems.push_back("campaign.program must not be an empty list");
      malformed = true;
    }
    for (std::size_t i = 0; i < program_spec.size(); ++i) {
      if (auto p = program_item(program_spec[i], "campaign.program[" + std::to_string(i) + "]", problems, malformed))
        parts.push_back(std::move(*p));
    }
  } else if (auto p = program_item(program_spec, "campaign.program", problems, malformed)) {
    parts.push_back(std::move(*p));
  }
  if (parts.size() != (program_spec.is_array() ? program_spec.size() : 1)) parts.clear();
  return parts;
}

// The program compiled against the table's limits: its JSON and label in `spec`. False when it
// does not compile (a problem says why).
bool compile_program_spec(const json& program_json, const json& program_spec, bool builtin_full,
                          const DaemonConfig& config, CampaignSpec& spec, motion::Program& program,
                          std::vector<std::string>& problems) {
  try {
    program = motion::compile_program(program_json.dump(), config.table_limits);
    spec.program_json = program_json.dump();
    if (builtin_full) {
      spec.program_label = "full";
    } else if (program_spec.is_string()) {
      spec.program_label = program_spec.get<std::string>();
    } else if (program_spec.is_array()) {
      spec.program_label = program.name;
    } else {
      spec.program_label = "inline:" + program.name;
    }
    return true;
  } catch (const std::exception& e) {
    problems.push_back(std::string("campaign.program: ") + e.what());
    return false;
  }
}

// `program`: its parts, joined when several, compiled. True when `program` holds it. A part of
// the wrong form makes every problem so far one of form (`form_problems`).
bool read_program(const json& program_spec, bool builtin_full, const DaemonConfig& config, CampaignSpec& spec,
                  motion::Program& program, std::size_t& form_problems, std::vector<std::string>& problems) {
  bool malformed_program = false;
  const std::vector<json> parts = program_parts(program_spec, problems, malformed_program);
  if (malformed_program) form_problems = problems.size();
  if (parts.empty()) return false;
  if (parts.size() == 1) return compile_program_spec(parts.front(), program_spec, builtin_full, config, spec, program, problems);
  const std::optional<json> joined = join_programs(parts, config.table_limits, problems);
  return joined && compile_program_spec(*joined, program_spec, builtin_full, config, spec, program, problems);
}

// The program against the table's limits, once per segment, axis and limit: the motion library
// reports a limit at every instant it is exceeded; one line per segment, axis and limit is what
// a person needs, with the count of the others.
void check_program_limits(const motion::Program& program, const DaemonConfig& config, std::vector<std::string>& problems) {
  std::vector<std::pair<std::string, int>> grouped;
  for (const auto& p : motion::validate_program(program, config.table_limits)) {
    std::string key = p;
    const auto t0 = key.find(" (t=");
    const auto t1 = t0 == std::string::npos ? t0 : key.find(" s)", t0);
    if (t1 != std::string::npos) key.erase(t0, t1 + 3 - t0);
    auto it = std::find_if(grouped.begin(), grouped.end(), [&](const auto& g) { return g.first == key; });
    if (it == grouped.end()) {
      grouped.emplace_back(key, 0);
      problems.push_back("campaign.program: " + p);
    } else {
      ++it->second;
    }
  }
  for (std::size_t i = 0, k = problems.size() - grouped.size(); i < grouped.size(); ++i, ++k)
    if (grouped[i].second > 0) problems[k] += " (and " + std::to_string(grouped[i].second) + " more times)";
}

// The estimators: what the program's parts were made for decides them unless the campaign lists
// them ({"program": "navigation"} runs stage 3); a listed one needs what its stage needs.
void check_program_estimators(const CampaignCheck& check, bool listed, CampaignSpec& spec,
                              std::vector<std::string>& problems) {
  RecordingMeta meta;
  meta.segments = check.segments;
  meta.program_json = spec.program_json;
  if (!listed) {
    for (const pipeline::Stage stage : pipeline::stages_for_parts(meta))
      if (std::find(kOnlineStages.begin(), kOnlineStages.end(), stage) != kOnlineStages.end())
        spec.estimators.emplace_back(pipeline::names_of(stage).estimator);
  }
  for (const std::string& name : spec.estimators) {
    const auto stage = pipeline::stage_of_estimator(name);
    if (!stage) continue;
    if (const auto why = pipeline::requirement_unmet(*stage, pipeline::feed(*stage, meta, true).segments))
      problems.push_back("estimator \"" + name + "\": " + *why);
  }
}

// A compiled program: its limits, duration and segments, and the estimators that run on it.
void check_compiled_program(const motion::Program& program, const DaemonConfig& config, bool estimators_listed,
                            CampaignCheck& check, CampaignSpec& spec) {
  check_program_limits(program, config, check.problems);
  check.duration_s = program.duration_s();
  check.segments = program.segments();
  if (check.duration_s > config.campaign.max_duration_s)
    check.problems.push_back("campaign.program lasts " + number_text(check.duration_s) + " s, more than the limit of " +
                             number_text(config.campaign.max_duration_s) + " s");
  check_program_estimators(check, estimators_listed, spec, check.problems);
}

// `truth`: the simulated IMU's errors; the daemon's when not given.
void read_truth(const json* truth, const DaemonConfig& config, CampaignSpec& spec, CampaignCheck& check) {
  if (truth != nullptr) {
    if (auto m = read_model(*truth, "campaign.truth", config, check.problems, check.malformed)) spec.truth = *m;
  } else if (!config.default_truth_json.empty()) {
    spec.truth = imu_model_from_json_text(config.default_truth_json, "config.sim.truth");
  } else if (auto m = read_model(json(config.sim.truth), "config.sim.truth", config, check.problems, check.malformed)) {
    spec.truth = *m;
  }
  if (spec.truth.frame != "instrument") check.problems.push_back("campaign.truth must be in the instrument frame");
}

// `navigation_model`: stage 3's model, with the navigation estimator only.
void read_navigation_model(const json& nav_model, const DaemonConfig& config, CampaignSpec& spec, CampaignCheck& check) {
  if (!spec.has_estimator("navigation"))
    check.problems.push_back("campaign.navigation_model is given but the \"navigation\" estimator is not listed");
  if (auto m = read_model(nav_model, "campaign.navigation_model", config, check.problems, check.malformed))
    spec.navigation_model = *m;
}

// `model`: the model the calibration stages start from, or the campaign whose model it is.
void read_start_model(const json& start_model, const DaemonConfig& config, CampaignSpec& spec, CampaignCheck& check) {
  if (std::none_of(spec.estimators.begin(), spec.estimators.end(),
                   [](const std::string& e) { return pipeline::stage_of_estimator(e).has_value(); }))
    check.problems.push_back("campaign.model is given but no calibration estimator (direct, lever-arm, stage3) runs");
  if (start_model.is_number_integer()) {
    spec.start_model_campaign = start_model.get<std::int64_t>();
  } else if (auto m = read_model(start_model, "campaign.model", config, check.problems, check.malformed)) {
    spec.start_model = *m;
    if (m->frame != "instrument" && (spec.has_estimator("direct") || spec.has_estimator("lever-arm")))
      check.problems.push_back("campaign.model is in the " + m->frame +
                               " frame: stages direct and lever-arm start from an instrument-frame model");
  }
}

// `suspenders`: the campaign's own settings of the conditions that hold a run.
void read_campaign_suspenders(const json& suspenders, CampaignSpec& spec, std::vector<std::string>& problems) {
  ObjectReader s(suspenders, "campaign.suspenders", problems);
  if (auto v = s.number_in("settle_s", 0, 86400)) spec.suspenders.settle_s = *v;
  if (auto v = s.number_in("frame_timeout_s", 0.01, 3600)) spec.suspenders.frame_timeout_s = *v;
  if (auto v = s.number_in("chamber_persist_s", 0, 3600)) spec.suspenders.chamber_persist_s = *v;
}

// Real devices (the configuration names their addresses) run at the IMU's rate and take no
// simulated faults.
void check_real_devices(const DaemonConfig& config, const CampaignSpec& spec, bool faults_given,
                        std::vector<std::string>& problems) {
  if (!config.device_addresses) return;
  const double imu_rate_hz = config.device_addresses->imu.rate_hz;
  if (std::abs(spec.rate_hz - imu_rate_hz) > 1e-9 * spec.rate_hz) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "campaign.rate_hz is %g Hz but the IMU runs at %g Hz (config.devices.imu.rate_hz): leave "
                  "rate_hz out or set it to the IMU's rate",
                  spec.rate_hz, imu_rate_hz);
    problems.push_back(text);
  }
  if (faults_given)
    problems.push_back("campaign.sim_faults need simulated devices; the configured devices are real "
                       "(config.devices names their addresses)");
}

// The campaign as stored: every setting explicit, so that a change of the daemon's defaults does
// not change a stored campaign.
json normalized_campaign(const json& campaign, const CampaignSpec& spec, json normalized) {
  normalized["name"] = spec.name;
  normalized["estimators"] = spec.estimators;
  normalized["rate_hz"] = spec.rate_hz;
  normalized["time_scale"] = spec.time_scale;
  normalized["seed"] = spec.seed;
  normalized["truth"] = model_json(spec.truth);
  if (spec.navigation_model) normalized["navigation_model"] = model_json(*spec.navigation_model);
  if (spec.start_model_campaign) normalized["model"] = *spec.start_model_campaign;
  if (spec.start_model) normalized["model"] = model_json(*spec.start_model);
  json steps = json::array();
  for (const motion::SetpointChange& c : motion::changes_of(spec.chamber.profile))
    steps.push_back({{"at_s", c.at_s}, {"setpoint_C", c.setpoint_C}, {"ramp_C_per_min", c.ramp_C_per_min}});
  normalized["chamber"] = {{"setpoint_C", spec.chamber.profile.start_C}, {"tolerance_C", spec.chamber.tolerance_C},
                           {"steps", steps}};
  normalized["suspenders"] = {{"settle_s", spec.suspenders.settle_s},
                              {"frame_timeout_s", spec.suspenders.frame_timeout_s},
                              {"chamber_persist_s", spec.suspenders.chamber_persist_s}};
  if (campaign.contains("sim_faults")) normalized["sim_faults"] = campaign.at("sim_faults");
  if (!spec.imu.serial.empty())
    normalized["imu"] = {{"serial", spec.imu.serial},     {"part_number", spec.imu.part_number},
                         {"firmware", spec.imu.firmware}, {"customer", spec.imu.customer},
                         {"notes", spec.imu.notes}};
  return normalized;
}

}  // namespace

namespace {

// The faults only the devices on the wire (sim-wire) can play, refused on the in-process bench.
void check_faults_need_no_wire(const std::vector<SimFault>& faults, std::vector<std::string>& problems) {
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const std::string where = "campaign.sim_faults[" + std::to_string(i) + "]: ";
    const SimFault::Kind kind = faults[i].kind;
    if (kind == SimFault::Kind::RelayStuck)
      problems.push_back(where + "relay_stuck needs the sim-wire devices (the in-process simulation has no power relay)");
    else if (kind == SimFault::Kind::DropConnection)
      problems.push_back(where + "drop_connection needs the sim-wire devices (the in-process simulation has no "
                                 "connections; use disconnect)");
    else if (kind == SimFault::Kind::ImuBytesDrop || kind == SimFault::Kind::ChamberCorrupt)
      problems.push_back(where + "imu_bytes_drop and chamber_corrupt need the sim-wire devices (the in-process "
                                 "simulation has no link bytes; use imu_corrupt)");
  }
}

}  // namespace

CampaignCheck check_campaign(const json& campaign, const DaemonConfig& config) {
  CampaignCheck check;
  auto& problems = check.problems;
  CampaignSpec spec = default_spec(config);

  // Form first: a problem here is the client's JSON (400), not the campaign's content (422).
  std::size_t form_problems = 0;
  json normalized = json::object();
  {
    ObjectReader r(campaign, "campaign", problems);
    if (!r.is_object()) {
      check.malformed = true;
      return check;
    }
    if (auto v = r.string("name", true)) {
      if (v->empty() || v->size() > 200) problems.push_back("campaign.name must have 1 to 200 characters");
      spec.name = *v;
    }
    const json* program_spec = r.get("program", true);
    // The built-in campaign `full`: the whole method in one run, each program made for its stage
    // (stage 1, lever arms, stage 3 from their models, then the Schuler test of every stage's model).
    const json full_programs = json::array({"direct", "lever-arm", "navigation", "evaluate"});
    const bool builtin_full = program_spec != nullptr && *program_spec == "full";
    if (builtin_full) program_spec = &full_programs;
    // A built-in program with a chamber profile of the same name (thermal, thermal-short) is the
    // built-in thermal campaign: it brings its profile, and its table cycle has no rate segments
    // for stage 1, so no estimator runs online unless asked; stage 2 runs on the whole run (GET
    // .../thermal, `imucal calibrate --stage thermal`).
    const bool builtin_thermal =
        program_spec != nullptr && program_spec->is_string() && motion::is_builtin_chamber(program_spec->get<std::string>());
    read_run_settings(r, spec);
    const json* estimators = r.get("estimators");
    const json* truth = r.get("truth");
    const json* nav_model = r.get("navigation_model");
    const json* start_model = r.get("model");
    const json* chamber = r.get("chamber");
    const json* suspenders = r.get("suspenders");
    const json* faults = r.get("sim_faults");
    const json* imu = r.get("imu");
    r.finish();
    form_problems = problems.size();

    if (estimators != nullptr) {
      read_estimator_list(*estimators, spec, problems);
      form_problems = problems.size();
    }
    if (program_spec != nullptr) {
      motion::Program program;
      if (read_program(*program_spec, builtin_full, config, spec, program, form_problems, problems))
        check_compiled_program(program, config, estimators != nullptr, check, spec);
      normalized["program"] = builtin_full ? json("full") : *program_spec;
    }
    if (spec.rate_hz > config.campaign.max_rate_hz)
      problems.push_back("campaign.rate_hz: " + number_text(spec.rate_hz) + " Hz exceeds the limit of " +
                         number_text(config.campaign.max_rate_hz) + " Hz");
    read_truth(truth, config, spec, check);
    if (nav_model != nullptr) read_navigation_model(*nav_model, config, spec, check);
    if (start_model != nullptr) read_start_model(*start_model, config, spec, check);
    if (chamber != nullptr) {
      check_chamber(*chamber, config, check.duration_s, spec.chamber, problems, check.malformed);
    } else if (builtin_thermal) {
      check_chamber(*program_spec, config, check.duration_s, spec.chamber, problems, check.malformed);
    }
    if (suspenders != nullptr) read_campaign_suspenders(*suspenders, spec, problems);
    if (faults != nullptr) check_faults(*faults, check.duration_s, spec.faults, problems);
    if (config.devices == "sim") check_faults_need_no_wire(spec.faults, problems);
    if (imu != nullptr) check_imu(*imu, spec.imu, problems);
    check_real_devices(config, spec, faults != nullptr, problems);
  }
  check.malformed = check.malformed || form_problems > 0;  // or a path where a name is asked (above)
  if (!problems.empty()) return check;

  spec.normalized = normalized_campaign(campaign, spec, std::move(normalized));
  check.spec = std::move(spec);
  return check;
}

void resolve_named_models(DaemonConfig& config) {
  namespace fs = std::filesystem;
  config.named_models.clear();
  const fs::path dir = fs::path(config.sim.truths_dir).is_absolute() ? fs::path(config.sim.truths_dir)
                                                                     : fs::path(config.data_dir) / config.sim.truths_dir;
  config.sim.truths_dir = dir.string();
  // The built-in truths first: a file of the folder with the same name replaces one.
  config.named_models[kBuiltinNavGradeTruth] =
      imu_model_to_json_text(imu_model_from_json_text(builtin::kNavGradeTruth, "the built-in truth nav-grade"));
  std::error_code ec;
  if (fs::is_directory(dir, ec)) {
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const fs::path& p = entry.path();
      const std::string name = p.stem().string();
      if (p.extension() != ".json" || name.empty() || looks_like_path(name) || name == "ideal") continue;
      // Regular files of a sane size only: a FIFO or a device in the folder must not hang or
      // flood the daemon's start.
      std::error_code fec;
      if (!fs::is_regular_file(p, fec) || fs::file_size(p, fec) > kNamedModelMaxBytes || fec) {
        spdlog::warn("truths folder: {} skipped (not a regular file of at most {} bytes)", p.string(), kNamedModelMaxBytes);
        continue;
      }
      try {
        config.named_models[name] = imu_model_to_json_text(read_imu_model_file(p.string()));
      } catch (const std::exception& e) {
        spdlog::warn("truths folder: {} skipped: {}", p.string(), e.what());
      }
    }
  }
  config.default_truth_json.clear();
  const std::string& truth = config.sim.truth;
  if (truth == "ideal") return;
  if (const auto it = config.named_models.find(truth); it != config.named_models.end()) {
    config.default_truth_json = it->second;
    return;
  }
  try {
    config.default_truth_json = imu_model_to_json_text(read_imu_model_file(truth));
  } catch (const std::exception& e) {
    throw ConfigError("config.sim.truth '" + truth + "': neither a model of the truths folder " + dir.string() +
                      " nor a readable imucal-imu-model/1 file: " + e.what());
  }
}

std::vector<NamedTruth> named_truths(const DaemonConfig& config) {
  std::vector<NamedTruth> out;
  out.push_back({"ideal", "an error-free, noise-free IMU (nothing to calibrate: every sigma tiny)", true});
  for (const auto& [name, text] : config.named_models) {
    const bool builtin = name == kBuiltinNavGradeTruth &&
                         text == imu_model_to_json_text(imu_model_from_json_text(builtin::kNavGradeTruth, "nav-grade"));
    std::string description;
    const json model = json::parse(text, nullptr, false);
    if (model.is_object() && model.contains("comment") && model.at("comment").is_string())
      description = model.at("comment").get<std::string>();
    if (builtin) description = "a realistic navigation-grade FOG IMU with noise (built in: examples/truth-nav-grade.json)";
    if (description.empty()) description = "the model " + name + ".json of the truths folder";
    out.push_back({name, description, builtin});
  }
  return out;
}

CampaignCheck check_campaign_text(const std::string& json_text, const DaemonConfig& config) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::parse_error& e) {
    CampaignCheck check;
    check.malformed = true;
    check.problems.push_back(std::string("not valid JSON: ") + e.what());
    return check;
  }
  return check_campaign(j, config);
}

std::int64_t store_campaign(DaemonDb& db, const CampaignCheck& check, const std::string& reason) {
  const CampaignSpec& spec = expect_value(check.spec, "the spec of the campaign to store (only a valid one is stored)");
  std::optional<CampaignUnit> unit;
  if (!spec.imu.serial.empty()) unit = CampaignUnit{spec.imu.serial, spec.imu.part_number};
  return db.insert_campaign(spec.name, spec.normalized.dump(), spec.program_label, check.duration_s, reason, unit);
}

motion::Program compile_campaign_program(const CampaignSpec& spec, const DaemonConfig& config) {
  return motion::compile_program(spec.program_json, config.table_limits);
}

}  // namespace imucal::daemon
