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
