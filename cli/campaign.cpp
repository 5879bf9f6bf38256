// imucal campaign run: a whole campaign through the daemon's sequencer in-process, on the simulated
// bench in accelerated time (daemon/campaign_runner.hpp).
#include "cli/commands.hpp"

#include <cstdio>

#include <nlohmann/json.hpp>

#include "daemon/campaign_runner.hpp"

namespace imucal::cli {

int run_campaign(const std::string& file, const daemon::CampaignRunOptions& options, bool json) {
  const auto r = daemon::run_campaign_file(file, options);
  const double speed = r.wall_s > 0 ? r.program_s / r.wall_s : 0.0;
  if (json) {
    const nlohmann::json j = {{"id", r.id},         {"state", r.state},         {"program_s", r.program_s},
                              {"wall_s", r.wall_s}, {"speed_factor", speed},    {"frames", r.frames},
                              {"run_db", r.run_db}, {"has_model", r.has_model}, {"results", r.results},
                              {"error", r.error},   {"override_overdue", r.override_overdue}};
    std::printf("%s\n", j.dump().c_str());
  } else if (r.id == 0 || r.state == "created") {  // not run: nothing to sum up but why
    std::fprintf(stderr, "imucal campaign run: %s\n", r.error.c_str());
  } else {
    std::printf("campaign %lld: %s; %.1f s of program in %.2f s (%.0fx real time), %lld frames -> %s\n",
                static_cast<long long>(r.id), r.state.c_str(), r.program_s, r.wall_s, speed,
                static_cast<long long>(r.frames), r.run_db.c_str());
    if (const auto& o = r.override_overdue; o.is_object())
      std::printf("  started with overdue reference equipment, overridden by %s: %s (%s)\n",
                  o.at("by").get<std::string>().c_str(), o.at("reason").get<std::string>().c_str(),
                  o.at("text").get<std::string>().c_str());
    if (!r.error.empty()) std::printf("  error: %s\n", r.error.c_str());
    for (const auto& [name, res] : r.results.items()) std::printf("  %s: %s\n", name.c_str(), res.dump().c_str());
    if (r.has_model && !options.model_out.empty()) std::printf("  model -> %s\n", options.model_out.c_str());
  }
  return r.exit_code;
}

}  // namespace imucal::cli
