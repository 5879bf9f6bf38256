#include "daemon/service.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <filesystem>

#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "daemon/analysis/analysis.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/http/http_server.hpp"
#include "daemon/production/lab.hpp"
#include "daemon/production/lab_users.hpp"
#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/journaled_registry.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "daemon/registry/sqlite_registry.hpp"
#include "daemon/subscribers/alarms.hpp"
#include "daemon/source_web_dir.hpp"

namespace imucal::daemon {

namespace fs = std::filesystem;

namespace {

std::string find_web_dir(const std::string& configured) {
  if (!configured.empty()) return configured;
  std::error_code ec;
  if (fs::is_directory("web", ec)) return "web";
  const std::string built_from = source_web_dir();
  if (!built_from.empty() && fs::is_directory(built_from, ec)) return built_from;
  return {};
}

// The registry the configuration names: the lab's PostgreSQL server (registry.postgresql), else
// the daemon's own database numbering from the site's sequence file, as before issue 38. The
// server's writes wait in a journal in the data directory while it is away (journaled_registry.hpp),
// tried again every few seconds by the registry's own thread: a stand idle between runs calls it
// for nothing, and the journal should not wait for its next run.
std::unique_ptr<Registry> make_registry(const DaemonConfig& config, DaemonDb& db, CertificateSequence& sequence) {
  if (config.registry.postgresql.empty()) {
    const fs::path limits = fs::path(config.limits_file).is_absolute() ? fs::path(config.limits_file)
                                                                        : fs::path(config.data_dir) / config.limits_file;
    return std::make_unique<SqliteRegistry>(
        db, sequence, registry_stand(config), limits.string());
  }
  auto connect = [conninfo = config.registry.postgresql, stand = registry_stand(config)] {
    auto registry = std::make_unique<PostgresRegistry>(conninfo, stand);
    // The connection string is not logged: it may hold a password.
    spdlog::info("registry: on the PostgreSQL server of registry.postgresql (schema version {}), as stand '{}'",
                 registry->schema_version(), registry->stand());
    return registry;
  };
  JournaledRegistry::Options options;
  options.retry_every = std::chrono::seconds(10);
  return std::make_unique<JournaledRegistry>(connect, (fs::path(config.data_dir) / "registry-journal.jsonl").string(),
                                             options);
}

}  // namespace

sigset_t block_termination_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  ::signal(SIGPIPE, SIG_IGN);
  return signals;
}

void setup_logging(const LogConfig& log, const std::string& data_dir) {
  std::vector<spdlog::sink_ptr> sinks;
  sinks.push_back(std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  std::string file_error;
  if (!log.file.empty()) {
    const fs::path path = fs::path(log.file).is_absolute() ? fs::path(log.file) : fs::path(data_dir) / log.file;
    try {
      fs::create_directories(path.parent_path());
      sinks.push_back(std::make_shared<spdlog::sinks::rotating_file_sink_mt>(
          path.string(), static_cast<std::size_t>(log.max_size_mb * 1024 * 1024), static_cast<std::size_t>(log.max_files)));
    } catch (const std::exception& e) {
      file_error = e.what();
    }
  }
  auto logger = std::make_shared<spdlog::logger>("imucald", sinks.begin(), sinks.end());
  logger->set_level(spdlog::level::from_str(log.level));
  logger->flush_on(spdlog::level::warn);
  spdlog::set_default_logger(logger);
  spdlog::flush_every(std::chrono::seconds(2));
  if (!file_error.empty()) spdlog::warn("no log file: {}", file_error);
}

Service::Service(DaemonConfig config) : config_(std::move(config)) {
  std::error_code ec;
  fs::create_directories(config_.data_dir, ec);
  if (ec) throw ConfigError("cannot create the data directory '" + config_.data_dir + "': " + ec.message());
  // One daemon per data directory: a second one would run the same queue on the same files.
  const std::string lock_path = (fs::path(config_.data_dir) / "imucald.lock").string();
  lock_fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (lock_fd_ < 0) throw ConfigError("cannot open " + lock_path);
  if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    ::close(lock_fd_);
    lock_fd_ = -1;
    throw ConfigError("another imucald is using the data directory '" + config_.data_dir + "'");
  }
  // The truths a campaign may name, read now: no request reads a file the client names.
  resolve_named_models(config_);
  db_ = std::make_unique<DaemonDb>((fs::path(config_.data_dir) / "imucald.db").string());
  const auto recovered = db_->recover_after_restart("found active at start-up: the daemon stopped without parking it "
                                                   "(crash or power loss)");
  for (const auto id : recovered) {
    spdlog::warn("campaign {} was active when the daemon stopped; it is now interrupted (resume to continue)", id);
    // The alarms the change implies (an interruption raises one), as for the sequencer's changes;
    // nobody is connected yet to be told, GET /api/alarms lists them.
    const auto transitions = db_->transitions(id);
    if (transitions.empty()) continue;
    const auto& last = transitions.back();
    if (last.from) (void)apply_transition_alarms(*db_, id, *last.from, last.to, last.reason);
  }
  certificate_sequence_ = std::make_unique<CertificateSequence>(certificate_sequence_path(config_));
  registry_ = make_registry(config_, *db_, *certificate_sequence_);
  // The runs recovery interrupted, in the units' history as they now are (no run subscriber saw
  // that change); a registry that cannot take them now has them at their next transition.
  for (const auto id : recovered) {
    try {
      (void)record_unit_calibration(*db_, *registry_, id);
    } catch (const std::exception& e) {
      spdlog::error("campaign {}: its interruption could not be recorded in the registry: {}", id, e.what());
    }
  }
  auth_ = std::make_unique<Auth>(config_, config_.data_dir);
  // The lab's accounts sign in here too (production/lab_users.hpp).
  auth_->set_lab_users([registry = registry_.get()] { return lab_user_entries(registry->users()); });
  sequencer_ = std::make_unique<Sequencer>(config_, *db_);
  assemble_certificates();
  assemble_archive();
  api_ = std::make_unique<Api>(config_, *db_, *registry_, *sequencer_, *auth_, *audit_, *certificates_);
  // The audit trail: the configuration and the users this start loaded, then what recovery did.
  nlohmann::json users = nlohmann::json::array();
  for (const auto& u : config_.users) users.push_back({{"name", u.name}, {"role", to_string(u.role)}});
  audit_->append("imucald", "service.started", "imucald",
              {{"version", api_->status().at("version")}, {"devices", config_.devices}, {"data_dir", config_.data_dir},
               {"config_dir", config_.config_dir}, {"site", config_.site_name}, {"users", users},
               {"signing_key", signing_key_path(config_)}, {"interrupted_at_start", recovered}});
  web_dir_ = find_web_dir(config_.http.web_dir);
  files_ = std::make_unique<StaticFiles>(web_dir_);
}

// The audit trail through the sequencer's ordered writes, the certificates' issuer, and the run
// subscriber that audits each transition and issues a run's certificate at its end (subscribed
// here, before the sequencer starts: no run is active yet).
void Service::assemble_certificates() {
  Sequencer* sequencer = sequencer_.get();
  audit_ = std::make_unique<AuditTrail>(*registry_, [sequencer](const std::string& what, std::function<void()> write) {
    sequencer->write_db(what, std::move(write));
  });
  // A certificate states the campaign as the API shows it, which the API builds (api_ exists by
  // the time anything is issued: no run starts before start()).
  certificates_ = std::make_unique<CertificateIssuer>(config_, *db_, *registry_, *audit_,
                                                      [this](const CampaignRow& row) { return api_->detail_json(row); });
  AuditTrail* audit = audit_.get();
  CertificateIssuer* certificates = certificates_.get();
  certificates_subscriber_ = std::make_unique<CertificatesSubscriber>(
      [audit](const std::string& actor, const std::string& action, const std::string& subject,
              const nlohmann::json& details) { audit->append(actor, action, subject, details); },
      [certificates](std::int64_t id, const std::string& reason) { (void)certificates->issue(id, reason); });
  sequencer_->subscribe(*certificates_subscriber_);
  // Through the sequencer's ordered writes, as the audit trail: behind the writes that wait.
  DaemonDb* db = db_.get();
  Registry* registry = registry_.get();
  calibrations_subscriber_ = std::make_unique<CalibrationsSubscriber>([sequencer, db, registry](std::int64_t id) {
    sequencer->write_db("campaign " + std::to_string(id) + "'s calibration in the registry",
                        [db, registry, id] { (void)record_unit_calibration(*db, *registry, id); });
  });
  sequencer_->subscribe(*calibrations_subscriber_);
}

// With registry.archive_dir: each run that ended leaves its bundle in the lab's shared archive
// (production/lab.hpp names its places), for the stands whose unit pages link to it.
void Service::assemble_archive() {
  if (config_.registry.archive_dir.empty()) return;
  archive_subscriber_ = std::make_unique<ArchiveSubscriber>(
      [db = db_.get(), data_dir = config_.data_dir, archive = archive_dir_path(config_),
       stand = registry_stand(config_)](std::int64_t id) {
        const auto row = db->campaign(id);
        if (!row || row->run_db.empty()) return;  // never started: nothing recorded
        const auto run = std::filesystem::path(data_dir) / row->run_db;
        if (!std::filesystem::exists(run)) return;
        // The bundle of GET /api/campaigns/{id}/recording, under the same top folder, replaced whole.
        const std::filesystem::path tar = archived_recording(archive, stand, id);
        std::filesystem::create_directories(tar.parent_path());
        write_recording_tar(run.string(), tar.string(), "campaign-" + std::to_string(id) + "-recording");
        spdlog::info("campaign {}: its recording is archived as {}", id, tar.string());
      });
  sequencer_->subscribe(*archive_subscriber_);
}

Service::~Service() {
  stop();
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

void Service::start(bool http, bool in_lab) {
  HttpServer* server = nullptr;
  if (http) {
    server_ = std::make_unique<HttpServer>(config_.http, *api_, *sequencer_, *files_);
    server = server_.get();
    api_->set_event_listener([server](const nlohmann::json& event) { server->broadcast_event(event); });
    server_->start(config_.http.host, config_.http.port);
  }
  // The run's events to the live view.
  if (server) sequencer_->set_event_listener([server](const nlohmann::json& event) { server->broadcast_event(event); });
  sequencer_->start();
  if (in_lab) start_heartbeat();
}

// This stand in the lab's registry: registered now, its state reported every registry.heartbeat_s
// from its own database (what it runs, its alarms), on the heartbeat's own thread.
void Service::start_heartbeat() {
  StandRow identity;
  identity.name = registry_stand(config_);
  identity.bench = config_.devices;
  identity.url = stand_url(config_, server_ ? server_->port() : config_.http.port);
  identity.version = api_->status().at("version").get<std::string>();
  const auto period = std::chrono::milliseconds(std::max<std::int64_t>(
      1, static_cast<std::int64_t>(config_.registry.heartbeat_s * 1000.0)));
  limits_follower_ = std::make_unique<LimitsFollower>(
      *db_, [api = api_.get()] { return api->limits().document(); },
      [this](const std::optional<std::set<std::string>>& changed, const std::string& reason) {
        reissue_under_new_limits(*registry_, *db_, *certificates_, changed, reason);
      });
  // Each beat also follows the lab's limits (limits_follower.hpp): one query, and reissues only
  // when another stand put new ones.
  heartbeat_ = std::make_unique<StandHeartbeat>(*registry_, identity, period, [this] {
    limits_follower_->follow();
    return stand_state_json(*db_, config_, sequencer_->active_id(), now_unix_ms());
  });
}

void Service::stop() {
  if (stopped_) return;
  stopped_ = true;
  if (heartbeat_) heartbeat_->stop();  // before what its state is read from stops
  if (api_) {
    api_->set_shutting_down();
    api_->set_event_listener({});  // the analyses' progress no longer reaches the server
  }
  if (sequencer_) sequencer_->shutdown();
  if (server_) server_->stop();
  spdlog::default_logger()->flush();
}

std::uint16_t Service::port() const { return server_ ? server_->port() : 0; }

}  // namespace imucal::daemon
