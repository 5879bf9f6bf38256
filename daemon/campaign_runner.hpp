// `imucal campaign run FILE`: one whole campaign through the daemon's own sequencer, recorder and
// online estimators, in-process, without HTTP, on the simulated bench as fast as it goes (unless
// the campaign sets a time scale). The regression-test entry point.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace imucal::daemon {

struct CampaignRunOptions {
  std::string config_file;             // optional daemon configuration (limits, site, defaults)
  std::string data_dir = "./data-campaign";
  std::string model_out;               // write the model here (optional)
  std::optional<double> time_scale;    // overrides the campaign's
  bool progress = true;                // progress lines on stderr
  // Who runs it: the audit trail's actor, and the operator an override names (empty: the login
  // name, else "imucal").
  std::string operator_name;
  // Why the campaign may start although reference equipment in the configuration is past its due
  // date; without it such a campaign is refused, as imucald refuses it (Api::command_campaign).
  std::optional<std::string> override_overdue;
};

struct CampaignRunResult {
  // 0 done, 1 failed or aborted, 2 invalid campaign or configuration, or not started (reference
  // equipment past its due date and no override: state "created", error says which and how)
  int exit_code = 1;
  std::int64_t id = 0;
  std::string state;
  double program_s = 0.0, wall_s = 0.0;
  std::int64_t frames = 0;
  std::string run_db;
  std::string error;
  nlohmann::json results = nlohmann::json::object();
  bool has_model = false;
  nlohmann::json override_overdue = nullptr;  // the override the run was started under (docs/api.md)
};

CampaignRunResult run_campaign_file(const std::string& campaign_file, const CampaignRunOptions& options);

}  // namespace imucal::daemon
