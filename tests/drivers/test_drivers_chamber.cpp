// The Modbus chamber driver against the simulated chamber (a libmodbus TCP server on loopback):
// both built-in maps, Fahrenheit controllers, driver and controller ramps, alarms, and every
// link fault, each reported as a typed error within a bounded time; plus a garbage-reply fuzz.
#include <atomic>
#include <cmath>
#include <random>
#include <thread>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "drivers/modbus_chamber.hpp"
#include "drivers/power_relay.hpp"
#include "sim/sim_chamber.hpp"
#include "test_helpers.hpp"

using namespace imucal::drivers;
namespace sim = imucal::sim;
using namespace std::chrono_literals;
using imucal::drivers::test::eventually;
using imucal::drivers::test::Stopwatch;
using imucal::drivers::test::bind_loopback;

namespace {

sim::SimChamberConfig sim_config(const std::string& map, double tau_s = 2.0) {
  sim::SimChamberConfig c;
  c.map = load_register_map(map);
  c.initial_C = 22.0;
  c.ambient_C = 22.0;
  c.time_constant_s = tau_s;
  return c;
}

ModbusChamberConfig driver_config(const sim::SimChamber& s, const std::string& map) {
  ModbusChamberConfig c;
  c.port = s.port();
  c.map = load_register_map(map);
  // Generous for a loaded machine, short enough to keep the suite fast.
  c.response_timeout = 400ms;
  c.backoff_initial = 50ms;
  c.backoff_max = 400ms;
  return c;
}

void bring_up(ModbusChamber& d) {
  ASSERT_TRUE(d.connect()) << d.describe();
  ASSERT_TRUE(d.configure());
  ASSERT_TRUE(d.activate());
  ASSERT_EQ(d.state(), DeviceState::active);
}

}  // namespace

TEST(ModbusChamber, F4tSetPointAndProcessValueInCelsius) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  ASSERT_TRUE(d.set_setpoint(40.0));
  EXPECT_NEAR(sim.setpoint_C(), 40.0, 1e-4);
  EXPECT_TRUE(sim.control_on());
  // The air follows the set point; each reading is a fresh read of the controller.
  ASSERT_TRUE(eventually([&] {
    auto r = d.read();
    return r && r->process_C > 30.0;
  }));
  const auto r = d.read();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_NEAR(r->setpoint_C, 40.0, 1e-4);
  const auto& working = r->working_setpoint_C;
  ASSERT_TRUE(working);
  EXPECT_NEAR(*working, 40.0, 1e-4);
  EXPECT_NEAR(r->process_C, sim.process_C(), 1.0);  // the air keeps moving between the two reads
  EXPECT_EQ(r->device_unit, TemperatureUnit::celsius);
  EXPECT_TRUE(r->alarms.empty());
  EXPECT_GT(r->t_ns, 0);
}

TEST(ModbusChamber, FahrenheitControllerIsReadAndWrittenInCelsius) {
  auto cfg = sim_config("watlow-f4t", 1000.0);
  cfg.unit = TemperatureUnit::fahrenheit;
  sim::SimChamber sim(cfg);
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  ASSERT_TRUE(d.set_setpoint(-20.0));
  EXPECT_NEAR(sim.setpoint_C(), -20.0, 1e-3);
  auto r = d.read();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->device_unit, TemperatureUnit::fahrenheit);
  EXPECT_NEAR(r->setpoint_C, -20.0, 1e-3);
  EXPECT_NEAR(r->process_C, sim.process_C(), 0.05);
  // Someone switches the front panel to Celsius mid-run: the next read follows.
  sim.set_unit(TemperatureUnit::celsius);
  r = d.read();
  ASSERT_TRUE(r);
  EXPECT_EQ(r->device_unit, TemperatureUnit::celsius);
  EXPECT_NEAR(r->setpoint_C, -20.0, 1e-3);
}

// A controller that runs its own ramps (a ramp-rate register and a working set point), with
// int16 values in tenths: a map of the test's own (neither built-in controller has both).
constexpr const char* kRampingInt16Map = R"({"format": "imucal-chamber-map/1", "name": "ramping-int16",
  "value": {"type": "int16", "scale": 10}, "process_value": 35, "setpoint": 60, "working_setpoint": 61,
  "ramp_rate_per_min": 62, "control_mode": {"address": 59, "auto": 1, "off": 0}, "fixed_unit": "C",
  "alarms": [{"name": "alarm word", "address": 33, "mask": 65535}]})";

TEST(ModbusChamber, Int16MapWithControllerRamp) {
  sim::SimChamberConfig sc = sim_config("csz-ezt570i", 0.5);
  sc.map = register_map_from_json(kRampingInt16Map);
  sim::SimChamber sim(sc);
  ModbusChamberConfig dc = driver_config(sim, "csz-ezt570i");
  dc.map = sc.map;
  ModbusChamber d(dc);
  bring_up(d);
  ASSERT_TRUE(d.set_setpoint(22.0));
  Stopwatch sw;
  ASSERT_TRUE(d.ramp_to(30.0, 240.0));  // 4 C/s, run by the controller
  EXPECT_NEAR(sim.setpoint_C(), 30.0, 0.05);
  auto r = d.read();
  ASSERT_TRUE(r);
  const auto& ramp_target = r->ramp_target_C;
  ASSERT_TRUE(ramp_target);
  EXPECT_NEAR(*ramp_target, 30.0, 1e-9);
  const auto& working = r->working_setpoint_C;
  ASSERT_TRUE(working);
  // Working set point on the ramp (0.1 C resolution of the int16 x10 registers).
  EXPECT_LE(*working, 22.0 + 4.0 * sw.seconds() + 0.2);
  ASSERT_TRUE(eventually([&] {
    auto x = d.read();
    return x && x->working_setpoint_C && std::fabs(*x->working_setpoint_C - 30.0) < 0.05 && !x->ramp_target_C;
  }));
  EXPECT_GT(sw.seconds(), 1.7);  // 8 C at 4 C/s
}

TEST(ModbusChamber, F4tRampIsSteppedByTheDriver) {
  sim::SimChamber sim(sim_config("watlow-f4t", 0.5));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  Stopwatch sw;
  ASSERT_TRUE(d.ramp_to(25.0, 180.0));  // 3 C/s from 22 C: one second
  double last_sp = 22.0;
  bool saw_intermediate = false;
  for (;;) {
    auto r = d.read();
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_GE(r->setpoint_C, last_sp - 1e-6);  // monotonic
    EXPECT_LE(r->setpoint_C, 22.0 + 3.0 * sw.seconds() + 0.05);  // never ahead of the ramp
    if (r->setpoint_C > 22.3 && r->setpoint_C < 24.7) saw_intermediate = true;
    last_sp = r->setpoint_C;
    if (!r->ramp_target_C) break;
    ASSERT_LT(sw.seconds(), 20.0);
    std::this_thread::sleep_for(20ms);
  }
  EXPECT_NEAR(last_sp, 25.0, 1e-4);
  EXPECT_TRUE(saw_intermediate);
  EXPECT_GT(sw.seconds(), 0.9);
}

TEST(ModbusChamber, AlarmIsReportedAndBlocksActivation) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  EXPECT_TRUE(d.check_alarms());
  sim.set_alarm(0, 7);  // "alarm high"
  auto r = d.read();
  ASSERT_TRUE(r);  // the values are still valid
  ASSERT_EQ(r->alarms.size(), 1u);
  EXPECT_EQ(r->alarms[0].name, "alarm 1");
  EXPECT_EQ(r->alarms[0].raw, 7);
  const auto c = d.check_alarms();
  EXPECT_EQ(c.code(), DriverErrc::alarm);
  EXPECT_NE(c.error().message.find("alarm 1"), std::string::npos);
  ASSERT_TRUE(d.safe_stop());
  EXPECT_EQ(d.activate().code(), DriverErrc::alarm);
  sim.clear_alarms();
  EXPECT_TRUE(d.activate());
}

TEST(ModbusChamber, SafeStopGoesToTheSafeSetPoint) {
  sim::SimChamber sim(sim_config("csz-ezt570i"));
  ModbusChamber d(driver_config(sim, "csz-ezt570i"));
  bring_up(d);
  ASSERT_TRUE(d.ramp_to(60.0, 1.0));
  ASSERT_TRUE(d.safe_stop());
  EXPECT_NEAR(sim.setpoint_C(), 25.0, 0.05);
  EXPECT_EQ(d.state(), DeviceState::configured);
  auto r = d.read();
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->ramp_target_C);
}

TEST(ModbusChamber, DroppedConnectionIsReportedThenReconnected) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  sim.drop_connections();
  Stopwatch sw;
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_TRUE(r.code() == DriverErrc::connection_lost || r.code() == DriverErrc::timeout) << r.error().message;
  EXPECT_LT(sw.seconds(), 3.0);
  EXPECT_EQ(d.state(), DeviceState::faulted);
  // The next call reconnects at once and reads fresh values.
  ASSERT_TRUE(eventually([&] { return d.read().ok(); }));
  EXPECT_EQ(d.state(), DeviceState::active);
  EXPECT_EQ(d.reconnects(), 1u);
}

TEST(ModbusChamber, LateReplyIsATimeoutAndNeverAStaleValue) {
  sim::SimChamber sim(sim_config("watlow-f4t", 1000.0));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  ASSERT_TRUE(d.set_setpoint(30.0));
  sim.set_reply_delay(1200ms);
  Stopwatch sw;
  const auto r = d.read();
  EXPECT_EQ(r.code(), DriverErrc::timeout);
  EXPECT_LT(sw.seconds(), 3.0);
  sim.set_reply_delay(0ms);
  // Change the truth while the late reply is still on its way: what the driver reports next
  // must be the new value, never the reply to the abandoned request.
  ASSERT_TRUE(eventually([&] { return d.set_setpoint(35.0).ok(); }));
  EXPECT_NEAR(sim.setpoint_C(), 35.0, 1e-4);
  auto fresh = d.read();
  ASSERT_TRUE(eventually([&] { return (fresh = d.read()).ok(); }));
  EXPECT_NEAR(fresh->setpoint_C, 35.0, 1e-4);
}

TEST(ModbusChamber, CorruptedReplyIsRejected) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  sim.corrupt_next_replies(1);
  const auto r = d.read();
  EXPECT_EQ(r.code(), DriverErrc::protocol_error) << (r ? "value returned" : r.error().message);
  ASSERT_TRUE(eventually([&] { return d.read().ok(); }));
}

TEST(ModbusChamber, SilentControllerTimesOutWithinTheResponseTimeout) {
  sim::SimChamber sim(sim_config("csz-ezt570i"));
  ModbusChamber d(driver_config(sim, "csz-ezt570i"));
  bring_up(d);
  sim.set_silent(true);
  Stopwatch sw;
  EXPECT_EQ(d.read().code(), DriverErrc::timeout);
  EXPECT_LT(sw.seconds(), 2.5);
  const auto w = d.set_setpoint(30.0);  // the next call reconnects and times out again
  EXPECT_EQ(w.code(), DriverErrc::timeout) << (w ? "" : w.error().message);
  sim.set_silent(false);
  ASSERT_TRUE(eventually([&] { return d.read().ok(); }));
}

TEST(ModbusChamber, UnreachableControllerBacksOff) {
  // A port nobody listens on: bind, read the number, close.
  int port = 0;
  ::close(bind_loopback(port, false));
  ModbusChamberConfig c;
  c.port = port;
  c.map = load_register_map("watlow-f4t");
  c.backoff_initial = 2000ms;
  ModbusChamber d(c);
  const auto r = d.connect();
  EXPECT_EQ(r.code(), DriverErrc::connect_failed);
  EXPECT_NE(r.error().message.find("127.0.0.1:" + std::to_string(port)), std::string::npos) << r.error().message;
  EXPECT_EQ(d.state(), DeviceState::disconnected);
}

TEST(ModbusChamber, BackoffBetweenFailedReconnections) {
  auto sim = std::make_unique<sim::SimChamber>(sim_config("watlow-f4t"));
  auto cfg = driver_config(*sim, "watlow-f4t");
  cfg.backoff_initial = 3000ms;
  cfg.backoff_max = 3000ms;
  ModbusChamber d(cfg);
  bring_up(d);
  sim.reset();  // the controller goes away
  EXPECT_FALSE(d.read());  // link loss detected
  const auto first = d.read();  // immediate reconnection attempt fails
  EXPECT_EQ(first.code(), DriverErrc::connect_failed) << first.error().message;
  Stopwatch sw;
  const auto second = d.read();  // within the backoff: no attempt, answered at once
  EXPECT_EQ(second.code(), DriverErrc::not_connected);
  EXPECT_NE(second.error().message.find("next attempt in"), std::string::npos);
  EXPECT_LT(sw.seconds(), 0.5);
}

TEST(ModbusChamber, RtuOnAMissingSerialDeviceFailsNamingIt) {
  ModbusChamberConfig c;
  c.transport = ModbusChamberConfig::Transport::rtu;
  c.serial_device = "/dev/ttyIMUCAL-missing";
  c.map = load_register_map("csz-ezt570i");
  ModbusChamber d(c);
  const auto r = d.connect();
  EXPECT_EQ(r.code(), DriverErrc::connect_failed);
  EXPECT_NE(r.error().message.find("/dev/ttyIMUCAL-missing"), std::string::npos) << r.error().message;
}

TEST(RegisterMap, BuiltInMapsNameTheManualPageOfEveryRegisterOrSayTheyAreNotChecked) {
  const RegisterMap f4t = load_register_map("watlow-f4t");
  EXPECT_EQ(f4t.source.summary(),
            "partly checked against Watlow F4T Controller Setup and Operations User's Guide, with the TestEquity F4T "
            "chamber manual (chapter 4, Communications); not checked: control_mode, alarms");
  for (const RegisterSource& r : f4t.source.registers) EXPECT_FALSE(r.where.empty()) << r.key;
  const RegisterMap ezt = load_register_map("csz-ezt570i");
  EXPECT_EQ(ezt.source.unchecked_keys(), std::vector<std::string>{"fixed_unit"});
  // A lab's own map without a source, and a source that names a key the map does not use.
  EXPECT_EQ(register_map_from_json(kRampingInt16Map).source.summary(), "not checked against a maker's manual");
  try {
    (void)register_map_from_json(R"({"format": "imucal-chamber-map/1", "name": "x", "value": {"type": "int16", "scale": 10},
      "process_value": 1, "setpoint": 2, "source": {"manual": "M", "registers": {"ramp_rate_per_min": {"checked": true}}}})");
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "register map 'x': 'source.registers.ramp_rate_per_min' is not a key the map uses");
  }
}

TEST(ModbusChamber, ConfigurationFromJson) {
  const auto c = modbus_chamber_config_from_json(
      R"({"transport":"rtu","serial_device":"/dev/ttyS1","baud":19200,"parity":"E","map":"csz-ezt570i",
          "response_timeout_ms":250,"safe_setpoint_C":18,"setpoint_range_C":[-40,120]})");
  EXPECT_EQ(c.transport, ModbusChamberConfig::Transport::rtu);
  EXPECT_EQ(c.baud, 19200);
  EXPECT_EQ(c.parity, 'E');
  EXPECT_EQ(c.map.name, "csz-ezt570i");
  EXPECT_EQ(c.response_timeout, 250ms);
  EXPECT_DOUBLE_EQ(c.safe_setpoint_C.value_or(0), 18.0);
  EXPECT_DOUBLE_EQ(c.setpoint_max_C, 120.0);
  // Control off as the safe stop needs a control-mode register, which the F4T's map has.
  EXPECT_FALSE(modbus_chamber_config_from_json(R"({"map":"watlow-f4t","safe_setpoint_C":null})").safe_setpoint_C);
  try {
    (void)modbus_chamber_config_from_json(R"({"map":"csz-ezt570i","safe_setpoint_C":null})");
    ADD_FAILURE() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "chamber config: safe_setpoint_C is null but the map has no control_mode register to switch off");
  }
  try {
    (void)modbus_chamber_config_from_json(R"({"map":"watlow-f4t","baudrate":9600})");
    ADD_FAILURE() << "accepted a misspelt key";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "chamber config: unknown key \"baudrate\"");
  }
  EXPECT_THROW(modbus_chamber_config_from_json(R"({"transport":"udp","map":"watlow-f4t"})"), std::invalid_argument);
  EXPECT_THROW(modbus_chamber_config_from_json(R"({"port":70000,"map":"watlow-f4t"})"), std::invalid_argument);
}

TEST(ModbusChamber, RefusesSetPointsOutsideTheConfiguredRange) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  ModbusChamber d(driver_config(sim, "watlow-f4t"));
  bring_up(d);
  EXPECT_EQ(d.set_setpoint(500.0).code(), DriverErrc::invalid_argument);
  EXPECT_EQ(d.set_setpoint(std::nan("")).code(), DriverErrc::invalid_argument);
  EXPECT_EQ(d.ramp_to(30.0, 0.0).code(), DriverErrc::invalid_argument);
  EXPECT_NEAR(sim.setpoint_C(), 22.0, 1e-4);
}

// Fuzz at the wire: a server that answers every request with random bytes (the request's own
// transaction id half of the time, so that libmodbus reads on into the random PDU). The driver
// must return an error every time, within its timeout, and never a value.
// ------------------------------------------------------------------------------------------------
// The IMU's power relay: a coil of the chamber controller's digital outputs (or a relay module).

namespace {

PowerRelayConfig relay_config(const sim::SimChamber& s, int coil) {
  PowerRelayConfig c;
  c.port = s.port();
  c.coil = coil;
  c.response_timeout = 400ms;
  c.backoff_initial = 50ms;
  c.backoff_max = 400ms;
  return c;
}

}  // namespace

TEST(PowerRelay, SwitchesTheCoilAndReadsItBack) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  PowerRelay relay(relay_config(sim, 3));
  ASSERT_TRUE(relay.set_power(true)) << relay.describe();
  EXPECT_TRUE(sim.coil(3));
  EXPECT_TRUE(*relay.powered());
  ASSERT_TRUE(relay.set_power(false));
  EXPECT_FALSE(sim.coil(3));
  EXPECT_FALSE(*relay.powered());
  ASSERT_TRUE(relay.set_power(true));
  const auto changes = sim.coil_changes();
  ASSERT_EQ(changes.size(), 3u);
  EXPECT_TRUE(changes[0].set);
  EXPECT_FALSE(changes[1].set);
  EXPECT_TRUE(changes[2].set);
  for (const auto& c : changes) EXPECT_EQ(c.coil, 3);
  EXPECT_EQ(relay.describe(), "power relay modbus-tcp://127.0.0.1:" + std::to_string(sim.port()) + " unit 1 coil 3");
}

TEST(PowerRelay, ANormallyClosedContactPowersTheImuWhileTheCoilIsClear) {
  sim::SimChamber sim(sim_config("watlow-f4t"));
  PowerRelayConfig c = relay_config(sim, 0);
  c.on_when_set = false;
  PowerRelay relay(c);
  EXPECT_TRUE(*relay.powered()) << "the coil starts clear";
  ASSERT_TRUE(relay.set_power(false));
  EXPECT_TRUE(sim.coil(0));
  ASSERT_TRUE(relay.set_power(true));
  EXPECT_FALSE(sim.coil(0));
}

TEST(PowerRelay, ACoilTheDeviceDoesNotHaveIsNamedInTheError) {
  sim::SimChamber sim(sim_config("watlow-f4t"));  // 8 digital outputs: coils 0..7
  PowerRelay relay(relay_config(sim, 12));
  const auto r = relay.set_power(false);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::device_rejected);
  EXPECT_NE(r.error().message.find("coil 12"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("switching the IMU off"), std::string::npos) << r.error().message;
}

TEST(PowerRelay, AnUnreachableRelayFailsWithinTheTimeoutNamingIt) {
  int port = 0;
  ::close(bind_loopback(port, false));  // a port nobody listens on
  PowerRelayConfig c;
  c.port = port;
  c.response_timeout = 300ms;
  PowerRelay relay(c);
  Stopwatch sw;
  const auto r = relay.set_power(true);
  ASSERT_FALSE(r);
  EXPECT_LT(sw.seconds(), 2.0);
  EXPECT_EQ(r.code(), DriverErrc::connect_failed);
  EXPECT_NE(r.error().message.find("power relay modbus-tcp://127.0.0.1:" + std::to_string(port)), std::string::npos)
      << r.error().message;
}

TEST(PowerRelay, ConfigurationFromJson) {
  const auto c = power_relay_config_from_json(
      R"({"host": "10.0.0.7", "port": 1502, "unit_id": 4, "coil": 2, "on_when_set": false, "off_s": 15})");
  EXPECT_EQ(c.host, "10.0.0.7");
  EXPECT_EQ(c.port, 1502);
  EXPECT_EQ(c.unit_id, 4);
  EXPECT_EQ(c.coil, 2);
  EXPECT_FALSE(c.on_when_set);
  EXPECT_DOUBLE_EQ(c.off_s, 15.0);
  auto message = [](const char* text) {
    try {
      (void)power_relay_config_from_json(text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message(R"({"coil": -1})"), "power relay config: coil is -1, must be between 0 and 65535");
  EXPECT_EQ(message(R"({"unit_id": 0})"), "power relay config: unit_id is 0, must be between 1 and 247");
  EXPECT_EQ(message(R"({"off_s": 0.2})"), "power relay config: off_s is 0.2, must be between 1.0 and 600.0");
  EXPECT_EQ(message(R"({"transport": "udp"})"), "power relay config: transport must be \"tcp\" or \"rtu\", not \"udp\"");
  // Read on its own, the driver's configuration is as strict as the daemon's: a misspelt key is
  // refused, not defaulted (an "of_s" would have left the IMU off for the default 10 s).
  EXPECT_EQ(message(R"({"coil": 1, "of_s": 3})"), "power relay config: unknown key \"of_s\"");
  EXPECT_EQ(message(R"({"coil": 1, "_note": "comments are ignored"})"), "accepted");
}

TEST(ModbusChamberFuzz, RandomRepliesNeverYieldAValue) {
  int port = 0;
  const int ls = bind_loopback(port);
  std::atomic<bool> stop{false};
  std::thread server([&] {
    std::mt19937_64 rng(2024);
    std::vector<int> clients;
    while (!stop) {
      std::vector<pollfd> fds{{ls, POLLIN, 0}};
      for (int c : clients) fds.push_back({c, POLLIN, 0});
      if (::poll(fds.data(), fds.size(), 20) <= 0) continue;
      if (fds[0].revents & POLLIN) clients.push_back(::accept(ls, nullptr, nullptr));
      for (std::size_t i = 1; i < fds.size(); ++i) {
        if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        std::uint8_t req[300];
        const ssize_t n = ::recv(fds[i].fd, req, sizeof req, 0);
        if (n <= 0) {
          ::close(fds[i].fd);
          clients.erase(std::find(clients.begin(), clients.end(), fds[i].fd));
          continue;
        }
        std::vector<std::uint8_t> rep(rng() % 24);
        for (auto& b : rep) b = static_cast<std::uint8_t>(rng());
        if (rep.size() >= 8 && n >= 8 && rng() % 2) {
          rep[0] = req[0];
          rep[1] = req[1];
          rep[2] = 0;
          rep[3] = 0;
          rep[6] = req[6];
          if (rng() % 2) rep[7] = req[7];  // the request's function code
        }
        if (rng() % 8 == 0) {
          ::close(fds[i].fd);  // or hang up
          clients.erase(std::find(clients.begin(), clients.end(), fds[i].fd));
          continue;
        }
        (void)::send(fds[i].fd, rep.data(), rep.size(), MSG_NOSIGNAL);
      }
    }
    for (int c : clients) ::close(c);
  });
  ModbusChamberConfig c;
  c.port = port;
  c.map = load_register_map("watlow-f4t");
  c.map.units.reset();  // fewer registers per read: more random replies per second
  c.map.alarms.clear();
  c.map.working_setpoint.reset();
  c.response_timeout = 60ms;
  c.backoff_initial = 1ms;
  c.backoff_max = 1ms;
  ModbusChamber d(c);
  (void)d.connect();
  int values = 0;
  Stopwatch total;
  for (int i = 0; i < 150 && total.seconds() < 2.5; ++i) {
    Stopwatch sw;
    const auto r = d.read();
    if (r) ++values;
    EXPECT_LT(sw.seconds(), 2.0);
  }
  EXPECT_EQ(values, 0);
  stop = true;
  server.join();
  ::close(ls);
}
