// Conformance of the Modbus chamber driver against an implementation imucal did not write: a
// controller served by Debian's python3-pymodbus (tests/drivers/pymodbus_chamber.py) over Modbus
// TCP and over RTU on a pseudo-terminal, holding the same register map as the driver (the server
// reads the very JSON the driver's map comes from). The server's own decoding of what the driver
// wrote, raw register words computed here by hand, and the function codes the server saw are
// checked, so a wrong word order or function code in the driver fails here even though the
// driver agrees with imucal's own simulated chamber.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "drivers/modbus_chamber.hpp"
#include "drivers/power_relay.hpp"
#include "test_helpers.hpp"
#include "tests/test_paths.hpp"

extern char** environ;

using namespace imucal::drivers;
using namespace std::chrono_literals;
using imucal::drivers::test::eventually;
using imucal::drivers::test::Stopwatch;
using nlohmann::json;

namespace {

const std::string kServerScript = imucaltest::source_dir() + "/tests/drivers/pymodbus_chamber.py";
const std::string kInstallHint =
    "python3-pymodbus is not importable by any python3 tried (IMUCAL_PYTHON3, /usr/bin/python3, python3 "
    "on PATH): run scripts/install-deps.sh";

// Runs `argv` to completion with no output; its exit status, or -1 when it cannot be started.
int run_quietly(const std::vector<std::string>& argv) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return -1;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The first python3 that imports pymodbus: a pyenv or virtualenv python3 first on PATH does not
// see Debian's dist-packages, so /usr/bin/python3 is tried before PATH.
const std::optional<std::string>& python_with_pymodbus() {
  static const std::optional<std::string> found = [] {
    std::vector<std::string> candidates;
    if (const char* env = std::getenv("IMUCAL_PYTHON3"); env && *env) candidates.emplace_back(env);
    candidates.emplace_back("/usr/bin/python3");
    candidates.emplace_back("python3");
    for (const std::string& py : candidates)
      if (run_quietly({py, "-c", "import pymodbus.server, pymodbus.payload, serial_asyncio"}) == 0)
        return std::optional<std::string>(py);
    return std::optional<std::string>();
  }();
  return found;
}

// The pymodbus chamber as a child process: commands on its stdin, one JSON line back on its
// stdout for each. Closing its stdin ends it.
class PymodbusChamber {
 public:
  enum class Transport { tcp, rtu };

  PymodbusChamber(const std::string& map_json, Transport transport) {
    const auto& py = python_with_pymodbus();
    if (!py) throw std::runtime_error(kInstallHint);
    std::filesystem::create_directories(imucaltest::test_tmp_dir());
    map_path_ = imucaltest::test_tmp_dir() + "/pymodbus-map-" + std::to_string(::getpid()) + "-" +
                std::to_string(counter()++) + ".json";
    std::ofstream(map_path_) << map_json;

    std::vector<std::string> argv{*py, kServerScript, "--map", map_path_};
    argv.emplace_back(transport == Transport::tcp ? "--tcp-port=0" : "--rtu");
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);

    int to_child[2], from_child[2];
    if (::pipe2(to_child, O_CLOEXEC) != 0 || ::pipe2(from_child, O_CLOEXEC) != 0)
      throw std::runtime_error("pipe failed");
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, to_child[0], STDIN_FILENO);
    posix_spawn_file_actions_adddup2(&fa, from_child[1], STDOUT_FILENO);
    const int rc = posix_spawnp(&pid_, args[0], &fa, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    ::close(to_child[0]);
    ::close(from_child[1]);
    in_fd_ = to_child[1];
    out_fd_ = from_child[0];
    if (rc != 0) {
      pid_ = -1;
      throw std::runtime_error("cannot start " + *py + " " + kServerScript);
    }
    hello_ = json::parse(read_line());
  }

  ~PymodbusChamber() {
    stop();
    if (in_fd_ >= 0) ::close(in_fd_);
    if (out_fd_ >= 0) ::close(out_fd_);
    std::error_code ec;
    std::filesystem::remove(map_path_, ec);
  }
  PymodbusChamber(const PymodbusChamber&) = delete;
  PymodbusChamber& operator=(const PymodbusChamber&) = delete;

  int tcp_port() const { return hello_.at("tcp_port").get<int>(); }
  std::string rtu_device() const { return hello_.at("rtu_device").get<std::string>(); }

  // Sends one command, returns its JSON answer; an answer {"error": ...} throws.
  json command(const std::string& line) {
    const std::string text = line + "\n";
    if (::write(in_fd_, text.data(), text.size()) != static_cast<ssize_t>(text.size()))
      throw std::runtime_error("pymodbus chamber: cannot send '" + line + "'");
    json answer = json::parse(read_line());
    if (answer.contains("error")) throw std::runtime_error("pymodbus chamber: '" + line + "': " + answer["error"].get<std::string>());
    return answer;
  }

  // The server's own (pymodbus BinaryPayloadDecoder) reading of a mapped value.
  double value(const std::string& name) { return command("get " + name).at("value").get<double>(); }
  std::vector<std::uint16_t> registers(const std::string& name) {
    return command("get " + name).at("registers").get<std::vector<std::uint16_t>>();
  }
  std::uint16_t raw(int address) { return command("raw " + std::to_string(address) + " 1").at("registers").at(0).get<std::uint16_t>(); }
  std::vector<int> function_codes() { return command("fcs").at("function_codes").get<std::vector<int>>(); }

  // Ends the server (stdin closed; killed if it has not exited within the deadline).
  void stop() {
    if (pid_ < 0) return;
    if (in_fd_ >= 0) {
      ::close(in_fd_);
      in_fd_ = -1;
    }
    const auto until = std::chrono::steady_clock::now() + 10s;
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > until) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(5ms);
    }
    pid_ = -1;
  }

 private:
  static int& counter() {
    static int n = 0;
    return n;
  }

  // One line of the child's stdout, waited for with a generous deadline (python's start-up on
  // a loaded machine).
  std::string read_line() {
    const auto until = std::chrono::steady_clock::now() + 20s;
    for (;;) {
      if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      const auto left_ms = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now()).count();
      if (left_ms <= 0) throw std::runtime_error("pymodbus chamber: no answer within 20 s");
      pollfd p{out_fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left_ms)) <= 0) continue;
      char chunk[4096];
      const ssize_t n = ::read(out_fd_, chunk, sizeof chunk);
      if (n <= 0) throw std::runtime_error("pymodbus chamber: the server exited (its stderr is above)");
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  pid_t pid_ = -1;
  int in_fd_ = -1;
  int out_fd_ = -1;
  std::string buffer_;
  std::string map_path_;
  json hello_;
};

ModbusChamberConfig tcp_config(const PymodbusChamber& server, const std::string& map_json) {
  ModbusChamberConfig c;
  c.port = server.tcp_port();
  c.map = register_map_from_json(map_json);
  // Generous for a loaded machine (python answers slower than the simulated chamber), short
  // enough to keep each test within a few seconds.
  c.response_timeout = 1000ms;
  c.backoff_initial = 50ms;
  c.backoff_max = 400ms;
  return c;
}

void bring_up(ModbusChamber& d) {
  const auto c = d.connect();
  ASSERT_TRUE(c) << c.error().message;
  const auto f = d.configure();
  ASSERT_TRUE(f) << f.error().message;
  const auto a = d.activate();
  ASSERT_TRUE(a) << a.error().message;
}

// A map of the test's own for each 32-bit word order, beside the two built-in maps; the alarm
// word has two bits of its own so that a bit is told from its neighbour.
std::string float_map(const std::string& word_order) {
  return R"({"format": "imucal-chamber-map/1", "name": "pymodbus-)" + word_order + R"(", "slave_id": 7,
    "value": {"type": "float32", "word_order": ")" + word_order + R"("},
    "process_value": 100, "setpoint": 102, "working_setpoint": 104,
    "control_mode": {"address": 110, "auto": 1, "off": 0}, "fixed_unit": "C",
    "alarms": [{"name": "high limit", "address": 120, "mask": 1},
               {"name": "door open", "address": 120, "mask": 4}]})";
}

// 47.11 as binary32 is 0x423C70A4: four different bytes, so every word and byte order differs.
struct MapCase {
  const char* label;
  std::string map_json;
  std::vector<std::uint16_t> words_47_11;  // the set point's registers, computed by hand
  double resolution_C;                     // of the map's encoding
};

// The case's name instead of its bytes in gtest's messages.
void PrintTo(const MapCase& c, std::ostream* os) { *os << c.label; }

std::vector<MapCase> map_cases() {
  return {
      {"WatlowF4tCDAB", builtin_register_map_json("watlow-f4t"), {0x70A4, 0x423C}, 1e-4},
      {"EztInt16x10", builtin_register_map_json("csz-ezt570i"), {471}, 0.05},  // 47.1
      {"ABCD", float_map("ABCD"), {0x423C, 0x70A4}, 1e-4},
      {"CDAB", float_map("CDAB"), {0x70A4, 0x423C}, 1e-4},
      {"BADC", float_map("BADC"), {0x3C42, 0xA470}, 1e-4},
      {"DCBA", float_map("DCBA"), {0xA470, 0x3C42}, 1e-4},
  };
}

class PymodbusMaps : public ::testing::TestWithParam<MapCase> {
 protected:
  void SetUp() override { ASSERT_TRUE(python_with_pymodbus()) << kInstallHint; }
};

}  // namespace

TEST_P(PymodbusMaps, SetPointLandsInTheServersRegistersInTheMapsWordOrder) {
  PymodbusChamber server(GetParam().map_json, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, GetParam().map_json));
  bring_up(d);
  const auto r = d.set_setpoint(47.11);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(server.registers("setpoint"), GetParam().words_47_11);
  EXPECT_NEAR(server.value("setpoint"), 47.11, GetParam().resolution_C);  // pymodbus's own decoding
  // activate() switched closed-loop control on, where the map has a control-mode register.
  const RegisterMap map = register_map_from_json(GetParam().map_json);
  if (map.control_mode) {
    EXPECT_EQ(server.raw(map.control_mode->address), map.control_mode->auto_value);
  }
}

TEST_P(PymodbusMaps, ReadingDecodesWhatTheServerEncoded) {
  PymodbusChamber server(GetParam().map_json, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, GetParam().map_json));
  bring_up(d);
  server.command("set process_value -31.5");  // encoded by pymodbus's BinaryPayloadBuilder
  server.command("set setpoint 47.11");
  const auto r = d.read();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_NEAR(r->process_C, -31.5, 1e-4);
  EXPECT_NEAR(r->setpoint_C, 47.11, GetParam().resolution_C);
  EXPECT_TRUE(r->alarms.empty());
}

TEST_P(PymodbusMaps, FunctionCodesAreReadHoldingAndWriteRegisters) {
  PymodbusChamber server(GetParam().map_json, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, GetParam().map_json));
  bring_up(d);
  const std::vector<int> up = server.function_codes();
  // connect and configure read (3, read holding registers); activate writes the control-mode
  // register alone (6, write single register) where the map has one.
  ASSERT_FALSE(up.empty());
  const bool has_control_mode = register_map_from_json(GetParam().map_json).control_mode.has_value();
  if (has_control_mode) {
    EXPECT_EQ(up.back(), 6);
  }
  EXPECT_EQ(std::count(up.begin(), up.end(), 3), static_cast<long>(up.size()) - (has_control_mode ? 1 : 0));
  ASSERT_TRUE(d.read());
  for (int fc : server.function_codes()) EXPECT_EQ(fc, 3) << "a read used function code " << fc;
  ASSERT_TRUE(d.set_setpoint(30.0));
  const std::vector<int> sp = server.function_codes();
  ASSERT_FALSE(sp.empty());
  // A two-register float is one write-multiple request (16); an int16 map's one register, a
  // write-single (6).
  const bool one_register = register_map_from_json(GetParam().map_json).registers_per_value() == 1;
  EXPECT_EQ(sp.back(), one_register ? 6 : 16);
}

INSTANTIATE_TEST_SUITE_P(Conformance, PymodbusMaps, ::testing::ValuesIn(map_cases()),
                         [](const ::testing::TestParamInfo<MapCase>& param_info) { return std::string(param_info.param.label); });

class Pymodbus : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(python_with_pymodbus()) << kInstallHint; }
};

// The IMU's power relay against the same independent server: a coil written with function 5 and
// read back with function 1, in the relay's sense; a coil the server does not have is refused by
// the server and the error names it.
TEST_F(Pymodbus, PowerRelayWritesACoilWithFunctionFiveAndReadsItBackWithOne) {
  PymodbusChamber server(builtin_register_map_json("watlow-f4t"), PymodbusChamber::Transport::tcp);
  PowerRelayConfig c;
  c.port = server.tcp_port();
  c.coil = 3;
  c.response_timeout = 1000ms;
  PowerRelay relay(c);
  ASSERT_TRUE(relay.set_power(true)) << relay.describe();
  EXPECT_TRUE(server.command("coil 3").at("value").get<bool>());
  EXPECT_EQ(server.function_codes(), (std::vector<int>{5, 1}));
  ASSERT_TRUE(relay.set_power(false));
  EXPECT_FALSE(server.command("coil 3").at("value").get<bool>());
  EXPECT_FALSE(server.command("coil 2").at("value").get<bool>()) << "its neighbour untouched";
  const auto powered = relay.powered();
  ASSERT_TRUE(powered);
  EXPECT_FALSE(*powered);
  EXPECT_EQ(server.function_codes(), (std::vector<int>{5, 1, 1}));

  c.coil = 9;  // the server has coils 0..7
  PowerRelay missing(c);
  const auto r = missing.set_power(false);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::device_rejected);
  EXPECT_NE(r.error().message.find("coil 9: switching the IMU off: Illegal data address"), std::string::npos)
      << r.error().message;
}

TEST_F(Pymodbus, ReadingFollowsTheSetPoint) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.command("follow 40");  // C per second
  ASSERT_TRUE(d.set_setpoint(30.0));
  double last_C = 22.0;
  bool monotonic = true;
  ASSERT_TRUE(eventually([&] {
    const auto r = d.read();
    if (!r) return false;
    monotonic = monotonic && r->process_C >= last_C - 1e-4;
    last_C = r->process_C;
    return std::fabs(r->process_C - 30.0) < 1e-4 && r->working_setpoint_C && std::fabs(*r->working_setpoint_C - 30.0) < 1e-4;
  }));
  EXPECT_TRUE(monotonic);
}

TEST_F(Pymodbus, FahrenheitUnitsRegisterIsHonoured) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.command("poke 1328 30");  // the F4T's units register: 30 = Fahrenheit
  server.command("set process_value 98.6");
  ASSERT_TRUE(d.set_setpoint(-40.0));
  EXPECT_NEAR(server.value("setpoint"), -40.0, 1e-3);  // -40 C is -40 F
  ASSERT_TRUE(d.set_setpoint(100.0));
  EXPECT_NEAR(server.value("setpoint"), 212.0, 1e-3);
  const auto r = d.read();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->device_unit, TemperatureUnit::fahrenheit);
  EXPECT_NEAR(r->process_C, 37.0, 1e-3);
}

TEST_F(Pymodbus, AlarmBitsAreToldApart) {
  const std::string map = float_map("ABCD");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  EXPECT_TRUE(d.check_alarms());
  server.command("poke 120 4");
  auto r = d.read();
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_EQ(r->alarms.size(), 1u);
  EXPECT_EQ(r->alarms[0].name, "door open");
  EXPECT_EQ(r->alarms[0].raw, 4);
  server.command("poke 120 5");
  r = d.read();
  ASSERT_TRUE(r);
  ASSERT_EQ(r->alarms.size(), 2u);
  EXPECT_EQ(r->alarms[0].name, "high limit");
  const auto c = d.check_alarms();
  EXPECT_EQ(c.code(), DriverErrc::alarm);
  EXPECT_NE(c.error().message.find("door open"), std::string::npos) << c.error().message;
  ASSERT_TRUE(d.safe_stop());
  EXPECT_EQ(d.activate().code(), DriverErrc::alarm);
  server.command("poke 120 2");  // a bit no alarm of the map watches
  EXPECT_TRUE(d.activate());
}

TEST_F(Pymodbus, F4tEnumeratedAlarmState) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.command("poke 1356 88");  // another "normal" state of the map
  EXPECT_TRUE(d.check_alarms());
  server.command("poke 1356 7");
  const auto c = d.check_alarms();
  EXPECT_EQ(c.code(), DriverErrc::alarm);
  EXPECT_NE(c.error().message.find("alarm 1 (7)"), std::string::npos) << c.error().message;
}

TEST_F(Pymodbus, ExceptionReplyIsATypedErrorNamingTheRegister) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.command("exception 1356 2");  // illegal data address on the alarm register
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::device_rejected) << r.error().message;
  EXPECT_NE(r.error().message.find("alarm 'alarm 1' (register 1356)"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("Illegal data address"), std::string::npos) << r.error().message;
  server.command("clear-exceptions");
  server.command("exception 2783 4");  // slave device failure on the set point's second word
  const auto w = d.set_setpoint(30.0);
  EXPECT_EQ(w.code(), DriverErrc::device_rejected) << (w ? "accepted" : w.error().message);
  EXPECT_NE(w.error().message.find("writing the set point (register 2782..2783)"), std::string::npos) << w.error().message;
  EXPECT_NE(w.error().message.find("Slave device or server failure"), std::string::npos) << w.error().message;
  // An exception reply is an answer: the link stays up, nothing reconnects.
  server.command("clear-exceptions");
  EXPECT_TRUE(d.set_setpoint(30.0));
  EXPECT_TRUE(d.read());
  EXPECT_EQ(d.reconnects(), 0u);
  EXPECT_EQ(d.state(), DeviceState::active);
}

TEST_F(Pymodbus, ConnectionDroppedMidRequestIsLostThenReconnected) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.command("drop-after 2");  // the third request of the next read() is never answered
  Stopwatch sw;
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::connection_lost) << r.error().message;
  EXPECT_LT(sw.seconds(), 3.0);
  EXPECT_EQ(d.state(), DeviceState::faulted);
  server.command("set process_value 25.5");
  std::optional<ChamberReading> fresh;
  ASSERT_TRUE(eventually([&] {
    auto x = d.read();
    if (x) fresh = *x;
    return x.ok();
  }));
  ASSERT_TRUE(fresh.has_value());
  EXPECT_NEAR(fresh->process_C, 25.5, 1e-4);
  EXPECT_EQ(d.state(), DeviceState::active);
  EXPECT_EQ(d.reconnects(), 1u);
}

TEST_F(Pymodbus, IdleConnectionClosedByTheServerIsLostThenReconnected) {
  const std::string map = builtin_register_map_json("csz-ezt570i");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  EXPECT_EQ(server.command("drop-now").at("dropped").get<int>(), 1);
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::connection_lost) << r.error().message;
  ASSERT_TRUE(eventually([&] { return d.set_setpoint(33.3).ok(); }));
  EXPECT_NEAR(server.value("setpoint"), 33.3, 1e-9);
  EXPECT_EQ(d.reconnects(), 1u);
}

TEST_F(Pymodbus, ServerGoneIsLostThenConnectFailed) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::tcp);
  ModbusChamber d(tcp_config(server, map));
  bring_up(d);
  server.stop();
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::connection_lost) << r.error().message;
  const auto again = d.read();
  EXPECT_EQ(again.code(), DriverErrc::connect_failed) << (again ? "value returned" : again.error().message);
}

// RTU: pymodbus's serial server (ModbusRtuFramer, CRC and all) on a pseudo-terminal the script
// creates; the driver opens its device path with libmodbus's RTU backend.
class PymodbusRtu : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(python_with_pymodbus()) << kInstallHint; }

  static ModbusChamberConfig rtu_config(const PymodbusChamber& server, const std::string& map_json) {
    ModbusChamberConfig c;
    c.transport = ModbusChamberConfig::Transport::rtu;
    c.serial_device = server.rtu_device();
    c.baud = 115200;
    c.map = register_map_from_json(map_json);
    c.response_timeout = 1000ms;
    c.backoff_initial = 50ms;
    c.backoff_max = 400ms;
    return c;
  }
};

TEST_F(PymodbusRtu, SetPointReadingAndAlarmsOverRtu) {
  const std::string map = builtin_register_map_json("watlow-f4t");
  PymodbusChamber server(map, PymodbusChamber::Transport::rtu);
  ModbusChamber d(rtu_config(server, map));
  bring_up(d);
  ASSERT_TRUE(d.set_setpoint(47.11));
  EXPECT_EQ(server.registers("setpoint"), (std::vector<std::uint16_t>{0x70A4, 0x423C}));
  server.command("set process_value -31.5");
  auto r = d.read();
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_NEAR(r->process_C, -31.5, 1e-4);
  EXPECT_NEAR(r->setpoint_C, 47.11, 1e-4);
  EXPECT_TRUE(r->alarms.empty());
  server.command("poke 1356 7");
  EXPECT_EQ(d.check_alarms().code(), DriverErrc::alarm);
  const std::vector<int> fcs = server.function_codes();
  for (int fc : fcs) EXPECT_TRUE(fc == 3 || fc == 6 || fc == 16) << "function code " << fc;
}

TEST_F(PymodbusRtu, ExceptionReplyOverRtuNamesTheRegister) {
  const std::string map = builtin_register_map_json("csz-ezt570i");
  PymodbusChamber server(map, PymodbusChamber::Transport::rtu);
  ModbusChamber d(rtu_config(server, map));
  bring_up(d);
  server.command("exception 61 2");  // the process value
  const auto r = d.read();
  ASSERT_FALSE(r);
  EXPECT_EQ(r.code(), DriverErrc::device_rejected) << r.error().message;
  EXPECT_NE(r.error().message.find("reading the process value (register 61)"), std::string::npos) << r.error().message;
  server.command("clear-exceptions");
  EXPECT_TRUE(d.read());
  EXPECT_EQ(d.reconnects(), 0u);
}

TEST_F(PymodbusRtu, SilentServerTimesOutThenRecovers) {
  const std::string map = builtin_register_map_json("csz-ezt570i");
  PymodbusChamber server(map, PymodbusChamber::Transport::rtu);
  ModbusChamber d(rtu_config(server, map));
  bring_up(d);
  // On a serial line "dropping the connection" is a controller that stops answering.
  server.command("drop-after 0");
  Stopwatch sw;
  const auto r = d.read();
  EXPECT_EQ(r.code(), DriverErrc::timeout) << (r ? "value returned" : r.error().message);
  EXPECT_LT(sw.seconds(), 3.0);
  ASSERT_TRUE(eventually([&] { return d.read().ok(); }));
}
