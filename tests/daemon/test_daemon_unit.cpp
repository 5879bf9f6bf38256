// The daemon's pure parts: the run state machine, the configuration and campaign checks (every
// problem listed, unknown keys refused, comments ignored), static files (no way out of the root),
// the one-time operator token.
#include <filesystem>
#include <future>
#include <fstream>

#include <gtest/gtest.h>

#include "daemon/campaign/campaign.hpp"
#include "daemon/config/config.hpp"
#include "daemon/config/password_hash.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/db/run_state.hpp"
#include "daemon/http/api.hpp"
#include "daemon/http/auth.hpp"
#include "daemon/http/client_address.hpp"
#include "daemon/http/static_files.hpp"
#include "daemon/run/suspenders.hpp"
#include "daemon_fixture.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemon;
using nlohmann::json;

TEST(RunState, NamesRoundTripAndFinalStates) {
  for (const char* name : {"created", "queued", "running", "pausing", "paused", "suspended", "stopping", "aborting",
                           "done", "failed", "aborted", "interrupted"}) {
    const auto s = parse_run_state(name);
    ASSERT_TRUE(s.has_value()) << name;
    EXPECT_EQ(to_string(*s), name);
  }
  EXPECT_FALSE(parse_run_state("idle"));
  EXPECT_TRUE(is_final(RunState::Done));
  EXPECT_TRUE(is_final(RunState::Failed));
  EXPECT_TRUE(is_final(RunState::Aborted));
  EXPECT_FALSE(is_final(RunState::Interrupted));
}

TEST(RunState, CommandsApplyOnlyInTheirStates) {
  EXPECT_EQ(command_target(RunState::Created, Command::Start), RunState::Queued);
  EXPECT_FALSE(command_target(RunState::Queued, Command::Start));
  EXPECT_FALSE(command_target(RunState::Done, Command::Start));
  EXPECT_EQ(command_target(RunState::Running, Command::Pause), RunState::Pausing);
  EXPECT_FALSE(command_target(RunState::Paused, Command::Pause));
  EXPECT_FALSE(command_target(RunState::Running, Command::Resume));  // resume while running
  EXPECT_EQ(command_target(RunState::Paused, Command::Resume), RunState::Running);
  EXPECT_EQ(command_target(RunState::Interrupted, Command::Resume), RunState::Queued);
  EXPECT_FALSE(command_target(RunState::Suspended, Command::Resume));
  EXPECT_EQ(command_target(RunState::Suspended, Command::Stop), RunState::Stopping);
  EXPECT_EQ(command_target(RunState::Queued, Command::Abort), RunState::Aborted);
  EXPECT_EQ(command_target(RunState::Paused, Command::Abort), RunState::Aborting);
  EXPECT_FALSE(command_target(RunState::Aborting, Command::Abort));
  EXPECT_FALSE(command_target(RunState::Done, Command::Abort));
}

// One table for every change: each operator command's target is in it, nothing leaves a final
// state, and the database refuses (with a typed error) what the table does not hold.
TEST(RunState, EveryChangeFollowsTheTransitionTable) {
  const RunState all[] = {RunState::Created, RunState::Queued,   RunState::Running, RunState::Pausing,
                          RunState::Paused,  RunState::Suspended, RunState::Stopping, RunState::Aborting,
                          RunState::Done,    RunState::Failed,   RunState::Aborted, RunState::Interrupted};
  for (const RunState from : all) {
    for (const Command c : {Command::Start, Command::Pause, Command::Resume, Command::Stop, Command::Abort}) {
      if (const auto to = command_target(from, c)) {
        EXPECT_TRUE(transition_allowed(from, *to)) << to_string(from) << " --" << to_string(c) << "--> " << to_string(*to);
      }
    }
    for (const RunState to : all) {
      if (is_final(from)) {
        EXPECT_FALSE(transition_allowed(from, to)) << to_string(from) << " -> " << to_string(to);
      }
    }
    // Only through aborting does an active run end aborted; only the queue (and a resume or a
    // cleared suspender) sets a run running.
    if (is_active(from) && from != RunState::Aborting) {
      EXPECT_FALSE(transition_allowed(from, RunState::Aborted)) << to_string(from);
    }
    if (from != RunState::Queued && from != RunState::Paused && from != RunState::Suspended) {
      EXPECT_FALSE(transition_allowed(from, RunState::Running)) << to_string(from);
    }
    // A crash or a shutdown can meet any active run.
    if (is_active(from)) {
      EXPECT_TRUE(transition_allowed(from, RunState::Interrupted)) << to_string(from);
    }
  }
  DaemonDb db(daemontest::scratch_dir("transitions") + "/imucald.db");
  const auto id = db.insert_campaign("t", "{}", "direct", 10.0, "created by the test");
  EXPECT_TRUE(db.set_state(id, RunState::Queued, "start"));
  try {
    db.set_state(id, RunState::Done, "skipping the run");
    FAIL() << "queued -> done was written";
  } catch (const InvalidTransition& e) {
    EXPECT_EQ(e.from, RunState::Queued);
    EXPECT_EQ(e.to, RunState::Done);
    EXPECT_NE(std::string(e.what()).find("no transition from queued to done"), std::string::npos) << e.what();
  }
  EXPECT_EQ(db.campaign(id)->state, RunState::Queued);  // nothing written
  EXPECT_EQ(db.transitions(id).size(), 2u);
}

TEST(Config, DefaultsRunWithNoFile) {
  const DaemonConfig c = parse_config("{}", "test");
  EXPECT_EQ(c.http.host, "127.0.0.1");
  EXPECT_EQ(c.http.port, 8080);
  EXPECT_EQ(c.data_dir, "./data");
  EXPECT_EQ(c.devices, "sim");
}

TEST(Config, ReadsEveryBlockAndIgnoresComments) {
  const DaemonConfig c = parse_config(R"({
    "_comment": "a comment",
    "listen": "0.0.0.0:9000", "data_dir": "/var/lib/imucal", "devices": "sim",
    "site": {"_comment": "x", "name": "lab", "latitude_deg": 45.0},
    "table": {"limits": {"middle": {"min_deg": -100, "max_deg": 100, "rate_dps": 50}}},
    "chamber": {"min_C": -20, "max_C": 70, "safe_setpoint_C": 23},
    "users": [{"name": "ann", "role": "viewer",
               "password_hash": "$argon2id$v=19$m=65536,t=2,p=1$c2FsdHNhbHRzYWx0c2FsdA$3o2mUAVEDnX4+1eLybYZKJwPGm3tO9mPz6s2n5Zj1vI"}],
    "http": {"body_limit_bytes": 4096, "live_queue": 8},
    "log": {"level": "debug", "file": ""}
  })", "test");
  EXPECT_EQ(c.http.host, "0.0.0.0");
  EXPECT_EQ(c.http.port, 9000);
  EXPECT_EQ(c.site_name, "lab");
  EXPECT_DOUBLE_EQ(c.site.latitude_deg, 45.0);
  EXPECT_DOUBLE_EQ(c.table_limits.axis[1].max_deg, 100.0);
  EXPECT_DOUBLE_EQ(c.table_limits.axis[1].rate_dps, 50.0);
  EXPECT_DOUBLE_EQ(c.chamber.safe_setpoint_C, 23.0);
  ASSERT_EQ(c.users.size(), 1u);
  EXPECT_EQ(c.users[0].role, Role::Viewer);
  EXPECT_EQ(c.http.body_limit_bytes, 4096);
  EXPECT_EQ(c.log.level, "debug");
}

TEST(Config, APlainTextPasswordIsRefusedAndAHashSignsIn) {
  try {
    parse_config(R"({"users": [{"name": "ann", "role": "viewer", "password": "long enough"},
                               {"name": "bob", "role": "viewer", "password_hash": "md5:abc"}]})", "cfg.json");
    FAIL() << "accepted a plain-text password";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("config.users[0].password: plain-text passwords are not accepted"), std::string::npos) << m;
    EXPECT_NE(m.find("imucal passwd"), std::string::npos) << m;
    EXPECT_NE(m.find("config.users[1].password_hash is not a hash made by `imucal passwd`"), std::string::npos) << m;
  }
  const std::string hash = hash_password("correct horse");
  EXPECT_TRUE(is_password_hash(hash)) << hash;
  EXPECT_NE(hash, hash_password("correct horse")) << "salted: two hashes of one password differ";
  EXPECT_TRUE(verify_password(hash, "correct horse"));
  EXPECT_FALSE(verify_password(hash, "correct horse "));
  EXPECT_FALSE(verify_password("not a hash", "correct horse"));
  const DaemonConfig c = parse_config(json{{"users", {{{"name", "ann"}, {"role", "viewer"}, {"password_hash", hash}}}}}.dump(),
                                      "cfg.json");
  Auth auth(c, daemontest::scratch_dir("hash-signin"));
  EXPECT_EQ(auth.login_password("ann", "correct horse").status, 200);
  EXPECT_EQ(auth.login_password("ann", "wrong").status, 401);
  EXPECT_EQ(auth.login_password("nobody", "correct horse").status, 401);
}

TEST(Config, ListsEveryProblem) {
  try {
    parse_config(R"({"listen": "nope", "devices": "real", "site": {"latitude_deg": 120}, "typo": 1,
                     "users": [{"name": "x", "role": "king", "token": "short"}]})",
                 "cfg.json");
    FAIL() << "accepted a bad configuration";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("config.listen"), std::string::npos) << m;
    EXPECT_NE(m.find("config.devices"), std::string::npos) << m;
    EXPECT_NE(m.find("latitude_deg"), std::string::npos) << m;
    EXPECT_NE(m.find("unknown key \"typo\""), std::string::npos) << m;
    EXPECT_NE(m.find("role"), std::string::npos) << m;
    EXPECT_NE(m.find("token must have at least 16"), std::string::npos) << m;
  }
  EXPECT_THROW(parse_config("{not json", "x"), ConfigError);
}

// A `devices` object names real devices in the drivers' own configuration forms.
TEST(Config, ADevicesObjectNamesRealDevices) {
  const DaemonConfig c = parse_config(R"({"devices": {
    "_comment": "the bench in room 2",
    "table": {"format": "imucal-table/1", "host": "10.0.0.5", "port": 5001, "watchdog_s": 2, "reply_checksum": false,
              "limits": [{"axis": "outer", "mode": "rate", "min_deg": -1e6, "max_deg": 1e6, "rate_dps": 100, "accel_dps2": 50}]},
    "chamber": {"transport": "tcp", "host": "10.0.0.6", "port": 1502, "map": "csz-ezt570i", "safe_setpoint_C": 22},
    "imu": {"socket": "/run/imucal/imu.sock", "framing": "fd", "rate_hz": 400, "gyro_lsb_rad": 2.5e-9,
            "accel_lsb_mps": 2.5e-8, "serial": "FOG-0042", "transport_delay_ns": 1500, "stall_timeout_ms": 300},
    "power_relay": {"format": "imucal-power-relay/1", "host": "10.0.0.9", "port": 502, "unit_id": 3, "coil": 5,
                    "on_when_set": false, "off_s": 20}}})",
                                      "test");
  EXPECT_EQ(c.devices, "real");
  ASSERT_TRUE(c.device_addresses);
  const DeviceAddresses& d = *c.device_addresses;
  EXPECT_EQ(d.table.host, "10.0.0.5");
  EXPECT_EQ(d.table.port, 5001);
  EXPECT_DOUBLE_EQ(d.table.watchdog_s, 2.0);
  EXPECT_FALSE(d.table.reply_checksum);
  const auto& outer_limits = d.table.limits[0][2];
  ASSERT_TRUE(outer_limits);
  EXPECT_DOUBLE_EQ(outer_limits->rate_dps, 100.0);
  EXPECT_EQ(d.chamber.host, "10.0.0.6");
  EXPECT_EQ(d.chamber.port, 1502);
  EXPECT_EQ(d.chamber.map.name, "csz-ezt570i");
  EXPECT_DOUBLE_EQ(d.chamber.safe_setpoint_C.value_or(0), 22.0);
  EXPECT_EQ(d.imu.socket_path, "/run/imucal/imu.sock");
  EXPECT_TRUE(d.imu.interface.empty());
  EXPECT_DOUBLE_EQ(d.imu.rate_hz, 400.0);
  EXPECT_DOUBLE_EQ(d.imu.link.gyro_increment_lsb_rad().value_or(0), 2.5e-9);  // imucal-can, per unit
  EXPECT_EQ(d.imu.serial, "FOG-0042");
  EXPECT_EQ(d.imu.transport_delay_ns, 1500);
  EXPECT_EQ(d.imu.stall_timeout_ms, 300);
  ASSERT_TRUE(d.power_relay);
  EXPECT_EQ(d.power_relay->host, "10.0.0.9");
  EXPECT_EQ(d.power_relay->unit_id, 3);
  EXPECT_EQ(d.power_relay->coil, 5);
  EXPECT_FALSE(d.power_relay->on_when_set);
  EXPECT_DOUBLE_EQ(d.power_relay->off_s, 20.0);

  const DaemonConfig can = parse_config(R"({"devices": {"table": {"host": "t", "port": 5000},
    "chamber": {"transport": "rtu", "serial_device": "/dev/ttyS1", "map": "watlow-f4t"},
    "imu": {"interface": "can0", "framing": "classic", "rate_hz": 200, "gyro_lsb_rad": 1e-8, "accel_lsb_mps": 1e-7,
            "serial": "X1"}}})", "test");
  ASSERT_TRUE(can.device_addresses);
  EXPECT_FALSE(can.device_addresses->power_relay) << "none: the operator switches the IMU";
  EXPECT_EQ(can.device_addresses->imu.interface, "can0");
  EXPECT_EQ(can.device_addresses->chamber.transport, drivers::ModbusChamberConfig::Transport::rtu);
  EXPECT_EQ(can.device_addresses->imu.framing, drivers::can::Framing::classic);
}

TEST(Config, ABadDevicesObjectListsEveryProblemWithItsKeyPath) {
  std::string m;
  try {
    parse_config(R"({"devices": {
      "table": {"host": "t", "port": 70000, "response_timeout_ms": -5, "watchdog": 1, "reply_checksum": "yes",
                "dialect": "acutrol-3000"},
      "chamber": {"port": 1502, "map": "no-such-map", "parity": "X"},
      "imu": {"interface": "can0", "socket": "/tmp/imu.sock", "framing": "flexray", "gyro_lsb_rad": 0,
              "accel_lsb_mps": 1e-7, "serial": "", "rate": 100},
      "power_relay": {"host": "r", "port": 502, "off_s": 3600, "coils": 2},
      "spare": {}}})",
                 "bench.json");
    FAIL() << "accepted a bad devices object";
  } catch (const ConfigError& e) {
    m = e.what();
  }
  for (const char* part : {
           "bench.json:",
           "config.devices: unknown key \"spare\"",
           "config.devices.table.port is 70000, must be between 1 and 65535",
           "config.devices.table.response_timeout_ms is -5, must be between 1 and 3600000",
           "config.devices.table: unknown key \"watchdog\"",
           "config.devices.table.reply_checksum must be true or false, not a string",
           "config.devices.table.dialect: table dialect 'acutrol-3000': no such built-in one (imucal-acl) or file",
           "config.devices.chamber.host is required",
           "config.devices.chamber.map: register map 'no-such-map': no such built-in one (watlow-f4t, csz-ezt570i) or file",
           "config.devices.chamber.parity must be \"N\", \"E\" or \"O\"",
           "config.devices.imu: give \"interface\" (a CAN interface) or \"socket\" (a Unix socket path), not both",
           "config.devices.imu.framing must be \"fd\" or \"classic\"",
           "config.devices.imu.rate_hz is required",
           "config.devices.imu.gyro_lsb_rad must be positive",
           "config.devices.imu.serial must not be empty",
           "config.devices.imu: unknown key \"rate\"",
           "config.devices.power_relay.coil is required",
           "config.devices.power_relay.off_s is 3600.0, must be between 1.0 and 600.0",
           "config.devices.power_relay: unknown key \"coils\"",
       })
    EXPECT_NE(m.find(part), std::string::npos) << "missing: " << part << "\nin:\n" << m;
  // The port is reported once, with its path; the driver's own prefix is gone.
  EXPECT_EQ(m.find("table config:"), std::string::npos) << m;

  // Missing devices, a classic-CAN rate too high for the framing, a string that names no bench.
  try {
    parse_config(R"({"devices": {"imu": {"interface": "can0", "framing": "classic", "rate_hz": 1000,
                                          "gyro_lsb_rad": 1, "accel_lsb_mps": 1, "serial": "s"}}})", "x");
    FAIL();
  } catch (const ConfigError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find("config.devices.table is required"), std::string::npos) << m;
  EXPECT_NE(m.find("config.devices.chamber is required"), std::string::npos) << m;
  EXPECT_NE(m.find("config.devices.imu: classic CAN framing carries at most 200"), std::string::npos) << m;
  EXPECT_THROW(parse_config(R"({"devices": "real"})", "x"), ConfigError);
}

// With real devices a campaign runs at the IMU's rate, and simulated faults make no sense.
TEST(Campaign, RealDevicesSetTheRateAndRefuseSimFaults) {
  const DaemonConfig config = parse_config(R"({"devices": {"table": {"host": "t", "port": 5000},
    "chamber": {"host": "c", "port": 502, "map": "watlow-f4t"},
    "imu": {"socket": "/tmp/imu.sock", "rate_hz": 200, "gyro_lsb_rad": 1e-8, "accel_lsb_mps": 1e-7, "serial": "S"}}})",
                                           "test");
  const CampaignCheck ok = check_campaign(json{{"name", "x"}, {"program", "direct"}}, config);
  ASSERT_TRUE(ok.spec) << (ok.problems.empty() ? "" : ok.problems.front());
  EXPECT_DOUBLE_EQ(ok.spec->rate_hz, 200.0);
  const CampaignCheck bad = check_campaign(
      json{{"name", "x"}, {"program", "direct"}, {"rate_hz", 100},
           {"sim_faults", {{{"kind", "imu_dropout"}, {"at_s", 5}, {"duration_s", 1}}}}},
      config);
  ASSERT_FALSE(bad.spec);
  std::string all;
  for (const auto& p : bad.problems) all += p + "\n";
  EXPECT_NE(all.find("campaign.rate_hz is 100 Hz but the IMU runs at 200 Hz (config.devices.imu.rate_hz)"),
            std::string::npos) << all;
  EXPECT_NE(all.find("campaign.sim_faults need simulated devices"), std::string::npos) << all;
}

TEST(Config, ListenAddress) {
  std::string host;
  std::uint16_t port = 1;
  parse_listen("127.0.0.1:0", host, port);
  EXPECT_EQ(port, 0);
  parse_listen("[::1]:8081", host, port);
  EXPECT_EQ(host, "::1");
  EXPECT_EQ(port, 8081);
  EXPECT_THROW(parse_listen("localhost", host, port), ConfigError);
  EXPECT_THROW(parse_listen("h:70000", host, port), ConfigError);
  EXPECT_THROW(parse_listen("h:80x", host, port), ConfigError);
}

TEST(Campaign, ShortFormUsesTheConfiguredDefaults) {
  DaemonConfig config;
  config.sim.rate_hz = 200;
  const CampaignCheck c = check_campaign(json{{"name", "quick"}, {"program", "direct"}}, config);
  ASSERT_TRUE(c.spec) << (c.problems.empty() ? "" : c.problems.front());
  EXPECT_EQ(c.spec->program_label, "direct");
  EXPECT_DOUBLE_EQ(c.spec->rate_hz, 200.0);
  EXPECT_EQ(c.spec->estimators, std::vector<std::string>{"direct"});
  EXPECT_GT(c.duration_s, 1000.0);
  // The stored form checks again to the same campaign (what a restart relies on).
  const CampaignCheck again = check_campaign(c.spec->normalized, config);
  ASSERT_TRUE(again.spec);
  EXPECT_EQ(again.spec->program_json, c.spec->program_json);
  EXPECT_DOUBLE_EQ(again.duration_s, c.duration_s);
}

TEST(Campaign, MalformedIsToldApartFromInvalid) {
  const DaemonConfig config;
  const auto unknown = check_campaign(json{{"name", "x"}, {"program", "direct"}, {"colour", "red"}}, config);
  EXPECT_FALSE(unknown.spec);
  EXPECT_TRUE(unknown.malformed);
  EXPECT_NE(unknown.problems.front().find("unknown key \"colour\""), std::string::npos);

  const auto not_json = check_campaign_text("{\"name\": ", config);
  EXPECT_TRUE(not_json.malformed);

  const auto missing = check_campaign(json{{"program", "direct"}}, config);
  EXPECT_TRUE(missing.malformed);

  // Well-formed but outside the limits: every problem, and not "malformed".
  DaemonConfig tight;
  tight.table_limits.axis[0].rate_dps = 10.0;
  tight.campaign.max_rate_hz = 500;
  const auto invalid = check_campaign(json{{"name", "x"},
                                           {"program", "direct"},
                                           {"rate_hz", 1000},
                                           {"estimators", {"direct", "kalman"}},
                                           {"chamber", {{"setpoint_C", 200}}}},
                                      tight);
  EXPECT_FALSE(invalid.spec);
  std::string all;
  for (const auto& p : invalid.problems) all += p + "\n";
  EXPECT_NE(all.find("rate"), std::string::npos) << all;              // table rate limit
  EXPECT_NE(all.find("rate_hz: 1000 Hz exceeds the limit of 500 Hz"), std::string::npos) << all;      // IMU rate limit
  EXPECT_NE(all.find("unknown estimator \"kalman\""), std::string::npos) << all;
  EXPECT_NE(all.find("setpoint_C: 200 °C is outside the chamber's limits -40 °C .. 85 °C"), std::string::npos) << all;
  EXPECT_NE(all.find("more times"), std::string::npos) << all;  // one line per segment and limit
  EXPECT_GE(invalid.problems.size(), 4u);
}

TEST(Campaign, EstimatorPrerequisites) {
  const DaemonConfig config;
  const auto noise_direct = check_campaign(json{{"name", "x"}, {"program", "noise"}, {"estimators", {"direct"}}}, config);
  ASSERT_FALSE(noise_direct.spec);
  EXPECT_NE(noise_direct.problems.front().find("needs at least 6 static segments"), std::string::npos);
  EXPECT_TRUE(check_campaign(json{{"name", "x"}, {"program", "noise"}, {"estimators", {"navigation"}}}, config).spec);
}

TEST(Campaign, ProgramsRunOneAfterTheOther) {
  const DaemonConfig config;
  const auto one = check_campaign(json{{"name", "a"}, {"program", "direct-short"}}, config);
  const auto nav = check_campaign(json{{"name", "b"}, {"program", "navigation"}, {"estimators", {"navigation"}}}, config);
  const auto both = check_campaign(
      json{{"name", "c"}, {"program", {"direct-short", "navigation"}}, {"estimators", {"direct", "navigation"}}}, config);
  ASSERT_TRUE(both.spec) << both.problems.front();
  EXPECT_EQ(both.spec->program_label, "direct-short+navigation");
  EXPECT_GE(both.duration_s, one.duration_s + nav.duration_s);
  bool prefixed = false;
  for (const auto& s : both.segments) prefixed = prefixed || s.name.rfind("navigation/", 0) == 0;
  EXPECT_TRUE(prefixed);
  const auto bad = check_campaign(json{{"name", "c"}, {"program", {"direct", "nonesuch"}}}, config);
  EXPECT_FALSE(bad.spec);
}

// One chamber model (issue 37, item 5): a profile, stored as a campaign's set-point changes and
// read back, is the same set point at every instant, ramping at the same times.
TEST(Campaign, AChamberProfileStoredAsItsChangesIsTheSameSetPointOverTime) {
  for (const std::string& name : motion::builtin_chamber_names()) {
    const motion::ChamberProfile built = motion::load_chamber_profile(name);
    const motion::ChamberProfile again = motion::profile_of_changes(built.start_C, motion::changes_of(built), built.duration_s());
    for (double t = 0; t <= built.duration_s() + 100; t += 7.3) ASSERT_NEAR(again.setpoint_C(t), built.setpoint_C(t), 1e-9) << name << " at " << t;
    for (double t = 0; t < built.duration_s(); t += 60)
      ASSERT_EQ(motion::ramps_within(again, t, t + 60), motion::ramps_within(built, t, t + 60)) << name << " at " << t;
  }
}

TEST(Campaign, ChamberProfileAndRamps) {
  CampaignChamber p;
  p.profile = motion::profile_of_changes(25, {{100, 45, 1.0}, {2000, 30, 0.0}}, 3000);
  EXPECT_DOUBLE_EQ(p.setpoint_at(50), 25.0);
  EXPECT_NEAR(p.setpoint_at(160), 26.0, 1e-12);  // 1 C/min for 60 s
  EXPECT_NEAR(p.setpoint_at(1300), 45.0, 1e-12);  // reached after 1200 s
  EXPECT_DOUBLE_EQ(p.setpoint_at(2500), 30.0);    // a step
  EXPECT_TRUE(p.ramps_within(0, 200));
  EXPECT_TRUE(p.ramps_within(1000, 1400));
  EXPECT_FALSE(p.ramps_within(1400, 3000));
  EXPECT_FALSE(p.ramps_within(0, 100));

  const DaemonConfig config;
  const auto fast = check_campaign(
      json{{"name", "x"}, {"program", "direct"}, {"chamber", {{"steps", {{{"at_s", 10}, {"setpoint_C", 40}, {"ramp_C_per_min", 50}}}}}}},
      config);
  ASSERT_FALSE(fast.spec);
  EXPECT_NE(fast.problems.front().find("exceeds the chamber's limit"), std::string::npos);
}

TEST(Campaign, FaultsAreChecked) {
  const DaemonConfig config;
  const auto ok = check_campaign(json{{"name", "x"},
                                      {"program", "direct-short"},
                                      {"sim_faults", {{{"kind", "chamber_offset"}, {"at_s", 50}, {"duration_s", 5},
                                                       {"offset_C", 9}},
                                                      {{"kind", "disconnect"}, {"device", "imu"}, {"at_s", 60},
                                                       {"duration_s", 1}}}}},
                                 config);
  ASSERT_TRUE(ok.spec) << ok.problems.front();
  EXPECT_EQ(ok.spec->faults.size(), 2u);
  const auto bad = check_campaign(
      json{{"name", "x"}, {"program", "direct-short"}, {"sim_faults", {{{"kind", "meteor"}, {"at_s", 5000}}}}}, config);
  ASSERT_FALSE(bad.spec);
  EXPECT_EQ(bad.problems.size(), 2u);  // unknown kind, at_s after the end
}

TEST(StaticFiles, ServesFilesWithTypesAndNeverLeavesTheRoot) {
  const std::string dir = daemontest::scratch_dir("static");
  std::filesystem::create_directories(dir + "/web/js");
  std::ofstream(dir + "/web/index.html") << "<html>hi</html>";
  std::ofstream(dir + "/web/js/app.js") << "export const x = 1;";
  std::ofstream(dir + "/web/.secret") << "no";
  std::ofstream(dir + "/outside.txt") << "secret";
  std::filesystem::create_symlink(dir + "/outside.txt", dir + "/web/link.txt");
  const StaticFiles files(dir + "/web");

  auto index = files.get("/", "", false);
  EXPECT_EQ(index.status, 200);
  EXPECT_EQ(index.body, "<html>hi</html>");
  EXPECT_EQ(index.content_type, "text/html; charset=utf-8");
  auto js = files.get("/js/app.js", "", false);
  EXPECT_EQ(js.status, 200);
  EXPECT_EQ(js.content_type, "text/javascript; charset=utf-8");
  std::string etag;
  for (const auto& [k, v] : js.headers)
    if (k == "ETag") etag = v;
  ASSERT_FALSE(etag.empty());
  EXPECT_EQ(files.get("/js/app.js", etag, false).status, 304);

  for (const char* evil : {"/../outside.txt", "/js/../../outside.txt", "/%2e%2e/outside.txt", "/js/%2E%2E/%2E%2E/outside.txt",
                           "/.secret", "/link.txt", "/nonexistent", "/js", "/..%5coutside.txt", "/%00"}) {
    const auto r = files.get(evil, "", false);
    EXPECT_TRUE(r.status == 404 || r.status == 400) << evil << " gave " << r.status;
    EXPECT_EQ(r.body.find("secret"), std::string::npos) << evil;
  }
}

TEST(Auth, GeneratesTheOperatorTokenOnceAndKeepsIt) {
  const std::string dir = daemontest::scratch_dir("auth");
  DaemonConfig config;
  std::string token;
  {
    const Auth auth(config, dir);
    token = auth.generated_token();
    ASSERT_EQ(token.size(), 64u);
    EXPECT_EQ(std::filesystem::status(dir + "/operator-token").permissions() & std::filesystem::perms::group_all,
              std::filesystem::perms::none);
    const auto p = auth.from_token(token);
    ASSERT_TRUE(p);
    EXPECT_EQ(p->role, Role::Operator);
    EXPECT_FALSE(auth.from_token(token.substr(1)));
    EXPECT_FALSE(auth.from_token(""));
  }
  const Auth again(config, dir);
  EXPECT_TRUE(again.generated_token().empty());  // printed once only
  EXPECT_TRUE(again.from_token(token));
  // A configured operator means no generated token at all.
  config.operator_token = "0123456789abcdef0123";
  const std::string dir2 = daemontest::scratch_dir("auth2");
  const Auth configured(config, dir2);
  EXPECT_TRUE(configured.generated_token().empty());
  EXPECT_FALSE(std::filesystem::exists(dir2 + "/operator-token"));
}

TEST(Auth, SessionsAndThrottling) {
  DaemonConfig config;
  config.users = {{"vic", Role::Viewer, hash_password("viewer-password"), ""},
                  {"ops", Role::Operator, hash_password("operator-password"), ""}};
  Auth auth(config, daemontest::scratch_dir("sessions"));
  const auto ok = auth.login_password("vic", "viewer-password");
  ASSERT_EQ(ok.status, 200);
  const auto p = auth.from_session(ok.session_id);
  ASSERT_TRUE(p);
  EXPECT_EQ(p->user, "vic");
  EXPECT_EQ(p->role, Role::Viewer);
  auth.logout(ok.session_id);
  EXPECT_FALSE(auth.from_session(ok.session_id));
  for (int i = 0; i < 5; ++i) EXPECT_EQ(auth.login_password("ops", "guess").status, 401);
  EXPECT_EQ(auth.login_password("ops", "operator-password").status, 429);
  // Per client and per user, not global (issue 33): the guessing client is locked out, whoever
  // it names; every other client signs in, as the user guessed at too.
  EXPECT_EQ(auth.login_password("vic", "viewer-password").status, 429);
  EXPECT_EQ(auth.login_token("anything").status, 429);
  EXPECT_EQ(auth.login_password("ops", "operator-password", "10.0.0.2").status, 200);
  EXPECT_EQ(auth.login_password("vic", "viewer-password", "10.0.0.3").status, 200);
  // Guesses at one name from many addresses (20 within the minute) lock that name only.
  for (int i = 0; i < 15; ++i) EXPECT_EQ(auth.login_password("ops", "guess", "10.1.0." + std::to_string(i)).status, 401);
  EXPECT_EQ(auth.login_password("ops", "operator-password", "10.0.0.4").status, 429);
  EXPECT_EQ(auth.login_password("vic", "viewer-password", "10.0.0.4").status, 200);
}

// The lab's accounts (issue 38) are read by one sign-in at a time, outside the lock: a sign-in
// meanwhile (the registry's server away holds a read up to its connect timeout) is answered from
// the accounts read before instead of queuing behind the read.
TEST(Auth, ASignInDoesNotWaitOnAnotherReadingTheLabsAccounts) {
  Auth auth(DaemonConfig{}, daemontest::scratch_dir("lab-users-read"));
  const std::string hash = hash_password("lab-password");
  auth.set_lab_users([&] { return std::vector<UserEntry>{{"ann", Role::Viewer, hash, ""}}; });
  ASSERT_EQ(auth.login_password("ann", "lab-password").status, 200);

  std::promise<void> entered, release;
  std::shared_future<void> released = release.get_future().share();
  auth.set_lab_users([&] {  // read once: ann was removed, and the read hangs until released
    entered.set_value();
    released.wait();
    return std::vector<UserEntry>{};
  });
  auto reading = std::async(std::launch::async, [&] { return auth.login_password("ann", "lab-password", "10.0.0.1"); });
  entered.get_future().wait();
  auto meanwhile = std::async(std::launch::async, [&] { return auth.login_password("ann", "lab-password", "10.0.0.2"); });
  const bool answered = meanwhile.wait_for(std::chrono::seconds(30)) == std::future_status::ready;
  release.set_value();
  EXPECT_TRUE(answered) << "a sign-in waited on another's read of the lab's accounts";
  EXPECT_EQ(meanwhile.get().status, 200) << "answered from the accounts read before";
  EXPECT_EQ(reading.get().status, 401) << "the reader judged by what it read";
  EXPECT_EQ(auth.login_password("ann", "lab-password", "10.0.0.3").status, 401);
}

// A lab account's session ends when the account is removed, or its password or role changed, on
// any stand: seen at the next request or live-page check once the accounts are read again. A
// configured user's session does not depend on the registry.
TEST(Auth, ALabAccountsSessionEndsWhenTheAccountIsRemovedOrChanged) {
  DaemonConfig config;
  config.users = {{"ops", Role::Operator, hash_password("operator-password"), ""}};
  Auth auth(config, daemontest::scratch_dir("lab-users-sessions"));
  const std::string hash = hash_password("lab-password");
  std::vector<UserEntry> accounts = {{"ann", Role::Operator, hash, ""}, {"bea", Role::Viewer, hash, ""}};
  auth.set_lab_users([&] { return accounts; });
  const auto ann = auth.login_password("ann", "lab-password");
  const auto bea = auth.login_password("bea", "lab-password");
  const auto ops = auth.login_password("ops", "operator-password");
  ASSERT_EQ(ann.status, 200);
  ASSERT_EQ(bea.status, 200);
  ASSERT_EQ(ops.status, 200);
  ASSERT_TRUE(auth.from_session(ann.session_id));

  accounts = {{"ann", Role::Viewer, hash, ""}, {"bea", Role::Viewer, hash_password("a new password"), ""}};
  auth.set_lab_users([&] { return accounts; });  // read again at the next use, as after kLabUsersFresh
  EXPECT_FALSE(auth.from_session(ann.session_id)) << "ann's role changed: her operator session ended";
  EXPECT_FALSE(auth.session_alive(bea.session_id)) << "bea's password changed: her live page's session ended";
  EXPECT_FALSE(auth.from_session(bea.session_id)) << "and it stays ended";
  EXPECT_TRUE(auth.from_session(ops.session_id));
  const auto ann_again = auth.login_password("ann", "lab-password");
  ASSERT_EQ(ann_again.status, 200);
  EXPECT_EQ(auth.from_session(ann_again.session_id).value_or(Principal{}).role, Role::Viewer);

  accounts.clear();  // removed
  auth.set_lab_users([&] { return accounts; });
  EXPECT_FALSE(auth.from_session(ann_again.session_id)) << "ann's account was removed";
  EXPECT_TRUE(auth.from_session(ops.session_id));
  // The registry away: the accounts read before hold, and their sessions go on.
  accounts = {{"ann", Role::Viewer, hash, ""}};
  auth.set_lab_users([&] { return accounts; });
  const auto during = auth.login_password("ann", "lab-password");
  ASSERT_EQ(during.status, 200);
  auth.set_lab_users([]() -> std::vector<UserEntry> { throw std::runtime_error("registry: server away"); });
  EXPECT_TRUE(auth.from_session(during.session_id));
}

TEST(Api, TargetsAndCookies) {
  const auto t = parse_target("/api/imus/FOG%2F7/?limit=5&x=a%20b+c");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->path, "/api/imus/FOG%2F7/");
  EXPECT_EQ(t->segments, (std::vector<std::string>{"api", "imus", "FOG/7"}));  // decoded, no trailing empty one
  EXPECT_EQ(t->query.at("limit"), "5");
  EXPECT_EQ(t->query.at("x"), "a b c");
  EXPECT_FALSE(parse_target("/a?x=%zz"));
  EXPECT_FALSE(parse_target("/a/%zz"));
  EXPECT_EQ(session_from_cookie("a=1; imucal_session=abc; b=2"), "abc");
  EXPECT_EQ(session_from_cookie("imucal_sessionx=1"), "");
}

TEST(Config, TheCommentedExampleParses) {
  const DaemonConfig c = load_config_file(imucaltest::source_dir() + "/examples/imucald.json");
  EXPECT_EQ(c.users.size(), 2u);
  EXPECT_EQ(c.users[1].role, Role::Operator);
  EXPECT_EQ(c.http.port, 8080);
  EXPECT_TRUE(std::isinf(c.table_limits.axis[0].max_deg));
  // Its real-devices example, put in place as the comment says, is a valid devices object.
  std::ifstream in(imucaltest::source_dir() + "/examples/imucald.json");
  json example = json::parse(in);
  example["devices"] = example.at("_devices_real");
  const DaemonConfig real = parse_config(example.dump(), "example");
  ASSERT_TRUE(real.device_addresses);
  EXPECT_EQ(real.device_addresses->imu.interface, "can0");
  EXPECT_EQ(real.device_addresses->table.port, 5000);
  ASSERT_TRUE(real.device_addresses->power_relay);
  EXPECT_EQ(real.device_addresses->power_relay->host, "192.168.10.21");
  // Its gravity survey, put in place with a measured g as its comment says.
  ASSERT_TRUE(c.reference_equipment.table.has_value());
  EXPECT_EQ(c.reference_equipment.table->uncertainty, "1 arcsec (k=2)");
  json surveyed = json::parse(std::ifstream(imucaltest::source_dir() + "/examples/imucald.json"));
  surveyed["reference_equipment"]["gravity"] = surveyed.at("reference_equipment").at("_gravity");
  surveyed["site"]["gravity_mps2"] = 9.81912;
  const DaemonConfig with_survey = parse_config(surveyed.dump(), "example");
  ASSERT_TRUE(with_survey.reference_equipment.gravity.has_value());
  EXPECT_EQ(with_survey.reference_equipment.gravity->calibration_certificate, "GS-2024-17");
}

// The wire's own faults (bytes on the IMU link, garbled Modbus replies) exist only where there is
// a wire; its time scale is the configuration's, real time unless it says otherwise.
TEST(Config, TheWireFaultsAndTimeScaleAreSimWires) {
  EXPECT_EQ(DaemonConfig{}.sim.wire_time_scale, 1.0);
  EXPECT_EQ(parse_config(R"({"sim": {"wire_time_scale": 200}})", "test").sim.wire_time_scale, 200.0);
  const json campaign = {{"name", "wire faults"},
                         {"program", "direct-short"},
                         {"sim_faults", {{{"kind", "imu_bytes_drop"}, {"at_s", 50}, {"frames", 3}},
                                         {{"kind", "chamber_corrupt"}, {"at_s", 60}, {"replies", 2}}}}};
  DaemonConfig sim_wire;
  sim_wire.devices = "sim-wire";
  const auto wire = check_campaign(campaign, sim_wire);
  ASSERT_TRUE(wire.spec.has_value()) << (wire.problems.empty() ? "" : wire.problems.front());
  ASSERT_EQ(wire.spec->faults.size(), 2u);
  EXPECT_EQ(wire.spec->faults[0].kind, SimFault::Kind::ImuBytesDrop);
  EXPECT_EQ(wire.spec->faults[1].frames, 2);
  const auto sim = check_campaign(campaign, DaemonConfig{});
  EXPECT_FALSE(sim.spec.has_value());
  ASSERT_EQ(sim.problems.size(), 2u);
  EXPECT_NE(sim.problems[0].find("imu_bytes_drop and chamber_corrupt need the sim-wire devices"), std::string::npos);
}

// The suspenders as objects: each trips on its condition, the chamber only after its persistence,
// the same objects say when it is clear to move again, and they describe themselves for the API.
TEST(Suspenders, TripOnTheirConditionAndClearOnTheSameRule) {
  SuspenderSettings settings;
  settings.chamber_persist_s = 2.0;
  settings.frame_timeout_s = 1.0;
  Suspenders s(settings);
  DeviceReadings r;
  r.now_s = 100.0;
  r.last_frame_s = 100.0;
  r.chamber_C = 25.0;
  r.setpoint_C = 25.0;
  r.tolerance_C = 2.0;
  EXPECT_FALSE(s.trip(r));
  EXPECT_TRUE(s.clear(r));
  // Out of band: held only after 2 s of it.
  r.chamber_C = 28.0;
  EXPECT_FALSE(s.trip(r));
  EXPECT_FALSE(s.clear(r)) << "not clear to move while out of band";
  r.now_s = r.last_frame_s = 101.5;
  EXPECT_FALSE(s.trip(r));
  r.now_s = r.last_frame_s = 102.1;
  const auto chamber = s.trip(r);
  ASSERT_TRUE(chamber);
  EXPECT_EQ(chamber->suspender, "chamber-out-of-band");
  EXPECT_NE(chamber->reason.find("chamber out of band: 28 °C, set point 25 °C ± 2 °C"), std::string::npos);
  r.chamber_C = 25.5;
  EXPECT_TRUE(s.clear(r));
  // Frames missing after the timeout; before a segment the IMU's link is what must be up.
  r.now_s = 104.0;
  const auto frames = s.trip(r);
  ASSERT_TRUE(frames);
  EXPECT_EQ(frames->suspender, "imu-frames-missing");
  r.imu_connected = false;
  EXPECT_FALSE(s.clear(r));
  r.imu_connected = true;
  r.last_frame_s = 104.0;
  // The recorder comes first, whatever else is wrong.
  r.table_connected = false;
  r.recorder_problem = "recording failed: disk full";
  const auto recorder_trip = s.trip(r);
  ASSERT_TRUE(recorder_trip);
  EXPECT_EQ(recorder_trip->suspender, "recorder");
  r.recorder_problem.clear();
  const auto table_trip = s.trip(r);
  ASSERT_TRUE(table_trip);
  EXPECT_EQ(table_trip->reason, "table disconnected");
  const nlohmann::json list = s.describe();
  ASSERT_EQ(list.size(), 7u);
  for (const auto& e : list) {
    EXPECT_FALSE(e.at("condition").get<std::string>().empty()) << e.dump();
    EXPECT_FALSE(e.at("resume").get<std::string>().empty()) << e.dump();
    EXPECT_EQ(e.at("severity"), "suspend");
  }
  EXPECT_NE(list.dump().find("for 2 s"), std::string::npos) << "the condition states the configured persistence";
}

TEST(ClientAddress, ATrustedProxysForwardedForNamesTheClientAndNothingElseDoes) {
  const std::vector<std::string> proxies = {"127.0.0.1", "10.0.0.5"};
  // Not from a trusted proxy: the peer, whatever the header says.
  EXPECT_EQ(client_address("192.168.1.7", "10.9.9.9", proxies), "192.168.1.7");
  EXPECT_EQ(client_address("192.168.1.7", "", {}), "192.168.1.7");
  // From one: the rightmost entry that is not a trusted proxy.
  EXPECT_EQ(client_address("127.0.0.1", "192.168.1.7", proxies), "192.168.1.7");
  EXPECT_EQ(client_address("127.0.0.1", "6.6.6.6, 192.168.1.7, 10.0.0.5", proxies), "192.168.1.7");
  EXPECT_EQ(client_address("127.0.0.1", " 2001:db8::1 ", proxies), "2001:db8::1");
  // No header, an unreadable entry, or proxies all the way: the peer.
  EXPECT_EQ(client_address("127.0.0.1", "", proxies), "127.0.0.1");
  EXPECT_EQ(client_address("127.0.0.1", "192.168.1.7, not-an-address", proxies), "127.0.0.1");
  EXPECT_EQ(client_address("127.0.0.1", "10.0.0.5", proxies), "127.0.0.1");
}

TEST(Config, TrustedProxiesMustBeAddresses) {
  EXPECT_EQ(parse_config(R"({"http": {"trusted_proxies": ["127.0.0.1", "::1"]}})", "test").http.trusted_proxies,
            (std::vector<std::string>{"127.0.0.1", "::1"}));
  try {
    parse_config(R"({"http": {"trusted_proxies": ["127.0.0.1", "nginx.local"]}})", "test");
    FAIL() << "a host name was taken as a proxy's address";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("config.http.trusted_proxies[1] must be an IP address"), std::string::npos)
        << e.what();
  }
}
