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
};

struct CampaignRunResult {
  int exit_code = 1;  // 0 done, 1 failed or aborted, 2 invalid campaign or configuration
  std::int64_t id = 0;
  std::string state;
  double program_s = 0.0, wall_s = 0.0;
  std::int64_t frames = 0;
  std::string run_db;
  std::string error;
  nlohmann::json results = nlohmann::json::object();
  bool has_model = false;
};

CampaignRunResult run_campaign_file(const std::string& campaign_file, const CampaignRunOptions& options);

}  // namespace imucal::daemon
