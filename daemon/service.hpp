// imucald assembled: the data directory (locked against a second daemon), the daemon database
// with crash recovery, authentication, the sequencer, the API and the HTTP server. Used by
// imucald's main and, in-process, by the tests and `imucal campaign run`.
#pragma once

#include <signal.h>

#include <cstdint>
#include <memory>
#include <string>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/http/api.hpp"
#include "daemon/http/auth.hpp"
#include "daemon/http/static_files.hpp"
#include "daemon/production/certificate_issuer.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/registry/certificate_sequence.hpp"
#include "daemon/production/limits_follower.hpp"
#include "daemon/registry/audit_trail.hpp"
#include "daemon/registry/registry.hpp"
#include "daemon/registry/stand_heartbeat.hpp"
#include "daemon/sequencer/sequencer.hpp"
#include "daemon/subscribers/archive.hpp"
#include "daemon/subscribers/calibrations.hpp"
#include "daemon/subscribers/certificates.hpp"

namespace imucal::daemon {

class HttpServer;

// For a main thread that ends on SIGTERM or SIGINT taken with sigwait(): blocks both in the
// calling thread, before it starts any other (threads inherit the mask, so no worker is ever
// interrupted by them), and ignores SIGPIPE (a peer closing a socket fails that call, not the
// process). Returns the set to sigwait() on.
sigset_t block_termination_signals();

class Service {
 public:
  // Opens (creates) the data directory and the database, marks runs left active by a crash as
  // interrupted. Throws with a message a person can act on.
  explicit Service(DaemonConfig config);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  // Starts the sequencer and, when `http`, the HTTP server on the configured address; when
  // `in_lab`, this stand's registration and heartbeat (an in-process `imucal campaign run` is no
  // stand of the lab: it has no page to link to, and would replace the stand's row of its name).
  void start(bool http = true, bool in_lab = true);
  // Clean shutdown: refuse changes, park the active run (interrupted), close the server.
  void stop();

  std::uint16_t port() const;
  const DaemonConfig& config() const { return config_; }
  DaemonDb& db() { return *db_; }
  Sequencer& sequencer() { return *sequencer_; }
  Auth& auth() { return *auth_; }
  Api& api() { return *api_; }
  const std::string& web_dir() const { return web_dir_; }

 private:
  void assemble_certificates();
  void assemble_archive();
  void start_heartbeat();

  DaemonConfig config_;
  int lock_fd_ = -1;
  std::string web_dir_;
  std::unique_ptr<DaemonDb> db_;
  // The site's certificate sequence file (the SQLite registry numbers from it) and the registry.
  std::unique_ptr<CertificateSequence> certificate_sequence_;
  std::unique_ptr<Registry> registry_;
  std::unique_ptr<Auth> auth_;
  // The audit trail's rule, the certificates' issuing and their run subscriber: declared before the
  // sequencer, which holds the subscriber, so that they outlive it.
  std::unique_ptr<AuditTrail> audit_;
  std::unique_ptr<CertificateIssuer> certificates_;
  std::unique_ptr<CertificatesSubscriber> certificates_subscriber_;
  // The units' calibrations recorded in the registry at each transition (same lifetime rule).
  std::unique_ptr<CalibrationsSubscriber> calibrations_subscriber_;
  // The ended runs' bundles written to the lab's shared archive (registry.archive_dir; none
  // without). Its thread reads the database: declared after it, so it goes first.
  std::unique_ptr<ArchiveSubscriber> archive_subscriber_;
  std::unique_ptr<Sequencer> sequencer_;
  std::unique_ptr<Api> api_;
  std::unique_ptr<StaticFiles> files_;
  std::unique_ptr<HttpServer> server_;
  // This stand's registration and state reports to the registry (issue 38, the lab overview):
  // started by start() once the port is known, stopped first by stop(), declared last so that it
  // goes before the sequencer and the database its state is read from.
  // A lab's limits put on another stand: this stand's certificates follow them at its heartbeat
  // (declared before it, so that it outlives the heartbeat's thread).
  std::unique_ptr<LimitsFollower> limits_follower_;
  std::unique_ptr<StandHeartbeat> heartbeat_;
  bool stopped_ = false;
};

// Sets up spdlog: stderr and, when configured, a rotating file under the data directory.
void setup_logging(const LogConfig& log, const std::string& data_dir);

}  // namespace imucal::daemon
