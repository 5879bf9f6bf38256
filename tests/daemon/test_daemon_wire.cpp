// `--devices sim-wire`: a short campaign through the daemon's sequencer and the real drivers,
// against the simulated table (ACL over TCP), chamber (Modbus TCP) and IMU (CAN FD frames over a
// socket pair) running in-process on loopback, in real time (about 30 s with a pause). It must
// run to completion with every frame on the program's grid recorded once, none lost, and frames
// that show the motion the table made.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

// About 20 s of program: holds, a move, a constant-acceleration rate segment and a sine, so that
// every way the bench follows a program is used.
json wire_campaign() {
  const json program = json::parse(R"({"name": "wire-short", "segments": [
    {"type": "hold", "name": "start", "duration_s": 3},
    {"type": "move", "name": "tilt", "to_deg": [0, 90, 0], "duration_s": 3},
    {"type": "hold", "name": "x-level", "duration_s": 2},
    {"type": "rate", "name": "spin", "axis": "outer", "rate_dps": 30, "duration_s": 6, "accel_dps2": 30},
    {"type": "sine", "name": "swing", "axis": "inner", "amplitude_deg": 10, "period_s": 4, "cycles": 1,
     "phase_deg": 90},
    {"type": "hold", "name": "end", "duration_s": 2}]})");
  return {{"name", "wire"}, {"program", program}, {"rate_hz", 100}, {"seed", 3},
          {"truth", noisy_truth()}, {"estimators", {"navigation"}}};
}

}  // namespace

TEST(SimWire, ACampaignThroughTheRealDriversRecordsEveryFrame) {
  LocalDaemon d("wire", false, [](daemon::DaemonConfig& c) { c.devices = "sim-wire"; });
  const auto id = d.post_campaign(wire_campaign());
  ASSERT_EQ(d.command(id, "start"), 200);
  // A pause in the rate segment: the table stops through the driver, and on resume it is moved
  // back to the segment's start pose and the segment is redone; frames continue the grid.
  d.wait_for(id, [](const json& x) { return x.at("program_time_s").get<double>() > 10.0; }, 60.0);
  ASSERT_EQ(d.command(id, "pause"), 200);
  d.wait_state(id, "paused", 30.0);
  ASSERT_EQ(d.command(id, "resume"), 200);
  const json c = d.wait_final(id, 180.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "resumed", "redoing segment 3 'spin'"));
  EXPECT_EQ(c.at("bad_frames"), 0);
  // Real time: a machine overloaded by other jobs (sanitizers, parallel tests) can stall the IMU
  // link long enough to suspend the run, which then redoes the segment. The file below must be
  // complete either way; the delivery counters are exact only without a suspension.
  if (!has_event(c, "suspended")) {
    EXPECT_EQ(c.at("lost_frames"), 0);
  } else {
    std::printf("note: the run was suspended on the way (machine load?): %s\n", c.at("events").dump().c_str());
  }
  EXPECT_TRUE(has_event(c, "info", "real drivers"));

  const std::string path = d.run_path(c);
  const auto frames = run_frames(path);
  const double duration_s = c.at("duration_s").get<double>();
  const std::int64_t dt_ns = 10'000'000;
  ASSERT_GE(static_cast<double>(frames.size()), duration_s * 100.0 - 1.0);
  EXPECT_EQ(c.at("frames"), static_cast<std::int64_t>(frames.size()));
  // Every instant of the program's grid once, from the first sample period on: nothing lost.
  EXPECT_EQ(frames.front().t_ns, dt_ns);
  std::size_t off_grid = 0;
  for (std::size_t i = 1; i < frames.size(); ++i) off_grid += frames[i].t_ns - frames[i - 1].t_ns != dt_ns;
  EXPECT_EQ(off_grid, 0u);
  const auto db = storage::RunDb::open(path, storage::OpenMode::Read);
  EXPECT_TRUE(db.dropped_spans().empty());
  EXPECT_FALSE(db.temps().empty());

  // The frames show what the table did: middle axis at 90 deg on the level hold (angles from the
  // table driver's reads), and the IMU sensing the 30 deg/s of the spin's constant-rate part.
  double rate_sum_dps = 0.0;
  int rate_n = 0;
  for (const ImuFrame& f : frames) {
    const double t_s = static_cast<double>(f.t_ns) * 1e-9;
    if (t_s > 6.5 && t_s < 7.5) {
      EXPECT_NEAR(f.table_deg.y(), 90.0, 1e-3) << t_s;
    }
    if (t_s > 10.0 && t_s < 12.0) {
      rate_sum_dps += f.dtheta_rad.norm() / 0.01 * 180.0 / M_PI;
      ++rate_n;
    }
  }
  ASSERT_GT(rate_n, 100);
  EXPECT_NEAR(rate_sum_dps / rate_n, 30.0, 0.5);
  // Every exit parks the table through the driver: interlock open, rate zero.
  const json t = d.service->sequencer().telemetry();
  EXPECT_FALSE(t.at("table").at("interlock_closed").get<bool>());
}

// sim_faults on sim-wire are injected on the simulated devices: a chamber_offset makes the
// simulated chamber controller serve a process value 6 C off, which the daemon reads over Modbus
// like any other. The run must suspend on it, resume once the reading is back in band and settled,
// redo the segment and still record every grid frame once.
TEST(SimWire, AChamberOutOfBandOverTheWireSuspendsAndTheRunResumes) {
  LocalDaemon d("wire-faults", false, [](daemon::DaemonConfig& c) { c.devices = "sim-wire"; });
  const json program = json::parse(R"({"name": "wire-fault", "segments": [
    {"type": "hold", "name": "start", "duration_s": 2},
    {"type": "move", "name": "tilt", "to_deg": [0, 90, 0], "duration_s": 2},
    {"type": "hold", "name": "level", "duration_s": 4}]})");
  json campaign = {{"name", "wire-fault"}, {"program", program}, {"rate_hz", 100}, {"estimators", json::array()}};
  campaign["sim_faults"] = {{{"kind", "chamber_offset"}, {"at_s", 5}, {"duration_s", 3}, {"offset_C", 6}}};
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 90.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "suspended", "chamber out of band")) << c.at("events").dump();
  EXPECT_TRUE(has_event(c, "resumed", "redoing segment 2 'level'")) << c.at("events").dump();
  EXPECT_TRUE(has_transition(c, "running", "suspended"));
  const auto frames = run_frames(d.run_path(c));
  ASSERT_EQ(frames.size(), 800u);
  std::size_t off_grid = frames.front().t_ns != 10'000'000;
  for (std::size_t i = 1; i < frames.size(); ++i) off_grid += frames[i].t_ns - frames[i - 1].t_ns != 10'000'000;
  EXPECT_EQ(off_grid, 0u);
}

namespace {

// A rest, a power cycle with the rest after it, and a short hold: the relay's whole path.
json power_cycle_campaign(const std::string& name) {
  const json program = json::parse(R"({"name": "power-short", "segments": [
    {"type": "hold", "name": "before", "duration_s": 2},
    {"type": "power-cycle", "name": "power-on-2", "duration_s": 2},
    {"type": "hold", "name": "after", "duration_s": 1}]})");
  return {{"name", name}, {"program", program}, {"rate_hz", 100}, {"seed", 4},
          {"truth", noisy_truth()}, {"estimators", json::array()}};
}

int count_events(const json& c, const std::string& kind) {
  int n = 0;
  for (const auto& e : c.at("events")) n += e.at("kind") == kind;
  return n;
}

}  // namespace

// The bench's power relay (sim-wire: the simulated chamber's digital output 0) switches the IMU:
// nobody is asked, the IMU is off for the relay's off time, and the run goes on by itself.
TEST(SimWire, APowerCycleSwitchesTheRelayWithoutAskingAnyone) {
  LocalDaemon d("wire-relay", false, [](daemon::DaemonConfig& c) { c.devices = "sim-wire"; });
  // The chamber's register map as the device card shows it: what a manual vouches for.
  const json map = d.get("/api/status").at("chamber_map");
  EXPECT_EQ(map.at("name"), "watlow-f4t");
  EXPECT_EQ(map.at("checked"), "partly");
  EXPECT_EQ(map.at("unchecked"), json({"control_mode", "alarms"}));
  EXPECT_NE(map.at("summary").get<std::string>().find("partly checked against Watlow F4T"), std::string::npos);
  // The table controller's language, as the table card shows it.
  const json dialect = d.get("/api/status").at("table_dialect");
  EXPECT_EQ(dialect.at("name"), "imucal-acl");
  EXPECT_NE(dialect.at("source").get<std::string>().find("Not a maker's manual"), std::string::npos) << dialect.dump();
  const auto id = d.post_campaign(power_cycle_campaign("relay"));
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 120.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_EQ(count_events(c, "prompt"), 0) << c.at("events").dump();
  ASSERT_EQ(count_events(c, "power-off"), 1) << c.at("events").dump();
  ASSERT_EQ(count_events(c, "power-on"), 1);
  EXPECT_TRUE(has_event(c, "power-off", "through power relay modbus-tcp://127.0.0.1:")) << c.at("events").dump();
  EXPECT_TRUE(has_event(c, "power-off", "coil 0; on again in 2 s")) << c.at("events").dump();
  double off_s = 0.0;
  for (const auto& e : c.at("events"))
    if (e.at("kind") == "power-on") std::sscanf(e.at("reason").get<std::string>().c_str(), "the IMU switched on again after %lf", &off_s);
  EXPECT_GE(off_s, 2.0);
  EXPECT_LT(off_s, 10.0) << "a loaded machine may be late, not this late";
}

// A relay whose output does not follow (forced by hand on the controller's panel) is an alarm
// naming the coil; the operator is asked instead, and the run goes on after the answer.
TEST(SimWire, ARelayThatDoesNotSwitchAsksTheOperatorInstead) {
  LocalDaemon d("wire-relay-stuck", false, [](daemon::DaemonConfig& c) { c.devices = "sim-wire"; });
  json campaign = power_cycle_campaign("stuck");
  campaign["sim_faults"] = {{{"kind", "relay_stuck"}, {"at_s", 0.5}, {"duration_s", 600}}};
  const auto id = d.post_campaign(campaign);
  ASSERT_EQ(d.command(id, "start"), 200);
  d.wait_for(id, [](const json& x) { return x.contains("prompt") && x.at("prompt").is_object(); }, 60.0);
  const json asked = d.campaign(id);
  EXPECT_NE(asked.at("prompt").at("text").get<std::string>().find("The power relay failed"), std::string::npos)
      << asked.at("prompt").dump();
  ASSERT_EQ(d.call("POST", "/api/campaigns/" + std::to_string(id) + "/prompt", R"({"answer": "done"})").status, 200);
  const json c = d.wait_final(id, 120.0);
  ASSERT_EQ(c.at("state"), "done") << c.dump();
  EXPECT_TRUE(has_event(c, "alarm", "coil 0: the coil reads set after it was written clear")) << c.at("events").dump();
  EXPECT_TRUE(has_event(c, "alarm", "asking the operator instead"));
  EXPECT_EQ(count_events(c, "power-on"), 0);
  EXPECT_EQ(count_events(c, "prompt-answered"), 1);
}

TEST(SimWire, AStuckRelayNeedsTheSimWireDevices) {
  LocalDaemon d("relay-fault-sim");
  EXPECT_TRUE(d.get("/api/status").at("chamber_map").is_null()) << "the in-process simulation has no register map";
  EXPECT_TRUE(d.get("/api/status").at("table_dialect").is_null()) << "nor a table dialect";
  json campaign = power_cycle_campaign("stuck");
  campaign["sim_faults"] = {{{"kind", "relay_stuck"}, {"at_s", 0.5}}};
  const auto r = d.call("POST", "/api/campaigns", campaign.dump());
  EXPECT_EQ(r.status, 422);
  EXPECT_NE(r.body.find("campaign.sim_faults[0]: relay_stuck needs the sim-wire devices"), std::string::npos) << r.body;
}
