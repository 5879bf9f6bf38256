// Real devices named in the configuration (`devices` as an object). The simulated devices run
// outside the daemon, as an operator would rehearse: `imucal sim-devices` in a subprocess (table
// controller and chamber controller on TCP ports, the IMU on a Unix socket carrying CAN frame
// images), and the daemon reaches them only through the addresses of the configuration that
// command printed. A short campaign must record every frame of its grid once, with the configured
// IMU serial and no truth. A CAN interface this kernel cannot open, and a chamber that does not
// answer, must fail the run with the reason, nothing recorded and the table parked.
#include <signal.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include <gtest/gtest.h>

#include "drivers/tcp_table.hpp"
#include "drivers/register_map.hpp"
#include "sim/sim_devices.hpp"
#include "service_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// `imucal sim-devices` as a subprocess, with the configuration it printed.
struct SimDevicesProcess {
  pid_t pid = -1;
  json config;  // {"devices": {...}}

  SimDevicesProcess(const std::vector<std::string>& args, const std::string& log_path) {
    std::vector<std::string> argv = {imucaltest::program("imucal"), "sim-devices"};
    argv.insert(argv.end(), args.begin(), args.end());
    Child child = spawn_child(argv, log_path);
    pid = child.pid;
    // The configuration is one JSON document on stdout, printed once the devices listen.
    read_stdout_until(
        child,
        [&](const std::string& text) {
          config = json::parse(text, nullptr, false);
          if (config.is_discarded()) config = json();
          return !config.is_null();
        },
        30.0);
  }

  // SIGTERM, then the exit status (-1: had to be killed).
  int stop() {
    if (pid <= 0) return -1;
    ::kill(pid, SIGTERM);
    const int status = wait_exit(pid, 10.0);
    pid = -1;
    return status;
  }
  ~SimDevicesProcess() { stop(); }
};

// About 10 s of program: holds, a move, a rate segment with ramps and a sine, so that every way
// the bench follows a program is used. No rate_hz: a campaign runs at the IMU's configured rate.
json short_campaign(const std::string& name) {
  const json program = json::parse(R"({"name": "devices-short", "segments": [
    {"type": "hold", "name": "start", "duration_s": 1.5},
    {"type": "move", "name": "tilt", "to_deg": [0, 90, 0], "duration_s": 2},
    {"type": "hold", "name": "x-level", "duration_s": 1},
    {"type": "rate", "name": "spin", "axis": "outer", "rate_dps": 30, "duration_s": 3, "accel_dps2": 60},
    {"type": "sine", "name": "swing", "axis": "inner", "amplitude_deg": 5, "period_s": 2, "cycles": 1,
     "phase_deg": 90},
    {"type": "hold", "name": "end", "duration_s": 0.5}]})");
  return {{"name", name}, {"program", program}, {"estimators", json::array()}};
}

// Every instant of the grid once from the first period on; returns how many are off the grid.
std::size_t off_grid(const std::vector<ImuFrame>& frames, std::int64_t dt_ns) {
  std::size_t n = frames.empty() || frames.front().t_ns != dt_ns ? 1 : 0;
  for (std::size_t i = 1; i < frames.size(); ++i) n += frames[i].t_ns - frames[i - 1].t_ns != dt_ns;
  return n;
}

// The daemon's configuration from a file, as imucald reads it: the devices it names.
void use_devices_of(const std::string& path, daemon::DaemonConfig& c) {
  const daemon::DaemonConfig file = daemon::load_config_file(path);
  c.devices = file.devices;
  c.device_addresses = file.device_addresses;
}

void write_file(const std::string& path, const json& j) {
  std::ofstream out(path);
  out << j.dump(2) << "\n";
}

// A Unix socket path has at most 107 characters, less than the scratch directories here.
std::string socket_path_for(const std::string& tag) {
  return "/tmp/imucal-test-" + std::to_string(::getpid()) + "-" + tag + ".sock";
}

// A loopback port nothing listens on: bound, then released (0 when no port could be bound).
int closed_loopback_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  int port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    socklen_t len = sizeof addr;
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) port = ntohs(addr.sin_port);
  }
  ::close(fd);
  return port;
}

drivers::TableStatus table_truth(sim::SimDevices& sim) {
  return sim.world().with_servo([](sim::TableServo& s, double t) { return s.status(t); });
}

}  // namespace

TEST(ConfiguredDevices, ACampaignThroughTheConfiguredAddressesRecordsEveryFrame) {
  const std::string dir = scratch_dir("devices");
  const std::string socket_path = socket_path_for("run");
  SimDevicesProcess devices({"--imu-socket", socket_path, "--rate-hz", "100", "--seed", "5", "--serial", "FOG-TEST-7",
                             "--truth", "ideal"},
                            dir + "/sim-devices.stderr");
  ASSERT_TRUE(devices.config.is_object()) << "imucal sim-devices printed no configuration; see " << dir;
  // The printed configuration as an operator would edit it: the table's watchdog armed, so the
  // daemon must keep every axis under control fed through the hold segments.
  json config = devices.config;
  config["devices"]["table"]["watchdog_s"] = 1.5;
  write_file(dir + "/imucald.json", config);

  LocalDaemon d("devices-run", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  ASSERT_EQ(d.config.devices, "real");
  EXPECT_EQ(d.get("/api/status").at("devices"), "real");

  const auto id = d.post_campaign(short_campaign("configured"));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 60.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "info", "devices at the configured addresses through the real drivers")) << c.dump();
  EXPECT_TRUE(has_event(c, "info", socket_path)) << c.dump();
  EXPECT_EQ(c.at("bad_frames"), 0);
  // Real time: a machine overloaded by other jobs can stall the link long enough to suspend the
  // run, which then redoes the segment; the file must be complete either way.
  if (!has_event(c, "suspended")) {
    EXPECT_EQ(c.at("lost_frames"), 0);
  } else {
    std::printf("note: the run was suspended on the way (machine load?): %s\n", c.at("events").dump().c_str());
  }
  EXPECT_EQ(c.at("spec").at("rate_hz"), 100.0);

  const std::string path = d.run_path(c);
  const auto frames = run_frames(path);
  const double duration_s = c.at("duration_s").get<double>();
  ASSERT_GE(static_cast<double>(frames.size()), duration_s * 100.0 - 1.0);
  EXPECT_EQ(c.at("frames"), static_cast<std::int64_t>(frames.size()));
  EXPECT_EQ(off_grid(frames, 10'000'000), 0u);
  const auto db = storage::RunDb::open(path, storage::OpenMode::Read);
  EXPECT_TRUE(db.dropped_spans().empty());
  const RecordingMeta meta = db.meta();
  EXPECT_EQ(meta.imu_serial, "FOG-TEST-7");
  EXPECT_TRUE(meta.truth_json.empty()) << meta.truth_json.substr(0, 200);
  EXPECT_DOUBLE_EQ(meta.gyro_lsb_rad.value_or(0), devices.config["devices"]["imu"]["gyro_lsb_rad"].get<double>());
  EXPECT_DOUBLE_EQ(meta.rate_hz, 100.0);

  // The frames show what the table did: middle axis at 90 deg on the level hold, and the IMU
  // sensing the 30 deg/s of the spin's constant-rate part.
  double rate_sum_dps = 0.0;
  int rate_n = 0;
  for (const ImuFrame& f : frames) {
    const double t_s = static_cast<double>(f.t_ns) * 1e-9;
    if (t_s > 3.7 && t_s < 4.4) {
      EXPECT_NEAR(f.table_deg.y(), 90.0, 1e-3) << t_s;
    }
    if (t_s > 5.5 && t_s < 6.8) {
      rate_sum_dps += f.dtheta_rad.norm() / 0.01 * 180.0 / M_PI;
      ++rate_n;
    }
  }
  ASSERT_GT(rate_n, 50);
  EXPECT_NEAR(rate_sum_dps / rate_n, 30.0, 0.5);
  // Parked at the end through the driver (and the watchdog never dropped an axis on the way).
  EXPECT_FALSE(d.service->sequencer().telemetry().at("table").at("interlock_closed").get<bool>());
  EXPECT_FALSE(has_event(c, "suspended", "watchdog")) << c.dump();

  // The IMU says who it is over imucal's CAN layout (its identity message).
  EXPECT_TRUE(has_event(c, "info", "the IMU reports serial number 'FOG-TEST-7'")) << c.dump();

  // A second run opens the IMU link again: the devices answer it with a new simulated IMU. It
  // names the unit on the link: checked, and it runs.
  json again = short_campaign("again");
  again["imu"] = {{"serial", "FOG-TEST-7"}};
  again["program"]["segments"] = json::parse(R"([{"type": "hold", "name": "a", "duration_s": 1},
    {"type": "move", "name": "tilt", "to_deg": [0, 45, 0], "duration_s": 2}])");
  const auto id2 = d.post_campaign(again);
  ASSERT_EQ(d.command(id2, "start"), 200);
  const json c2 = d.wait_final(id2, 60.0);
  ASSERT_EQ(c2.at("state"), "done") << c2.dump();
  const auto frames2 = run_frames(d.run_path(c2));
  EXPECT_GE(frames2.size(), 299u);
  EXPECT_EQ(off_grid(frames2, 10'000'000), 0u);
  EXPECT_TRUE(has_event(c2, "info", "'FOG-TEST-7', the campaign's unit")) << c2.dump();

  // A campaign naming another unit than the one on the link does not start (issue 17): the
  // error gives both serials, nothing is recorded, and the table is left parked.
  json other = short_campaign("another unit");
  other["imu"] = {{"serial", "FOG-OTHER"}};
  const auto id3 = d.post_campaign(other);
  ASSERT_EQ(d.command(id3, "start"), 200);
  const json c3 = d.wait_final(id3, 60.0);
  EXPECT_EQ(c3.at("state"), "failed") << c3.dump();
  const std::string why = c3.value("error", "");
  EXPECT_NE(why.find("reports serial number 'FOG-TEST-7'"), std::string::npos) << why;
  EXPECT_NE(why.find("names the unit 'FOG-OTHER'"), std::string::npos) << why;
  EXPECT_EQ(c3.at("frames"), 0);
  EXPECT_FALSE(c3.at("has_model").get<bool>());
  EXPECT_FALSE(d.service->sequencer().telemetry().at("table").at("interlock_closed").get<bool>());

  d.service->stop();
  d.service.reset();
  EXPECT_EQ(devices.stop(), 0);
  std::ifstream log(dir + "/sim-devices.stderr");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("stopping after 3 IMU link(s)"), std::string::npos) << text;
}

// A table controller of another family is a configuration file: `imucal sim-devices` given a
// dialect only the tests define (tests/data/table-dialect-test-rtc.json), the daemon configured
// with the same file, a campaign runs through it.
TEST(ConfiguredDevices, ATableSpeakingADialectOnlyTheTestDefinesRunsACampaign) {
  const std::string dir = scratch_dir("devices-dialect");
  const std::string socket_path = socket_path_for("dialect");
  const std::string dialect = imucaltest::test_data_dir() + "/table-dialect-test-rtc.json";
  SimDevicesProcess devices({"--imu-socket", socket_path, "--rate-hz", "100", "--seed", "6", "--table-dialect", dialect},
                            dir + "/sim-devices.stderr");
  ASSERT_TRUE(devices.config.is_object()) << "imucal sim-devices printed no configuration; see " << dir;
  EXPECT_EQ(devices.config["devices"]["table"]["dialect"], dialect);
  write_file(dir + "/imucald.json", devices.config);

  LocalDaemon d("dialect-run", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  ASSERT_TRUE(d.config.device_addresses.has_value());
  EXPECT_EQ(d.config.device_addresses->table.dialect.name, "test-rtc");
  const auto id = d.post_campaign(short_campaign("dialect"));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 60.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "info", "table test-rtc://127.0.0.1:")) << c.dump();
  const auto frames = run_frames(d.run_path(c));
  ASSERT_GE(static_cast<double>(frames.size()), c.at("duration_s").get<double>() * 100.0 - 1.0);
  EXPECT_EQ(off_grid(frames, 10'000'000), 0u);
  // The table went where the program said, read back through the dialect's replies.
  int level = 0;
  for (const ImuFrame& f : frames) {
    const double t_s = static_cast<double>(f.t_ns) * 1e-9;
    if (t_s > 3.7 && t_s < 4.4) {
      EXPECT_NEAR(f.table_deg.y(), 90.0, 1e-3) << t_s;
      ++level;
    }
  }
  EXPECT_GT(level, 50);
  EXPECT_FALSE(d.service->sequencer().telemetry().at("table").at("interlock_closed").get<bool>());
  d.service->stop();
  d.service.reset();
  EXPECT_EQ(devices.stop(), 0);
}

// The simulated table and chamber of `imucal sim-devices`, in-process, so that the test can see
// the table as it is.
sim::SimDevicesConfig in_process_devices(const std::string& socket_path) {
  sim::SimDevicesConfig c;
  for (auto& axis : c.servo.limits) axis.fill(drivers::AxisLimitSetting{-1e9, 1e9, 300, 300});
  c.imu_socket_path = socket_path;
  c.imu.rate_hz = 100;
  return c;
}

TEST(ConfiguredDevices, ACanInterfaceThisKernelCannotOpenFailsTheRunWithTheReason) {
  const std::string dir = scratch_dir("devices-can");
  sim::SimDevices sim(in_process_devices(socket_path_for(::testing::UnitTest::GetInstance()->current_test_info()->name())));
  json devices = json::parse(sim.devices_config_json());
  devices["imu"].erase("socket");
  devices["imu"]["interface"] = "can0";
  write_file(dir + "/imucald.json", json{{"devices", devices}});

  LocalDaemon d("devices-can0", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  const auto id = d.post_campaign(short_campaign("can0"));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 30.0);
  EXPECT_EQ(c.at("state"), "failed");
  const std::string error = c.at("error").get<std::string>();
  EXPECT_NE(error.find("CAN interface 'can0'"), std::string::npos) << error;
  // This kernel has no AF_CAN; a kernel with SocketCAN but no can0 says so instead.
  EXPECT_TRUE(error.find("no SocketCAN support") != std::string::npos ||
              error.find("no such network interface") != std::string::npos)
      << error;
  EXPECT_NE(error.find("nothing was moved"), std::string::npos) << error;
  EXPECT_EQ(c.at("frames"), 0);
  // The table was never contacted: still parked (interlock open, every axis off), at rest.
  const drivers::TableStatus s = table_truth(sim);
  EXPECT_EQ(s.interlock, drivers::InterlockState::open);
  for (const auto& axis : s.axes) EXPECT_EQ(axis.mode, drivers::TableMode::off);
  EXPECT_EQ(sim.imu_links(), 0u);
}

TEST(ConfiguredDevices, AChamberThatDoesNotAnswerFailsTheStartAndParksTheTable) {
  const std::string dir = scratch_dir("devices-chamber");
  sim::SimDevices sim(in_process_devices(socket_path_for(::testing::UnitTest::GetInstance()->current_test_info()->name())));
  // Someone left the table spinning: a failed start must not leave it so once it took it over.
  {
    drivers::TcpTableConfig tc;
    tc.port = sim.table_port();
    drivers::TcpTable table(tc);
    ASSERT_TRUE(table.connect());
    ASSERT_TRUE(table.interlock_close());
    ASSERT_TRUE(table.set_mode(0, drivers::TableMode::rate));
    ASSERT_TRUE(table.demand_rate(0, 10.0));
  }
  const int closed_port = closed_loopback_port();
  ASSERT_GT(closed_port, 0);
  json devices = json::parse(sim.devices_config_json());
  devices["chamber"]["port"] = closed_port;
  devices["chamber"]["response_timeout_ms"] = 300;
  write_file(dir + "/imucald.json", json{{"devices", devices}});

  LocalDaemon d("devices-nochamber", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  const auto id = d.post_campaign(short_campaign("no-chamber"));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 60.0);
  EXPECT_EQ(c.at("state"), "failed");
  const std::string error = c.at("error").get<std::string>();
  EXPECT_NE(error.find("chamber: connect"), std::string::npos) << error;
  EXPECT_NE(error.find(":" + std::to_string(closed_port)), std::string::npos) << error;
  EXPECT_NE(error.find("the table was parked (axes off, interlock open)"), std::string::npos) << error;
  EXPECT_EQ(c.at("frames"), 0);
  const drivers::TableStatus s = table_truth(sim);
  EXPECT_EQ(s.interlock, drivers::InterlockState::open);
  for (const auto& axis : s.axes) {
    EXPECT_EQ(axis.mode, drivers::TableMode::off);
    EXPECT_FALSE(axis.moving);
  }
}

// A program that cycles the IMU's power needs the relay hours later: at the start, a relay that
// says the IMU is unpowered while the IMU answers (the coil's sense configured wrong) fails the
// run before anything moves, naming the relay and the key to check; a relay that is not there
// fails it naming its address.
TEST(ConfiguredDevices, APowerRelayThatCannotServeTheProgramFailsTheStart) {
  const std::string dir = scratch_dir("devices-relay");
  sim::SimDevices sim(in_process_devices(socket_path_for(::testing::UnitTest::GetInstance()->current_test_info()->name())));
  json campaign = short_campaign("relay");
  campaign["program"]["segments"] = json::parse(R"([{"type": "hold", "name": "a", "duration_s": 1},
    {"type": "power-cycle", "name": "power-on-2", "duration_s": 1}])");
  const auto run = [&](const json& relay, const std::string& tag) {
    json devices = json::parse(sim.devices_config_json());
    devices["power_relay"] = relay;
    write_file(dir + "/" + tag + ".json", json{{"devices", devices}});
    LocalDaemon d("devices-" + tag, false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/" + tag + ".json", c); });
    const auto id = d.post_campaign(campaign);
    EXPECT_EQ(d.command(id, "start"), 200);
    return d.wait_final(id, 60.0);
  };
  json relay = json::parse(sim.devices_config_json()).at("power_relay");
  relay["on_when_set"] = false;  // the simulated supply's contact is normally open
  const json wrong = run(relay, "relay-sense");
  EXPECT_EQ(wrong.at("state"), "failed");
  std::string error = wrong.at("error").get<std::string>();
  EXPECT_NE(error.find("coil 0 says the IMU is unpowered, but the IMU answers: check the coil and on_when_set"),
            std::string::npos) << error;
  EXPECT_NE(error.find("the table was parked"), std::string::npos) << error;
  EXPECT_EQ(wrong.at("frames"), 0);

  const int closed_port = closed_loopback_port();
  ASSERT_GT(closed_port, 0);
  relay = json::parse(sim.devices_config_json()).at("power_relay");
  relay["port"] = closed_port;
  relay["response_timeout_ms"] = 300;
  const json missing = run(relay, "relay-missing");
  EXPECT_EQ(missing.at("state"), "failed");
  error = missing.at("error").get<std::string>();
  EXPECT_NE(error.find("power relay modbus-tcp://127.0.0.1:" + std::to_string(closed_port)), std::string::npos) << error;
  EXPECT_EQ(missing.at("frames"), 0);
  EXPECT_TRUE(sim.chamber().coil_changes().empty()) << "nothing was switched";
}

// A pause while the relay holds the IMU off switches it on first (every way out of a run leaves
// the IMU powered); the resumed run power-cycles it again, for the whole off time.
TEST(ConfiguredDevices, APauseWhileTheRelayHoldsTheImuOffSwitchesItOnFirst) {
  const std::string dir = scratch_dir("devices-relay-pause-config");
  sim::SimDevices sim(in_process_devices(socket_path_for(::testing::UnitTest::GetInstance()->current_test_info()->name())));
  json devices = json::parse(sim.devices_config_json());
  devices["power_relay"]["off_s"] = 8;  // room for the pause on a loaded machine
  write_file(dir + "/imucald.json", json{{"devices", devices}});
  LocalDaemon d("devices-relay-pause", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  json campaign = short_campaign("relay-pause");
  campaign["program"]["segments"] = json::parse(R"([{"type": "hold", "name": "a", "duration_s": 1},
    {"type": "power-cycle", "name": "power-on-2", "duration_s": 1}, {"type": "hold", "name": "b", "duration_s": 0.5}])");
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  // The relay itself, not the stored event: a store slowed by a loaded disk would show the event
  // late and eat into the off time the pause must land in.
  const auto imu_off = [&] { return !sim.chamber().coil_changes().empty() && !sim.chamber().coil(sim::SimDevices::kImuPowerCoil); };
  const auto waited = std::chrono::steady_clock::now();
  while (!imu_off() && std::chrono::steady_clock::now() - waited < std::chrono::seconds(60))
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(imu_off()) << "the relay never switched the IMU off";
  ASSERT_EQ(d.command(id, "pause"), 200);
  const json paused = d.wait_state(id, "paused", 30.0);
  EXPECT_TRUE(has_event(paused, "power-on")) << paused.at("events").dump();
  EXPECT_TRUE(sim.chamber().coil(sim::SimDevices::kImuPowerCoil)) << "the IMU is on while the run is paused";
  ASSERT_EQ(d.command(id, "resume"), 200);
  const json c = d.wait_final(id, 60.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  const auto changes = sim.chamber().coil_changes();
  ASSERT_EQ(changes.size(), 4u) << "off, on (the pause), off, on; events: " << c.at("events").dump();
  for (std::size_t i = 0; i < changes.size(); ++i) EXPECT_EQ(changes[i].set, i % 2 == 1) << i;
  EXPECT_LT(changes[1].t_s - changes[0].t_s, 8.0) << "the pause cut the first off time short";
  EXPECT_GE(changes[3].t_s - changes[2].t_s, 8.0) << "the second power cycle is whole";
  EXPECT_TRUE(sim.chamber().coil(sim::SimDevices::kImuPowerCoil));
}

// A KVH-style serial IMU (the built-in kvh-1750 description: float32 delta angles, accelerations in
// g, a 7-bit counter, CRC-32/MPEG-2) on a pseudo-terminal, reached by the daemon through the
// serial device path in its configuration. A campaign records every frame of its grid once; a
// corrupted CRC, a dropped byte and a sequence jump on the line each suspend the run (a gap: the
// frame is never recorded wrong), which redoes the segment and still records every frame once.
TEST(ConfiguredDevices, AKvhSerialImuOverAPseudoTerminalRecordsEveryFrameOnceThroughFaults) {
  const std::string dir = scratch_dir("devices-kvh-config");
  sim::SimDevicesConfig sc = in_process_devices("");
  sc.imu_link = "kvh-1750";
  sc.imu_serial = "KVH-TEST-1";
  sim::SimDevices sim(sc);
  ASSERT_FALSE(sim.imu_serial_device().empty());
  json devices = json::parse(sim.devices_config_json());
  EXPECT_EQ(devices["imu"]["link"], "kvh-1750");
  EXPECT_FALSE(devices["imu"].contains("gyro_lsb_rad"));  // the description fixes the units
  write_file(dir + "/imucald.json", json{{"devices", devices}});

  LocalDaemon d("devices-kvh", false, [&](daemon::DaemonConfig& c) { use_devices_of(dir + "/imucald.json", c); });
  const auto id = d.post_campaign(short_campaign("kvh"));
  ASSERT_EQ(d.command(id, "start"), 200);
  // Faults on the line while it runs, one after the other, each once the run is going again.
  using Fault = std::function<void(sim::SimImu&)>;
  const std::vector<std::pair<std::string, Fault>> faults = {
      {"corrupted CRC", [](sim::SimImu& imu) { imu.corrupt_next_samples(1); }},
      {"dropped byte", [](sim::SimImu& imu) { imu.drop_byte_of_next_sample(); }},
      {"sequence jump", [](sim::SimImu& imu) { imu.skip_sequence(3); }},
  };
  std::size_t suspensions = 0;
  for (const auto& [name, fault] : faults) {
    d.wait_for(id, [](const json& c) { return c.value("state", "") == "running" && c.value("frames", 0) > 50; }, 60.0);
    ASSERT_TRUE(sim.with_imu(fault)) << name;
    const json c = d.wait_for(id, [&](const json& x) {
      return x.value("state", "") == "suspended" || x.value("state", "") == "done";
    }, 60.0);
    if (c.value("state", "") == "done") break;  // the program ended first (a loaded machine)
    ++suspensions;
  }
  const json c = d.wait_final(id, 120.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_GE(suspensions, 1u) << c.dump();
  EXPECT_TRUE(has_event(c, "suspended")) << c.dump();
  EXPECT_EQ(c.at("bad_frames"), 0);
  EXPECT_TRUE(has_event(c, "info", sim.imu_serial_device())) << c.dump();

  const auto frames = run_frames(d.run_path(c));
  const double duration_s = c.at("duration_s").get<double>();
  ASSERT_GE(static_cast<double>(frames.size()), duration_s * 100.0 - 1.0);
  EXPECT_EQ(off_grid(frames, 10'000'000), 0u);  // every instant once, none wrong, none twice
  const RecordingMeta meta = storage::RunDb::open(d.run_path(c), storage::OpenMode::Read).meta();
  EXPECT_EQ(meta.imu_serial, "KVH-TEST-1");
  EXPECT_FALSE(meta.gyro_lsb_rad.has_value());  // float increments: stored as doubles
  // The IMU senses the 30 deg/s spin through the float32 delta angles.
  double rate_sum_dps = 0.0;
  int rate_n = 0;
  for (const ImuFrame& f : frames) {
    const double t_s = static_cast<double>(f.t_ns) * 1e-9;
    if (t_s > 5.5 && t_s < 6.8) {
      rate_sum_dps += f.dtheta_rad.norm() / 0.01 * 180.0 / M_PI;
      ++rate_n;
    }
  }
  ASSERT_GT(rate_n, 50);
  EXPECT_NEAR(rate_sum_dps / rate_n, 30.0, 0.5);
}
