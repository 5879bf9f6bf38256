// The daemon's configuration: one JSON file (docs/daemon.md, examples/imucald.json), every key
// optional, overridden by command-line flags. The defaults run on a fresh machine with no file:
// simulated devices, data in ./data, HTTP on 127.0.0.1:8080.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/recording.hpp"
#include "daemon/config/device_config.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

// A configuration that cannot be used; the message lists every problem, one per line.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class Role { Viewer, Operator };
const char* to_string(Role role);

struct UserEntry {
  std::string name;
  Role role = Role::Viewer;
  std::string password_hash;  // for the browser sign-in, made by `imucal passwd` (empty: none)
  std::string token;     // for `Authorization: Bearer` (empty: none)
};

struct ChamberConfig {
  motion::ChamberLimits limits;      // what the chamber can do (its range, its fastest ramp)
  double safe_setpoint_C = 25.0;     // where every exit path leaves the chamber
  double tolerance_C = 2.0;          // default band of a campaign
  double wait_timeout_s = 3600.0;    // longest wait for the chamber to reach a set point
};

// Defaults of the simulated devices (a campaign may override rate, time scale, seed, truth).
struct SimDefaults {
  double rate_hz = 100.0;
  double time_scale = 10.0;    // program seconds per wall second; 0: as fast as possible
  // sim-wire's program seconds per wall second (1: real time). Not the campaign's time_scale: the
  // wire cannot go as fast as possible, and a fault must outlast the drivers' timeouts in wall time.
  double wire_time_scale = 1.0;
  std::uint64_t seed = 1;
  std::string truth = "ideal"; // "ideal", a truth's name (truths_dir) or a path to an imucal-imu-model/1 file
  // The folder of the simulated truths a campaign may name (docs/api.md, "Campaign JSON"): every
  // NAME.json in it; relative to the data directory.
  std::string truths_dir = "truths";
  double chamber_tau_s = 20.0; // first-order time constant of the simulated chamber
  double home_time_s = 5.0;    // simulated homing time
};

// The suspenders' settings (daemon/run/suspenders.hpp): the daemon's defaults (configuration
// `suspenders`) and a campaign's own.
struct SuspenderSettings {
  double settle_s = 10.0;          // a cleared condition must stay clear this long before resuming
  double frame_timeout_s = 1.0;    // no IMU frame for this long (device time): frames missing
  double chamber_persist_s = 2.0;  // out of band for this long before suspending (noise immunity)
};

struct RecorderConfig {
  double commit_interval_s = 1.0;
  std::int64_t queue_frames = 1 << 18;  // bound of the recorder queue
};

struct HttpConfig {
  std::string host = "127.0.0.1";
  std::uint16_t port = 8080;
  std::int64_t body_limit_bytes = 1 << 20;
  double request_timeout_s = 30.0;
  double session_idle_s = 12 * 3600.0;
  double live_rate_hz = 10.0;
  std::int64_t live_queue = 64;  // messages per WebSocket client before the oldest are dropped
  // Open connections (HTTP and WebSocket) from one address; more are answered 429 and closed. A
  // browser opens about six per site and a socket per tab.
  std::int64_t max_connections_per_client = 64;
  // Analyses and plans waiting or computing at once (two compute, the rest wait); more are 429.
  std::int64_t max_analysis_jobs = 16;
  // The recording bundles kept in DATA_DIR/exports/ (any viewer can have every run's written):
  // past this many bytes the least recently written go, to be written again when asked.
  std::int64_t exports_max_bytes = std::int64_t{10} << 30;
  int threads = 1;
  std::string web_dir;  // empty: ./web if it exists, else the source tree's web/
  // Reverse proxies whose X-Forwarded-For names the client (client_address.hpp); none by default.
  std::vector<std::string> trusted_proxies;
};

struct LogConfig {
  std::string level = "info";
  std::string file = "logs/imucald.log";  // relative to the data directory; "" for none
  double max_size_mb = 10.0;
  int max_files = 5;
};

struct CampaignLimits {
  double max_duration_s = 48 * 3600.0;
  double max_rate_hz = 4000.0;
};

// One instrument of the bench's reference equipment, as a calibration certificate names it.
struct ReferenceInstrument {
  std::string make, model, serial;
  std::string calibration_due;          // "YYYY-MM-DD": when its own calibration runs out
  std::string calibration_certificate;  // optional: its own certificate's number
  // Optional: its uncertainty as its certificate states it, free text ("1 arcsec (k=2)").
  std::string uncertainty;
};

// The survey that measured the site's g (`site.gravity_mps2`): who, its certificate (report)
// number, and when the site is to be surveyed again. Its uncertainty is not configured: it is the
// 1-sigma the calibration uses for a measured g (earth::site_gravity_sigma_mps2), one number.
struct GravitySurvey {
  std::string surveyed_by;
  std::string calibration_certificate;
  std::string calibration_due;  // "YYYY-MM-DD"
};

// The reference equipment of the bench (`reference_equipment`): printed on every certificate; a
// campaign does not start while one is past its due date unless an operator overrides it
// (daemon/production/reference_equipment.hpp).
struct ReferenceEquipment {
  std::optional<ReferenceInstrument> table, chamber;
  std::optional<GravitySurvey> gravity;
};

// Certificate numbers (`certificates`, docs/daemon.md "Certificates"): PREFIX-YYYY-NNNNNN, the
// sequence kept in a small file outside the data directory, so that a new data directory never
// hands out a number again.
struct CertificateConfig {
  std::string prefix;         // empty: derived from the site's name (certificate_prefix)
  std::string sequence_file;  // empty: kDefaultSequenceFile; relative: to the configuration file's directory
  static constexpr const char* kDefaultSequenceFile = "imucal-certificate-sequence.json";
  // The lab's Ed25519 key (`imucal keygen`, docs/signing.md): certificates and test reports are
  // signed with it. Empty: nothing is signed. Relative: to the configuration file's directory.
  std::string signing_key_file;
};

// The lab's registry (`registry`, issue 38; daemon/registry/registry.hpp): certificates and their
// numbers, overdue overrides and the audit trail, in the daemon's own database (no `postgresql`)
// or on a lab's PostgreSQL server the stands of a production line share.
struct RegistryConfig {
  std::string postgresql;  // a libpq connection string ("host=db.lab dbname=imucal"); empty: SQLite
  std::string stand;       // this stand's name in a shared registry; empty: the host's name (registry_stand)
  // The lab overview (GET /api/lab): this stand's page as other stands' browsers reach it (empty:
  // stand_url's default), and how often it reports its state to the registry.
  std::string url;
  double heartbeat_s = 5.0;
  // The lab's shared archive of recordings (a directory every stand mounts; empty: none): each
  // ended run's bundle is written there, and a unit's history fetches another stand's recording
  // from it (production/lab.hpp, subscribers/archive.hpp). Relative: to the configuration file's directory.
  std::string archive_dir;
};

struct DaemonConfig {
  std::string site_name = "simulated lab";
  // The directory of the configuration file this came from (empty: none was read); relative
  // paths that belong to the site rather than to one data directory are resolved against it.
  std::string config_dir;
  Site site;
  std::string data_dir = "./data";
  // Acceptance limits per part number (imucal-limits/1, daemon/production/acceptance.hpp); relative
  // to the data directory. A missing file means no limits; the UI writes it (PUT /api/limits).
  std::string limits_file = "limits.json";
  // "sim" (in-process, accelerated), "sim-wire" (simulated devices on loopback through the real
  // drivers) or "real" (the devices named in `device_addresses`, from a `devices` object).
  std::string devices = "sim";
  std::optional<DeviceAddresses> device_addresses;  // set when `devices` named real devices
  motion::TableLimits table_limits;
  // The table's certificate (`table.geometry`, `table.sigma`, `table.certificate`; formats.md
  // `table`): the simulated bench moves with the geometry, and every run's meta records it.
  std::optional<table::TableCertificate> table_certificate;
  ChamberConfig chamber;
  SimDefaults sim;
  SuspenderSettings suspenders;
  RecorderConfig recorder;
  HttpConfig http;
  LogConfig log;
  CampaignLimits campaign;
  std::string operator_token;
  std::vector<UserEntry> users;
  bool queue_autostart = true;  // run queued campaigns after a restart without an operator
  ReferenceEquipment reference_equipment;
  CertificateConfig certificates;
  RegistryConfig registry;
  // Filled by resolve_named_models (daemon/campaign/campaign.hpp) before any campaign is checked:
  // the models of truths_dir by name and the default truth, read once so that no request reads a
  // file (a client names a model, never a path on the daemon's machine).
  std::map<std::string, std::string> named_models;  // name -> imucal-imu-model/1 JSON text
  std::string default_truth_json;                   // sim.truth's model (empty: ideal)
  // `imucal campaign run FILE`: the file's author runs it on their own machine, so its models and
  // chamber profiles may also be files named by path. Never set by imucald.
  bool campaign_file_paths = false;
};

// Parses the configuration; throws ConfigError listing every problem. `source` names it in messages.
DaemonConfig parse_config(const std::string& json_text, const std::string& source);
DaemonConfig load_config_file(const std::string& path);

// A date "YYYY-MM-DD" of the Gregorian calendar as its day number since 1970-01-01, or nothing
// when it is not one (reference_equipment's calibration_due: checked here, compared by it).
std::optional<std::int64_t> date_day_number(const std::string& text);
// The inverse: "YYYY-MM-DD" of a day number since 1970-01-01 (proleptic Gregorian calendar).
std::string date_text(std::int64_t day_number);

// The name this stand's campaigns go by in a shared registry: `registry.stand`, else the host's name.
std::string registry_stand(const DaemonConfig& config);
// This stand's address in the lab overview: registry.url, else http://HOST:PORT with the HTTP
// server's host (the host's name when it listens on every address, 0.0.0.0 or ::) and `port`,
// the port it listens on (the configured one may be 0: any).
std::string stand_url(const DaemonConfig& config, std::uint16_t port);

// The certificate prefix in use: `certificates.prefix`, else the site's name in capitals with
// every run of other characters made one '-' ("simulated lab" -> "SIMULATED-LAB"), at most
// 20 characters, else "IMUCAL".
std::string certificate_prefix(const DaemonConfig& config);
// A path that belongs to the site rather than to one data directory, as configured: resolved
// against the configuration file's directory, or the data directory when the daemon runs without
// a configuration file; an absolute or empty one as it is.
std::string site_path(const DaemonConfig& config, const std::string& path);
// The certificate sequence file: `certificates.sequence_file` (default kDefaultSequenceFile)
// resolved against the configuration file's directory, or the data directory when the daemon
// runs without a configuration file.
std::string certificate_sequence_path(const DaemonConfig& config);
// The signing key's path as configured, resolved as the sequence file's (empty: none configured).
std::string signing_key_path(const DaemonConfig& config);
// The lab's shared archive of recordings (`registry.archive_dir`), resolved the same way (empty: none).
std::string archive_dir_path(const DaemonConfig& config);

// "HOST:PORT" (port 0: any free port). Throws ConfigError.
void parse_listen(const std::string& text, std::string& host, std::uint16_t& port);

}  // namespace imucal::daemon
