// The simulated table's servo model (pure), then the ACL table driver against the simulated table
// (an Asio server on loopback): lifecycle, modes, coherent position reads and their clock model,
// limits, interlock, watchdog, and every link fault as a typed error within a bounded time.
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

#include "core/units.hpp"
#include "drivers/table_dialect.hpp"
#include "drivers/tcp_table.hpp"
#include "sim/sim_table.hpp"
#include "sim/table_servo.hpp"
#include "test_helpers.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::drivers;
using namespace std::chrono_literals;
using imucal::drivers::test::eventually;
using imucal::drivers::test::Stopwatch;
using imucal::drivers::test::bind_loopback;

namespace {

constexpr int kOuter = 0, kMiddle = 1, kInner = 2;

sim::ServoConfig servo_config() {
  sim::ServoConfig c;
  c.start_deg = {0.0, 0.0, 0.0};
  for (auto& axis : c.limits)
    for (auto& m : axis) m = AxisLimitSetting{-1e9, 1e9, 200.0, 400.0};
  return c;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Servo model

TEST(TableServo, RateDemandRampsAtTheAccelerationLimit) {
  sim::TableServo s(servo_config());
  ASSERT_TRUE(s.interlock_close(0.0).ok());
  ASSERT_TRUE(s.set_mode(1.0, kOuter, TableMode::rate).ok());
  ASSERT_TRUE(s.demand_rate(1.0, kOuter, 40.0).ok());  // 0.1 s ramp at 400 deg/s^2
  const auto a = s.sample(1.05);
  EXPECT_NEAR(a[0].rate_dps, 20.0, 1e-9);
  EXPECT_NEAR(a[0].angle_deg, 0.5 * 400.0 * 0.05 * 0.05, 1e-9);
  const auto b = s.sample(3.0);
  EXPECT_NEAR(b[0].rate_dps, 40.0, 1e-9);
  EXPECT_NEAR(b[0].angle_deg, 0.5 * 40.0 * 0.1 + 40.0 * 1.9, 1e-9);
}

TEST(TableServo, PositionMoveIsARestToRestTrapezoid) {
  sim::TableServo s(servo_config());
  s.interlock_close(0.0);
  s.set_mode(0.0, kMiddle, TableMode::position);
  ASSERT_TRUE(s.demand_position(0.0, kMiddle, 90.0).ok());
  // 200 deg/s, 400 deg/s^2: 0.5 s up (50 deg), 0 s cruise ... 90 deg < 100: triangular, ta = sqrt(90/400)
  const double ta = std::sqrt(90.0 / 400.0);
  EXPECT_NEAR(s.sample(ta)[1].angle_deg, 45.0, 1e-9);
  EXPECT_NEAR(s.sample(ta)[1].rate_dps, 400.0 * ta, 1e-9);
  EXPECT_NEAR(s.sample(2 * ta + 0.01)[1].angle_deg, 90.0, 1e-12);
  EXPECT_EQ(s.sample(2 * ta + 0.01)[1].rate_dps, 0.0);
  EXPECT_EQ(s.demand_position(5.0, kMiddle, 1e10).refusal, dialect::Refusal::limit_exceeded);
}

TEST(TableServo, RateModeRunsIntoItsPositionLimitAndLatches) {
  sim::TableServo s(servo_config());
  s.interlock_close(0.0);
  ASSERT_TRUE(s.set_limit_position(0.0, kInner, TableMode::rate, -10.0, 10.0).ok());
  s.set_mode(0.0, kInner, TableMode::rate);
  ASSERT_TRUE(s.demand_rate(0.0, kInner, 20.0).ok());
  s.advance(2.0);
  const TableStatus st = s.status(2.0);
  EXPECT_TRUE(st.axes[2].at_limit);
  EXPECT_EQ(st.axes[2].mode, TableMode::off);
  const double a = s.sample(2.0)[2].angle_deg;
  EXPECT_GT(a, 10.0);  // braked beyond the limit (limit switch before the hard stop)
  EXPECT_LT(a, 10.0 + 20.0 * 20.0 / (2 * 400.0) + 1e-9);
  EXPECT_EQ(s.sample(2.0)[2].rate_dps, 0.0);
  EXPECT_EQ(s.set_mode(2.0, kInner, TableMode::rate).refusal, dialect::Refusal::axis_fault);
  ASSERT_TRUE(s.interlock_reset(2.0).ok());
  ASSERT_TRUE(s.set_mode(2.0, kInner, TableMode::position).ok());
  ASSERT_TRUE(s.set_limit_position(2.0, kInner, TableMode::position, -10.0, 10.0).ok());
  EXPECT_TRUE(s.demand_position(2.0, kInner, 0.0).ok());
}

TEST(TableServo, OscillationStartsAndStopsAtTurningPointsInPhaseWithWorldTime) {
  sim::TableServo s(servo_config());
  s.interlock_close(0.0);
  s.set_mode(0.0, kOuter, TableMode::synthesis);
  ASSERT_TRUE(s.demand_oscillation(0.0, kOuter, {2.0, 1.0, 30.0}).ok());
  // From t = 2 s on it oscillates as 2 sin(2 pi t + 30 deg) about 0.
  for (double t = 2.0; t < 4.0; t += 0.0371) {
    const double psi = 2 * units::kPi * t + 30.0 * units::kDegToRad;
    EXPECT_NEAR(s.sample(t)[0].angle_deg, 2.0 * std::sin(psi), 1e-9) << t;
    EXPECT_NEAR(s.sample(t)[0].rate_dps, 2.0 * 2 * units::kPi * std::cos(psi), 1e-7) << t;
  }
  // Repeating the demand (keep-alive) changes nothing.
  const auto v = s.version();
  ASSERT_TRUE(s.demand_oscillation(4.0, kOuter, {2.0, 1.0, 30.0}).ok());
  EXPECT_EQ(s.version(), v);
  ASSERT_TRUE(s.set_mode(4.0, kOuter, TableMode::off).ok());
  // Stopped at the next turning point: at rest at +-2 deg, never a rate jump.
  const auto end = s.sample(6.0)[0];
  EXPECT_NEAR(std::fabs(end.angle_deg), 2.0, 1e-9);
  EXPECT_EQ(end.rate_dps, 0.0);
  EXPECT_EQ(s.demand_oscillation(6.0, kOuter, {1.0, 1.0, 0.0}).refusal, dialect::Refusal::wrong_mode);
}

TEST(TableServo, OscillationBeyondTheLimitsIsRefused) {
  sim::TableServo s(servo_config());
  s.interlock_close(0.0);
  s.set_mode(0.0, kOuter, TableMode::synthesis);
  EXPECT_EQ(s.demand_oscillation(0.0, kOuter, {10.0, 10.0, 0.0}).refusal, dialect::Refusal::limit_exceeded);  // rate 628 deg/s
  EXPECT_EQ(s.demand_oscillation(0.0, kOuter, {1.0, -1.0, 0.0}).refusal, dialect::Refusal::argument);
}

TEST(TableServo, InterlockAndWatchdog) {
  sim::TableServo s(servo_config());
  EXPECT_EQ(s.set_mode(0.0, kOuter, TableMode::rate).refusal, dialect::Refusal::interlock_open);
  s.interlock_close(0.0);
  ASSERT_TRUE(s.set_watchdog(0.0, 0.5).ok());
  s.set_mode(0.0, kOuter, TableMode::rate);
  s.demand_rate(0.0, kOuter, 10.0);
  s.demand_rate(0.4, kOuter, 10.0);  // fed
  s.advance(0.8);
  EXPECT_EQ(s.status(0.8).axes[0].mode, TableMode::rate);
  s.advance(1.0);
  EXPECT_EQ(s.status(1.0).axes[0].mode, TableMode::off);
  EXPECT_TRUE(s.status(1.0).axes[0].watchdog_expired);
  EXPECT_EQ(s.demand_rate(1.0, kOuter, 10.0).refusal, dialect::Refusal::watchdog_expired);
  // Interlock open brakes everything.
  s.set_mode(1.0, kMiddle, TableMode::rate);
  s.set_watchdog(1.0, 0.0);
  s.demand_rate(1.0, kMiddle, 100.0);
  s.interlock_open(2.0);
  EXPECT_EQ(s.status(2.0).interlock, InterlockState::open);
  EXPECT_EQ(s.sample(3.0)[1].rate_dps, 0.0);
  EXPECT_EQ(s.demand_rate(3.0, kMiddle, 1.0).refusal, dialect::Refusal::interlock_open);
}

TEST(TableServo, ProgramFromMatchesTheServoMotion) {
  // The physics reads the motion through motion::Program; it must be the motion the table
  // reports, whatever the piece boundaries of the three axes.
  sim::TableServo s(servo_config());
  s.interlock_close(0.0);
  s.set_mode(0.0, kOuter, TableMode::rate);
  s.demand_rate(0.1, kOuter, 30.0);
  s.set_mode(0.2, kMiddle, TableMode::position);
  s.demand_position(0.3, kMiddle, 54.7356);
  s.set_mode(0.35, kInner, TableMode::synthesis);
  s.demand_oscillation(0.4, kInner, {3.0, 2.0, 45.0});
  s.demand_rate(1.7, kOuter, -20.0);
  const double t_from = 0.25;
  const motion::Program p = s.program_from(t_from);
  std::size_t cursor = 0;
  // (Program time 0 itself is "before the start", at rest, by the Program convention.)
  for (double t = t_from + 1e-6; t < 6.0; t += 0.00731) {
    const auto st = p.evaluate(t - t_from, cursor);
    const auto smp = s.sample(t);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(st.angle_rad[k] * units::kRadToDeg, smp[static_cast<std::size_t>(k)].angle_deg, 1e-8) << t << " axis " << k;
      EXPECT_NEAR(st.rate_radps[k] * units::kRadToDeg, smp[static_cast<std::size_t>(k)].rate_dps, 1e-6) << t << " axis " << k;
    }
  }
}

// ------------------------------------------------------------------------------------------------
// Driver against the simulated table

namespace {

struct Rig {
  sim::SimWorld world{servo_config()};
  sim::SimTable table;
  TcpTable driver;
  explicit Rig(sim::SimTableConfig tc = {}, std::function<void(TcpTableConfig&)> tweak = {})
      : table(world, tc), driver(make_config(table, tweak)) {}
  static TcpTableConfig make_config(const sim::SimTable& t, const std::function<void(TcpTableConfig&)>& tweak) {
    TcpTableConfig c;
    c.port = t.port();
    c.response_timeout = 500ms;
    c.backoff_initial = 50ms;
    c.backoff_max = 400ms;
    c.safe_stop_timeout = 10s;
    if (tweak) tweak(c);
    return c;
  }
  void up() {
    ASSERT_TRUE(driver.connect()) << driver.describe();
    ASSERT_TRUE(driver.configure());
    ASSERT_TRUE(driver.activate());
  }
};

// A client on the table's port that types lines itself, as a person with a terminal would.
class RawClient {
 public:
  explicit RawClient(int port) : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  ~RawClient() { ::close(fd_); }
  RawClient(const RawClient&) = delete;
  RawClient& operator=(const RawClient&) = delete;
  bool connected() const { return connected_; }
  // Sends `line` as it is and returns the reply up to its '\n' (a '\r' before it kept).
  std::string ask(const std::string& line) {
    (void)::send(fd_, line.data(), line.size(), MSG_NOSIGNAL);
    std::string reply;
    char ch;
    while (::recv(fd_, &ch, 1, 0) == 1 && ch != '\n') reply += ch;
    return reply;
  }

 private:
  int fd_;
  bool connected_ = false;
};

}  // namespace

TEST(TcpTable, LifecycleConfiguresLimitsAndClosesTheInterlock) {
  Rig rig({}, [](TcpTableConfig& c) { c.limits[1][static_cast<int>(TableMode::position)] = AxisLimitSetting{-95.0, 95.0, 50.0, 100.0}; });
  rig.up();
  EXPECT_EQ(rig.driver.state(), DeviceState::active);
  const auto st = rig.driver.read_status();
  ASSERT_TRUE(st) << st.error().message;
  EXPECT_EQ(st->interlock, InterlockState::closed);
  ASSERT_TRUE(rig.driver.set_mode(kMiddle, TableMode::position));
  EXPECT_EQ(rig.driver.demand_position(kMiddle, 100.0).code(), DriverErrc::limit_exceeded);
  ASSERT_TRUE(rig.driver.safe_stop());
  EXPECT_EQ(rig.driver.read_status()->interlock, InterlockState::open);
  EXPECT_EQ(rig.driver.state(), DeviceState::configured);
  rig.driver.disconnect();
  EXPECT_EQ(rig.driver.state(), DeviceState::disconnected);
  EXPECT_EQ(rig.driver.read_positions().code(), DriverErrc::invalid_state);
}

TEST(TcpTable, RateModeAndTimeCoherentPositionReads) {
  sim::SimTableConfig tc;
  tc.clock_drift_ppm = 80.0;
  tc.clock_offset_us = 123'456'789'000;
  Rig rig(tc);
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 30.0));
  std::this_thread::sleep_for(200ms);  // past the 75 ms ramp
  std::vector<TablePositions> reads;
  Stopwatch sw;
  while (sw.seconds() < 1.5) {
    auto p = rig.driver.read_positions();
    ASSERT_TRUE(p) << p.error().message;
    reads.push_back(*p);
    std::this_thread::sleep_for(2ms);
  }
  ASSERT_GT(reads.size(), 50u);
  double worst_us = 0.0;
  for (std::size_t i = 1; i < reads.size(); ++i) {
    EXPECT_GT(reads[i].t_ns, reads[i - 1].t_ns);
    EXPECT_NEAR(reads[i].rate_dps[0], 30.0, 1e-9);
    // Where the table really was at the mapped time (world clock is the truth here).
    const double true_world_s = (static_cast<double>(reads[i].device_time_us - tc.clock_offset_us) / (1.0 + 80e-6)) * 1e-6;
    const double err_us = static_cast<double>(reads[i].t_ns - rig.world.host_ns(true_world_s)) / 1e3;
    if (i > reads.size() / 2) worst_us = std::max(worst_us, std::fabs(err_us));
  }
  // Loopback round trips are tens of microseconds; allow a loaded machine its hiccups.
  EXPECT_LT(worst_us, 2000.0);
  RecordProperty("table_time_error_us", std::to_string(worst_us));
  const auto cm = rig.driver.clock_model();
  EXPECT_TRUE(cm.valid);
}

TEST(TcpTable, PositionAndOscillationDemandsMoveTheTable) {
  Rig rig;
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kMiddle, TableMode::position));
  ASSERT_TRUE(rig.driver.demand_position(kMiddle, 30.0));
  ASSERT_TRUE(eventually([&] {
    auto p = rig.driver.read_positions();
    return p && std::fabs(p->angle_deg[1] - 30.0) < 1e-9 && p->rate_dps[1] == 0.0;
  }));
  ASSERT_TRUE(rig.driver.set_mode(kInner, TableMode::synthesis));
  ASSERT_TRUE(rig.driver.demand_oscillation(kInner, {1.5, 2.0, 0.0}));
  double lo = 0.0, hi = 0.0;
  Stopwatch sw;
  while (sw.seconds() < 2.5) {
    auto p = rig.driver.read_positions();
    ASSERT_TRUE(p);
    lo = std::min(lo, p->angle_deg[2]);
    hi = std::max(hi, p->angle_deg[2]);
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_GT(hi, 1.4);
  EXPECT_LT(lo, -1.4);
  EXPECT_LE(hi, 1.5 + 1e-9);
  EXPECT_GE(lo, -1.5 - 1e-9);
}

TEST(TcpTable, InterlockOpenRefusesMotion) {
  Rig rig;
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 50.0));
  rig.table.trip_interlock();  // emergency stop on the panel
  const auto r = rig.driver.demand_rate(kOuter, 50.0);
  EXPECT_EQ(r.code(), DriverErrc::interlock_open) << (r ? "" : r.error().message);
  const auto st = rig.driver.read_status();
  ASSERT_TRUE(st);
  EXPECT_EQ(st->interlock, InterlockState::open);
  EXPECT_EQ(st->axes[0].mode, TableMode::off);
  ASSERT_TRUE(eventually([&] {
    auto p = rig.driver.read_positions();
    return p && p->rate_dps[0] == 0.0;
  }));
  EXPECT_EQ(rig.driver.set_mode(kOuter, TableMode::rate).code(), DriverErrc::interlock_open);
  ASSERT_TRUE(rig.driver.interlock_close());
  EXPECT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
}

TEST(TcpTable, AxisLimitHitIsATypedFaultUntilReset) {
  Rig rig;
  rig.up();
  ASSERT_TRUE(rig.driver.set_limits(kInner, TableMode::rate, {-5.0, 5.0, 100.0, 400.0}));
  ASSERT_TRUE(rig.driver.set_mode(kInner, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kInner, 25.0));
  Stopwatch sw;
  ASSERT_TRUE(eventually([&] {
    auto st = rig.driver.read_status();
    return st && st->axes[2].at_limit;
  }));
  EXPECT_LT(sw.seconds(), 5.0);  // 0.2 s of motion; the rest is the machine's load
  const auto st = rig.driver.read_status();
  EXPECT_TRUE(st->axes[2].fault);
  EXPECT_EQ(st->axes[2].mode, TableMode::off);
  EXPECT_EQ(rig.driver.set_mode(kInner, TableMode::rate).code(), DriverErrc::axis_fault);
  ASSERT_TRUE(rig.driver.interlock_reset());
  ASSERT_TRUE(rig.driver.set_mode(kInner, TableMode::position));
  ASSERT_TRUE(rig.driver.demand_position(kInner, 0.0));
  EXPECT_EQ(rig.driver.demand_rate(kInner, 1.0).code(), DriverErrc::invalid_state);  // wrong mode
}

TEST(TcpTable, WatchdogDropsAnUnfedAxisAndFeedingKeepsItAlive) {
  Rig rig({}, [](TcpTableConfig& c) { c.watchdog_s = 1.0; });
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 5.0));
  // Fed every 50 ms for a second: still in rate mode.
  Stopwatch sw;
  while (sw.seconds() < 1.0) {
    ASSERT_TRUE(rig.driver.demand_rate(kOuter, 5.0));
    std::this_thread::sleep_for(50ms);
  }
  EXPECT_EQ(rig.driver.read_status()->axes[0].mode, TableMode::rate);
  // Demands stop: the axis is dropped to off.
  ASSERT_TRUE(eventually([&] {
    auto st = rig.driver.read_status();
    return st && st->axes[0].watchdog_expired && st->axes[0].mode == TableMode::off;
  }));
  EXPECT_EQ(rig.driver.demand_rate(kOuter, 5.0).code(), DriverErrc::watchdog_expired);
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));  // re-arms
  EXPECT_TRUE(rig.driver.demand_rate(kOuter, 5.0));
}

TEST(TcpTable, BadCommandsGetErrorRepliesAndBadArgumentsNeverLeave) {
  Rig rig;
  rig.up();
  EXPECT_EQ(rig.driver.demand_rate(3, 1.0).code(), DriverErrc::invalid_argument);
  EXPECT_EQ(rig.driver.demand_position(0, std::nan("")).code(), DriverErrc::invalid_argument);
  EXPECT_EQ(rig.driver.set_limits(0, TableMode::rate, {5.0, -5.0, 1.0, 1.0}).code(), DriverErrc::invalid_argument);
  // A raw client: unknown command, bad arguments, an over-long line.
  RawClient client(rig.table.port());
  ASSERT_TRUE(client.connected());
  auto ask = [&](const std::string& line) { return client.ask(line); };
  EXPECT_EQ(ask(":FOO:BAR 1\n").rfind("ERR 100,", 0), 0u);
  EXPECT_EQ(ask(":DEM:RATE 7,1\n").rfind("ERR 101,", 0), 0u);
  EXPECT_EQ(ask(":READ:POS?\r\n").rfind("POS ", 0), 0u);
  EXPECT_EQ(ask(std::string(2000, 'A') + "\n").rfind("ERR 100,", 0), 0u);
}

TEST(TcpTable, DroppedConnectionIsReportedThenReconnected) {
  Rig rig;
  rig.up();
  rig.table.drop_connections();
  Stopwatch sw;
  const auto r = rig.driver.read_positions();
  ASSERT_FALSE(r);
  EXPECT_TRUE(r.code() == DriverErrc::connection_lost || r.code() == DriverErrc::timeout) << r.error().message;
  EXPECT_LT(sw.seconds(), 3.0);
  EXPECT_EQ(rig.driver.state(), DeviceState::faulted);
  ASSERT_TRUE(eventually([&] { return rig.driver.read_positions().ok(); }));
  EXPECT_EQ(rig.driver.reconnects(), 1u);
  EXPECT_EQ(rig.driver.state(), DeviceState::active);
  // The reconnection restored the session's checksum mode: corrupted replies are still caught.
  rig.table.corrupt_next_replies(1);
  EXPECT_EQ(rig.driver.read_positions().code(), DriverErrc::crc_error);
}

TEST(TcpTable, LateReplyIsATimeoutAndNeverAStaleValue) {
  Rig rig({}, [](TcpTableConfig& c) { c.response_timeout = 300ms; });
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 20.0));
  rig.table.set_reply_delay(900ms);
  Stopwatch sw;
  const auto r = rig.driver.read_positions();
  EXPECT_EQ(r.code(), DriverErrc::timeout);
  EXPECT_LT(sw.seconds(), 2.0);
  const std::int64_t after_timeout = host_time_ns();
  rig.table.set_reply_delay(0ms);
  auto p = rig.driver.read_positions();
  ASSERT_TRUE(eventually([&] { return (p = rig.driver.read_positions()).ok(); }));
  // The late reply (sampled before the timeout) was never delivered: this one is newer.
  EXPECT_GT(p->t_ns, after_timeout - 1'000'000);
}

TEST(TcpTable, CorruptedReplyIsCaughtByTheChecksum) {
  Rig rig;
  rig.up();
  for (int i = 0; i < 5; ++i) {
    rig.table.corrupt_next_replies(1);
    const auto r = rig.driver.read_positions();
    EXPECT_EQ(r.code(), DriverErrc::crc_error) << (r ? "a corrupted value was returned" : r.error().message);
    ASSERT_TRUE(eventually([&] { return rig.driver.read_positions().ok(); }));
  }
}

TEST(TcpTable, SilentTableTimesOut) {
  Rig rig({}, [](TcpTableConfig& c) { c.response_timeout = 300ms; });
  rig.up();
  rig.table.set_silent(true);
  Stopwatch sw;
  EXPECT_EQ(rig.driver.read_status().code(), DriverErrc::timeout);
  EXPECT_LT(sw.seconds(), 2.0);
  rig.table.set_silent(false);
  ASSERT_TRUE(eventually([&] { return rig.driver.read_status().ok(); }));
}

TEST(TcpTable, SafeStopBringsEveryAxisToRestThenOpensTheInterlock) {
  Rig rig;
  rig.up();
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 100.0));
  ASSERT_TRUE(rig.driver.set_mode(kInner, TableMode::synthesis));
  ASSERT_TRUE(rig.driver.demand_oscillation(kInner, {1.0, 1.0, 0.0}));
  std::this_thread::sleep_for(300ms);
  ASSERT_TRUE(rig.driver.safe_stop());
  const auto p = rig.driver.read_positions();
  ASSERT_TRUE(p);
  for (double w : p->rate_dps) EXPECT_EQ(w, 0.0);
  EXPECT_EQ(rig.driver.read_status()->interlock, InterlockState::open);
}

TEST(TcpTable, UnreachableTableFailsWithinTheConnectTimeout) {
  TcpTableConfig c;
  c.port = 1;  // nothing listens on port 1 of the loopback
  TcpTable d(c);
  Stopwatch sw;
  const auto r = d.connect();
  EXPECT_EQ(r.code(), DriverErrc::connect_failed);
  EXPECT_NE(r.error().message.find("127.0.0.1:1"), std::string::npos);
  EXPECT_LT(sw.seconds(), 2.0);
}

TEST(TcpTable, ConfigurationFromJson) {
  const auto c = tcp_table_config_from_json(
      R"({"host":"10.0.0.5","port":5001,"watchdog_s":0.5,"reply_checksum":false,
          "limits":[{"axis":"middle","mode":"rate","min_deg":-90,"max_deg":90,"rate_dps":50,"accel_dps2":20}]})");
  EXPECT_EQ(c.host, "10.0.0.5");
  EXPECT_EQ(c.port, 5001);
  EXPECT_FALSE(c.reply_checksum);
  const auto& middle_limits = c.limits[1][2];
  ASSERT_TRUE(middle_limits);
  EXPECT_DOUBLE_EQ(middle_limits->max_deg, 90.0);
  auto message = [](const char* text) {
    try {
      (void)tcp_table_config_from_json(text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message(R"({"limits":[{"axis":"top","mode":"rate"}]})"),
            "table config: limits[0].axis must be outer, middle or inner, not \"top\"");
  EXPECT_EQ(message(R"({"limits":[{"axis":"outer","mode":"rate","rate":5}]})"),
            "table config: limits[0]: unknown key \"rate\"");
  // A misspelt key is refused, not defaulted (a "watchdog" would have left the watchdog off).
  EXPECT_EQ(message(R"({"watchdog": 1})"), "table config: unknown key \"watchdog\"");
  EXPECT_EQ(message(R"({"port": 0})"), "table config: port is 0, must be between 1 and 65535");
  EXPECT_EQ(message(R"({"format": "imucal-table/2"})"), "table config: format must be \"imucal-table/1\"");
}

// A second controller family is a file: the driver and the simulated table both given a dialect
// only the tests define (tests/data/table-dialect-test-rtc.json: other tokens, time tags in
// seconds, error codes that are not numbers, no reply checksum).
namespace {
const std::string kTestDialectPath = imucaltest::test_data_dir() + "/table-dialect-test-rtc.json";

Rig rtc_rig(std::function<void(TcpTableConfig&)> tweak = {}) {
  sim::SimTableConfig tc;
  tc.dialect = dialect::load_dialect(kTestDialectPath);
  tc.clock_offset_us = 7'000'000;
  return Rig(tc, [tweak](TcpTableConfig& c) {
    c.dialect = dialect::load_dialect(kTestDialectPath);
    if (tweak) tweak(c);
  });
}
}  // namespace

TEST(TcpTable, ATableSpeakingADialectOnlyTheTestDefinesRunsEveryCommand) {
  Rig rig = rtc_rig([](TcpTableConfig& c) {
    c.limits[1][static_cast<int>(TableMode::position)] = AxisLimitSetting{-95.0, 95.0, 50.0, 100.0};
    c.watchdog_s = 30.0;
  });
  EXPECT_NE(rig.driver.describe().find("test-rtc://127.0.0.1:"), std::string::npos) << rig.driver.describe();
  rig.up();
  const auto st = rig.driver.read_status();
  ASSERT_TRUE(st) << st.error().message;
  EXPECT_EQ(st->interlock, InterlockState::closed);
  // Errors arrive as the dialect's codes and leave the driver typed.
  EXPECT_EQ(rig.driver.demand_rate(kOuter, 5.0).code(), DriverErrc::invalid_state);  // the axis is off
  ASSERT_TRUE(rig.driver.set_mode(kMiddle, TableMode::position));
  const auto far = rig.driver.demand_position(kMiddle, 100.0);
  EXPECT_EQ(far.code(), DriverErrc::limit_exceeded);
  EXPECT_NE(far.error().message.find("'B GOTO 100.000000' refused: E11"), std::string::npos) << far.error().message;
  ASSERT_TRUE(rig.driver.demand_position(kMiddle, 10.0));
  ASSERT_TRUE(rig.driver.set_mode(kOuter, TableMode::rate));
  ASSERT_TRUE(rig.driver.demand_rate(kOuter, 30.0));
  ASSERT_TRUE(rig.driver.set_mode(kInner, TableMode::synthesis));
  ASSERT_TRUE(rig.driver.demand_oscillation(kInner, {2.0, 0.5, 0.0}));
  // Positions in the dialect's fixed decimals, time tags in seconds mapped onto the host clock.
  ASSERT_TRUE(eventually([&] {
    auto p = rig.driver.read_positions();
    return p && std::fabs(p->rate_dps[0] - 30.0) < 1e-6 && std::fabs(p->angle_deg[1] - 10.0) < 1e-6;
  }));
  const auto p = rig.driver.read_positions();
  ASSERT_TRUE(p);
  const auto truth = rig.world.with_servo([](sim::TableServo& s, double t) { return s.sample(t); });
  EXPECT_NEAR(p->angle_deg[1], truth[1].angle_deg, 1e-6);
  EXPECT_GE(p->device_time_us, 7'000'000);
  ASSERT_TRUE(rig.driver.interlock_open());
  EXPECT_EQ(rig.driver.demand_rate(kOuter, 10.0).code(), DriverErrc::interlock_open);
  ASSERT_TRUE(rig.driver.interlock_reset());
  ASSERT_TRUE(rig.driver.interlock_close());
  ASSERT_TRUE(rig.driver.safe_stop());
  EXPECT_EQ(rig.driver.read_status()->interlock, InterlockState::open);
  // The wire is the dialect's: a raw client sees its line end and its replies.
  RawClient client(rig.table.port());
  ASSERT_TRUE(client.connected());
  auto ask = [&](const std::string& line) { return client.ask(line); };
  EXPECT_EQ(ask("WHO\r\n"), "IMUCAL,SIM-TABLE,0,1.0\r");
  EXPECT_EQ(ask("STATE\r\n").rfind("#", 0), 0u);
  EXPECT_EQ(ask(":READ:POS?\r\n").rfind("!E1 ", 0), 0u);  // the other dialect is unknown here
  EXPECT_EQ(ask("D GOTO 1\r\n").rfind("!E2 ", 0), 0u);
}

TEST(TcpTable, ADialectIsConfiguredByNameOrFile) {
  const auto c = tcp_table_config_from_json(R"({"port": 5001, "dialect": ")" + kTestDialectPath + R"("})");
  EXPECT_EQ(c.dialect.name, "test-rtc");
  EXPECT_FALSE(c.reply_checksum);  // the dialect has none
  EXPECT_TRUE(tcp_table_config_from_json(R"({"dialect": "imucal-acl"})").reply_checksum);
  auto message = [](const std::string& json_text) {
    try {
      (void)tcp_table_config_from_json(json_text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message(R"({"dialect": ")" + kTestDialectPath + R"(", "reply_checksum": true})")
                .find("reply_checksum is true but dialect 'test-rtc' has no reply checksum"),
            std::string::npos);
  EXPECT_NE(message(R"({"dialect": "acutrol-3000"})").find("table dialect 'acutrol-3000': no such built-in one (imucal-acl) or file"),
            std::string::npos)
      << message(R"({"dialect": "acutrol-3000"})");
}

// Fuzz at the wire: a table that answers the connection handshake properly and every position
// request with a damaged reply (one byte changed, a truncated line, random printable garbage or
// random bytes). With reply checksums on, the driver must never return a position.
TEST(TcpTableFuzz, DamagedRepliesNeverYieldAPosition) {
  int port = 0;
  const int ls = bind_loopback(port);
  std::atomic<bool> stop{false};
  std::thread server([&] {
    std::mt19937_64 rng(77);
    std::vector<int> clients;
    std::vector<std::string> pending;
    while (!stop) {
      std::vector<pollfd> fds{{ls, POLLIN, 0}};
      for (int c : clients) fds.push_back({c, POLLIN, 0});
      if (::poll(fds.data(), fds.size(), 20) <= 0) continue;
      if (fds[0].revents & POLLIN) {
        clients.push_back(::accept(ls, nullptr, nullptr));
        pending.emplace_back();
      }
      for (std::size_t i = 1; i < fds.size(); ++i) {
        if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        char buf[512];
        const ssize_t n = ::recv(fds[i].fd, buf, sizeof buf, 0);
        const std::size_t idx = i - 1;
        if (n <= 0) {
          ::close(fds[i].fd);
          clients[idx] = -1;
          continue;
        }
        pending[idx].append(buf, static_cast<std::size_t>(n));
        std::size_t nl;
        while ((nl = pending[idx].find('\n')) != std::string::npos) {
          const std::string line = pending[idx].substr(0, nl);
          pending[idx].erase(0, nl + 1);
          std::string reply;
          if (line == "*IDN?") reply = dialect::frame_line(dialect::imucal_acl(), "IDN FUZZ", false);
          else if (line.rfind(":SYST:CHEC", 0) == 0) reply = dialect::frame_line(dialect::imucal_acl(), "OK", true);
          else {
            std::string good = dialect::frame_line(dialect::imucal_acl(), "POS 123456,1.5,2.5,3.5,0,0,0", true);
            switch (rng() % 4) {
              case 0: {  // one byte changed, the terminator kept
                const std::size_t at = rng() % (good.size() - 1);
                char c = static_cast<char>(good[at] ^ static_cast<char>(1 + rng() % 127));
                if (c == '\n') c = 'x';
                good[at] = c;
                reply = good;
                break;
              }
              case 1: reply = good.substr(0, rng() % (good.size() - 1)) + "\n"; break;
              case 2: {
                reply.resize(rng() % 60);
                for (char& c : reply) c = static_cast<char>(0x20 + rng() % 95);
                reply += '\n';
                break;
              }
              default: {
                reply.resize(1 + rng() % 60);
                for (char& c : reply) c = static_cast<char>(rng() % 256);
                if (rng() % 2) reply += '\n';
                break;
              }
            }
          }
          (void)::send(fds[i].fd, reply.data(), reply.size(), MSG_NOSIGNAL);
        }
      }
      for (std::size_t i = 0; i < clients.size();) {
        if (clients[i] < 0) {
          clients.erase(clients.begin() + static_cast<std::ptrdiff_t>(i));
          pending.erase(pending.begin() + static_cast<std::ptrdiff_t>(i));
        } else {
          ++i;
        }
      }
    }
    for (int c : clients) ::close(c);
  });
  TcpTableConfig c;
  c.port = port;
  c.response_timeout = 100ms;
  c.backoff_initial = 1ms;
  c.backoff_max = 1ms;
  TcpTable d(c);
  ASSERT_TRUE(d.connect());
  int values = 0;
  Stopwatch total;
  for (int i = 0; i < 400 && total.seconds() < 3.0; ++i) {
    Stopwatch sw;
    const auto r = d.read_positions();
    if (r) ++values;
    EXPECT_LT(sw.seconds(), 2.0);
  }
  EXPECT_EQ(values, 0);
  stop = true;
  server.join();
  ::close(ls);
}
