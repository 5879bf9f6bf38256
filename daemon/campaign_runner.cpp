#include "daemon/campaign_runner.hpp"

#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <spdlog/spdlog.h>

#include "daemon/campaign/campaign.hpp"
#include "daemon/service.hpp"

namespace imucal::daemon {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {

// Who the audit trail and an override name: the person running it, not the program (as imucald
// names the signed-in user).
std::string operator_name(const CampaignRunOptions& options) {
  if (!options.operator_name.empty()) return options.operator_name;
  const char* user = std::getenv("USER");
  return user != nullptr && *user != '\0' ? user : "imucal";
}

}  // namespace

namespace {

// What stops a run before it starts (exit status 2): a bad configuration or campaign file.
struct NotRunnable : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The daemon's configuration for a regression run: the file's limits and site, on the simulated
// bench always (a regression run must never reach the real devices a daemon's configuration
// names), as fast as it goes unless the campaign says otherwise.
DaemonConfig runner_config(const CampaignRunOptions& options) {
  DaemonConfig config;
  try {
    if (!options.config_file.empty()) config = load_config_file(options.config_file);
    config.data_dir = options.data_dir;
    config.devices = "sim";
    config.device_addresses.reset();
    config.sim.time_scale = 0.0;
    config.operator_token = "campaign-run-local-operator";  // no HTTP here: keeps Auth from generating a token file
    config.queue_autostart = true;
    // The campaign file is its author's, run on their machine: it may name model files by path.
    config.campaign_file_paths = true;
    resolve_named_models(config);
  } catch (const std::exception& e) {
    throw NotRunnable(e.what());
  }
  return config;
}

// The campaign file read and checked (the time scale of the options overriding its own).
CampaignCheck read_campaign(const std::string& campaign_file, const CampaignRunOptions& options,
                            const DaemonConfig& config) {
  std::ifstream in(campaign_file);
  if (!in) throw NotRunnable(campaign_file + ": cannot read");
  std::stringstream text;
  text << in.rdbuf();
  json campaign;
  try {
    campaign = json::parse(text.str());
    if (options.time_scale && campaign.is_object()) campaign["time_scale"] = *options.time_scale;
  } catch (const json::exception& e) {
    throw NotRunnable(campaign_file + ": not valid JSON: " + e.what());
  }
  CampaignCheck check = check_campaign(campaign, config);
  if (!check.spec) {
    std::string why = campaign_file + ": the campaign is invalid:";
    for (const auto& p : check.problems) why += "\n  - " + p;
    throw NotRunnable(why);
  }
  return check;
}

// Waits for the run to end (or be interrupted), with a progress line every 5 % when asked.
void wait_for_the_end(Service& service, std::int64_t id, bool progress) {
  int last_pct = -1;
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const auto row = service.db().campaign(id);
    if (!row) throw std::runtime_error("campaign disappeared from the database");
    const int pct = row->duration_s > 0 ? static_cast<int>(100.0 * row->program_time_s / row->duration_s) : 0;
    if (progress && pct / 5 != last_pct / 5) {
      std::fprintf(stderr, "\rcampaign %lld '%s': %s %3d %%", static_cast<long long>(id), row->name.c_str(),
                   std::string(to_string(row->state)).c_str(), pct);
      std::fflush(stderr);
      last_pct = pct;
    }
    if (is_final(row->state) || row->state == RunState::Interrupted) return;
  }
}

// The ended run as the command reports it; its model written where the options say.
void read_outcome(Service& service, const DaemonConfig& config, const CampaignRunOptions& options, CampaignRunResult& out) {
  const auto row = service.db().campaign(out.id);
  if (!row) throw std::runtime_error("campaign disappeared from the database");
  out.state = std::string(to_string(row->state));
  out.program_s = row->program_time_s;
  out.frames = row->frames;
  out.run_db = (std::filesystem::path(config.data_dir) / row->run_db).string();
  out.error = row->error.value_or("");
  if (row->results_json) out.results = json::parse(*row->results_json);
  out.has_model = row->model_json.has_value();
  if (row->model_json && !options.model_out.empty()) {
    std::ofstream model(options.model_out);
    if (!model) throw std::runtime_error(options.model_out + ": cannot write");
    model << *row->model_json << "\n";
  }
  out.exit_code = row->state == RunState::Done ? 0 : 1;
}

}  // namespace

CampaignRunResult run_campaign_file(const std::string& campaign_file, const CampaignRunOptions& options) {
  CampaignRunResult out;
  try {
    const DaemonConfig config = runner_config(options);
    const CampaignCheck check = read_campaign(campaign_file, options, config);
    // The progress line and the summary say what a person needs; warnings (alarms) still show.
    if (options.progress) spdlog::set_level(spdlog::level::warn);
    Service service(config);
    service.start(false, false);  // no HTTP, and no stand of the lab
    out.id = store_campaign(service.db(), check, "imucal campaign run " + campaign_file);
    const auto t0 = Clock::now();
    // Started as imucald starts a campaign: the reference equipment judged by the same code.
    const auto started = service.api().command_campaign(
        out.id, Command::Start,
        {operator_name(options), "campaign run", options.override_overdue, "--override-overdue",
         "run it again with --override-overdue REASON (kept in the audit trail and stated on the run's certificate)"});
    // Not started: overdue equipment without an override, or an override that gives no reason.
    if (started.status == 400 || (started.status == 409 && started.extra.contains("overdue"))) {
      service.stop();
      out.exit_code = 2;
      out.state = "created";
      out.error = started.error;
      return out;
    }
    if (started.status != 200) throw std::runtime_error(started.error);
    out.override_overdue = service.api().overdue_override_json(out.id);
    wait_for_the_end(service, out.id, options.progress);
    out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
    service.stop();
    if (options.progress) std::fprintf(stderr, "\n");
    read_outcome(service, config, options, out);
  } catch (const NotRunnable& e) {
    out.exit_code = 2;
    out.error = e.what();
  } catch (const std::exception& e) {
    out.exit_code = 1;
    out.error = e.what();
  }
  return out;
}

}  // namespace imucal::daemon
