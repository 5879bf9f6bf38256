// The built-in motion programs, generated as data (the same JSON a user could write).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "motion_programs/program.hpp"

namespace imucal::motion {

using nlohmann::json;

namespace {

// Table poses (outer, middle, inner in degrees) that point one IMU axis up or down for an IMU
// mounted square on the platform (C_o_p = I): z up at middle 0, y up at middle 90, x up at
// middle 90 / inner 90. The outer angle sets the heading.
json pose(double outer, double middle, double inner) { return json::array({outer, middle, inner}); }

const double kDiagonalMiddleDeg = std::atan(std::sqrt(2.0)) * 180.0 / 3.14159265358979323846;

json hold(const std::string& name, double s) { return {{"type", "hold"}, {"name", name}, {"duration_s", s}}; }
json move(const std::string& name, const json& to) { return {{"type", "move"}, {"name", name}, {"to_deg", to}}; }

// Multi-position statics and +/- rate runs about each IMU axis. dwell 36 s per the seed.
json direct_program(double dwell_s, const std::vector<double>& headings, double rate_dps, double revolutions) {
  json segs = json::array();
  segs.push_back(hold("start", dwell_s));
  json positions = json::array();
  const std::vector<std::array<double, 2>> orientations = {
      {0, 0}, {180, 0}, {90, 0}, {-90, 0}, {90, 90}, {90, -90}};  // z up/down, y up/down, x up/down
  for (const auto& o : orientations)
    for (double h : headings) positions.push_back(pose(h, o[0], o[1]));
  segs.push_back({{"type", "positions"}, {"name", "pos"}, {"positions_deg", positions}, {"dwell_s", dwell_s}});
  const std::vector<std::pair<std::string, json>> rate_axes = {
      {"z", pose(0, 0, 0)}, {"x", pose(0, 90, 90)}, {"y", pose(0, 90, 0)}};
  for (const auto& [axis, p] : rate_axes) {
    segs.push_back(move("to-pre-" + axis, p));
    segs.push_back(hold("pre-" + axis, dwell_s));
    for (const char* sign : {"+", "-"}) {
      const double r = sign[0] == '+' ? rate_dps : -rate_dps;
      segs.push_back({{"type", "rate"}, {"name", "rate-" + axis + sign}, {"axis", "outer"}, {"rate_dps", r},
                      {"revolutions", revolutions}, {"accel_dps2", 20.0}});
      segs.push_back(hold("post-" + axis + sign, dwell_s));
    }
  }
  return {{"name", "direct"},
          {"comment", "Stage 1: each IMU axis up and down at several headings, then +/- rate runs about each IMU axis"},
          {"segments", segs}};
}

json lever_arm_program() {
  json segs = json::array();
  const std::vector<std::pair<std::string, json>> up = {{"x", pose(0, 90, 90)}, {"y", pose(0, 90, 0)}, {"z", pose(0, 0, 0)}};
  for (const auto& [axis, p] : up) {
    segs.push_back(move("to-" + axis + "-up", p));
    segs.push_back(hold("static-" + axis + "-up", 36));
    // Variable angular acceleration about the vertical accelerometer axis: 20 deg at 2 s.
    segs.push_back({{"type", "sine"}, {"name", "osc-" + axis + "-up"}, {"axis", "outer"}, {"amplitude_deg", 20.0},
                    {"period_s", 2.0}, {"cycles", 60}, {"phase_deg", 0.0}, {"ramp_s", 4.0}});
    segs.push_back(hold("after-" + axis + "-up", 36));
  }
  return {{"name", "lever-arm"},
          {"comment", "Oscillations with variable angular acceleration about each accelerometer axis pointing up"},
          {"segments", segs}};
}

json navigation_program() {
  json segs = json::array();
  auto swing = [&](const std::string& name, const char* axis) {
    segs.push_back({{"type", "sine"}, {"name", name}, {"axis", axis}, {"amplitude_deg", 360.0},
                    {"period_s", 1200.0}, {"cycles", 1}, {"phase_deg", 90.0}});
  };
  // Part 1: slow 360 deg swings, 20 min period, about each table axis; then 90 deg re-orientation.
  segs.push_back(hold("start", 60));
  swing("swing-outer-a", "outer");
  swing("swing-middle-a", "middle");
  segs.push_back(move("to-middle-90-a", pose(0, 90, 0)));
  swing("swing-inner-a", "inner");
  segs.push_back(move("reorient-90", pose(0, 90, 90)));
  segs.push_back(hold("settle-b", 60));
  swing("swing-outer-b", "outer");
  swing("swing-middle-b", "middle");
  swing("swing-inner-b", "inner");
  // Part 2: fast 180 deg / 25 s oscillation of the outer axis with the IMU diagonal up.
  segs.push_back(move("to-diagonal", pose(0, kDiagonalMiddleDeg, 45)));
  segs.push_back(hold("diagonal-static", 60));
  segs.push_back({{"type", "sine"}, {"name", "diagonal-osc"}, {"axis", "outer"}, {"amplitude_deg", 180.0},
                  {"period_s", 25.0}, {"cycles", 20}, {"phase_deg", 0.0}, {"ramp_s", 25.0}});
  // Part 3: single-axis 180 deg / 20 s oscillations about each IMU axis.
  const std::vector<std::pair<std::string, json>> up = {{"z", pose(0, 0, 0)}, {"x", pose(0, 90, 90)}, {"y", pose(0, 90, 0)}};
  for (const auto& [axis, p] : up) {
    segs.push_back(move("to-osc-" + axis, p));
    segs.push_back(hold("pre-osc-" + axis, 30));
    segs.push_back({{"type", "sine"}, {"name", "osc-" + axis}, {"axis", "outer"}, {"amplitude_deg", 180.0},
                    {"period_s", 20.0}, {"cycles", 10}, {"phase_deg", 0.0}, {"ramp_s", 20.0}});
  }
  segs.push_back(hold("end", 30));
  return {{"name", "navigation"},
          {"comment", "Stage 3 (seed ch. 4): slow swings, fast diagonal oscillation, single-axis oscillations"},
          {"segments", segs}};
}

json noise_program() {
  return {{"name", "noise"},
          {"comment", "Two hours static, z up, for Allan deviation and bias instability"},
          {"segments", json::array({hold("static", 7500)})}};
}

// IEEE 952 warm-up: one static from the moment the IMU is switched on (start the campaign as it
// is powered), z up, long enough for several time constants of its transient.
json warm_up_program(const std::string& name, double duration_s) {
  return {{"name", name},
          {"comment", "Warm-up: a static from power-on (switch the IMU on as the run starts), z up: the bias transient, "
                      "its time constant and the time to settle"},
          {"segments", json::array({hold("warm-up", duration_s)})}};
}

// IEEE 952 turn-on to turn-on repeatability: `turn_ons` power-ons, z up, each followed by a rest
// of settle_s (kind "settle": its warm-up, not measured) and a static of dwell_s; before each
// power-on after the first a power-cycle segment (imucald prompts the operator to switch the IMU
// off and on, and waits).
json repeatability_program(const std::string& name, int turn_ons, double rest_s, double settle_s, double dwell_s) {
  json segs = json::array();
  char label[16];
  for (int k = 1; k <= turn_ons; ++k) {
    std::snprintf(label, sizeof label, "%02d", k);
    if (k > 1) segs.push_back({{"type", "power-cycle"}, {"name", std::string("power-") + label}, {"duration_s", rest_s}});
    segs.push_back({{"type", "hold"}, {"name", std::string("settle-") + label}, {"kind", "settle"}, {"duration_s", settle_s}});
    segs.push_back(hold(std::string("on-") + label, dwell_s));
  }
  return {{"name", name},
          {"comment", "Turn-on to turn-on repeatability: switch the IMU on as the run starts; imucald asks for each "
                      "further power cycle and waits"},
          {"segments", segs}};
}

json evaluate_program() {
  json segs = json::array();
  segs.push_back(hold("start", 120));
  // Tilts: accelerometer errors show as Schuler oscillations after each tilt.
  segs.push_back({{"type", "tilts"}, {"name", "tilt"},
                  {"positions_deg", json::array({pose(0, 10, 0), pose(0, 0, 0), pose(0, 10, 90)})},
                  {"dwell_s", 1800}});
  // Coning: middle and inner axes, same frequency, 90 deg apart.
  segs.push_back(move("to-level", pose(0, 0, 0)));
  segs.push_back({{"type", "coning"}, {"name", "coning"}, {"axes", {"middle", "inner"}}, {"amplitude_deg", 10.0},
                  {"period_s", 10.0}, {"cycles", 540}, {"ramp_s", 10.0}});
  segs.push_back(hold("end", 60));
  return {{"name", "evaluate"},
          {"comment", "Judging a calibration: tilts (30 min each), then 90 min of coning 10 deg at 10 s"},
          {"segments", segs}};
}

// IEEE Std 952's scale-factor tests: each IMU axis vertical (the poses of `direct`), turned about
// the outer axis at every rate of the ladder, positive then negative, whole revolutions rest to
// rest (the cruise long against the ramps: about 30 deg/s worth of revolutions), with a static in
// the same orientation before the first rate and after each. estimators/rate_steps.hpp reads it.
json rate_steps_program(const std::string& name, const std::vector<double>& ladder_dps, double dwell_s) {
  json segs = json::array();
  const std::vector<std::pair<std::string, json>> axes = {{"z", pose(0, 0, 0)}, {"x", pose(0, 90, 90)}, {"y", pose(0, 90, 0)}};
  char label[48];
  for (const auto& [axis, p] : axes) {
    segs.push_back(move("to-steps-" + axis, p));
    segs.push_back(hold("rest-" + axis, dwell_s));
    for (double r : ladder_dps) {
      for (double sign : {1.0, -1.0}) {
        std::snprintf(label, sizeof label, "%s%c%03.0f", axis.c_str(), sign > 0 ? '+' : '-', r);
        segs.push_back({{"type", "rate"}, {"name", std::string("steps-") + label}, {"axis", "outer"},
                        {"rate_dps", sign * r}, {"revolutions", std::max(1.0, std::round(r / 30.0))},
                        {"accel_dps2", 100.0}});
        segs.push_back(hold(std::string("rest-") + label, dwell_s));
      }
    }
  }
  return {{"name", name},
          {"comment", "IEEE 952 scale-factor tests: each IMU axis up, turned at a ladder of rates both ways "
                      "(whole revolutions, a static after each): scale factor per rate, asymmetry, nonlinearity"},
          {"segments", segs}};
}

// IEEE Std 1293's multipoint tumble: the platform turned about the horizontal middle axis through
// a whole turn in equal steps, a static at each, twice: with the inner axis at 0 (y and z sweep the
// vertical plane) and at 90 deg (x and z: the inner axis turns x into the plane the middle axis
// sweeps; x is up at middle 90 / inner 90). Every accelerometer meets +1 g and -1 g and the angles
// between; the specific force sweeps every direction of o, which the gyros' g-sensitivity needs.
// estimators/tumble.hpp reads it.
json tumble_program(const std::string& name, int steps, double dwell_s) {
  json segs = json::array();
  for (double inner : {0.0, 90.0}) {
    const std::string plane = inner == 0.0 ? "yz" : "xz";
    json positions = json::array();
    for (int k = 0; k < steps; ++k) positions.push_back(pose(0, 360.0 * k / steps, inner));
    segs.push_back({{"type", "positions"}, {"name", "tumble-" + plane}, {"positions_deg", positions}, {"dwell_s", dwell_s}});
  }
  return {{"name", name},
          {"comment", "IEEE 1293 multipoint tumble: the middle axis through a whole turn in equal steps with a static at "
                      "each, with the inner axis at 0 and at 90 deg: accelerometer bias, scale, K2, K3, misalignment; "
                      "gyro g-sensitivity"},
          {"segments", segs}};
}

// Stage 2 (seed ch. 3): a table cycle that gives every coefficient of model (1) once (each axis
// up and down; rotations of both signs about each axis between stops), repeated while the chamber
// runs its profile. The cycle is a palindrome in time: six stops out, the sixth held twice as
// long, the same stops back in reverse order to the first, which the next cycle shares. The
// sensors drift by up to 1e-3 m/s^2 within a cycle while the chamber ramps; with every stop
// mirrored about the cycle's middle a linear drift cancels out of every estimate instead of
// leaking from one coefficient into another.
json thermal_program(const std::string& name, int cycles, double dwell_s) {
  struct Stop {
    const char* name;
    double middle, inner;  // outer stays at 0; every move between neighbours is one axis by 90 deg
  };
  static const Stop kStops[] = {
      {"z-up", 0, 0}, {"y-up", 90, 0}, {"x-up", 90, 90}, {"z-down", 180, 90}, {"x-down", 270, 90}, {"y-down", 270, 0},
  };
  constexpr int kN = 6;
  constexpr double kMove_s = 12.0;
  json segs = json::array();
  char prefix[32];
  auto stop = [&](int k, const char* suffix, double dwell) {
    const Stop& s = kStops[k];
    const std::string label = std::string(prefix) + s.name + suffix;
    if (!segs.empty())
      segs.push_back({{"type", "move"}, {"name", "to-" + label}, {"to_deg", pose(0, s.middle, s.inner)},
                      {"duration_s", kMove_s}});
    segs.push_back(hold(label, dwell));
  };
  for (int c = 1; c <= cycles; ++c) {
    std::snprintf(prefix, sizeof prefix, "cycle-%03d/", c);
    for (int k = 0; k < kN; ++k) stop(k, "", k == kN - 1 ? 2.0 * dwell_s : dwell_s);
    for (int k = kN - 2; k >= 1; --k) stop(k, "-b", dwell_s);
  }
  // The closing stop gives the last cycle its final rest, mirroring its first.
  prefix[0] = '\0';
  stop(0, "", dwell_s);
  segs[segs.size() - 2]["name"] = "to-end";
  segs.back()["name"] = "end";
  return {{"name", name},
          {"comment", "Stage 2 (seed ch. 3): a palindromic cycle of 36 s stops and 90 deg single-axis rotations, "
                      "repeated; run it with a chamber profile (imucal simulate --chamber)"},
          {"segments", segs}};
}

}  // namespace

std::vector<std::string> builtin_program_names() {
  return {"direct", "direct-short", "lever-arm", "navigation", "noise", "evaluate", "thermal", "thermal-short",
          "rate-steps", "rate-steps-short", "tumble", "tumble-short", "warm-up", "warm-up-short",
          "repeatability", "repeatability-short"};
}

std::string builtin_program_json(const std::string& name) {
  if (name == "direct") return direct_program(36.0, {0, 90, 180, 270}, 20.0, 5.0).dump(1);
  if (name == "direct-short") {
    json j = direct_program(10.0, {0, 180}, 30.0, 2.0);
    j["name"] = "direct-short";
    // No duration in words: the builder shows the compiled one beside it.
    j["comment"] = "A short version of direct for quick checks: 10 s dwells, 2 headings, 2 revolutions at 30 deg/s (not enough statics for full accuracy)";
    return j.dump(1);
  }
  if (name == "lever-arm") return lever_arm_program().dump(1);
  if (name == "navigation") return navigation_program().dump(1);
  if (name == "noise") return noise_program().dump(1);
  if (name == "evaluate") return evaluate_program().dump(1);
  // 83 cycles of 516 s and the closing stop: 11.9 h, the length of the thermal chamber profile.
  if (name == "thermal") return thermal_program("thermal", 83, 36.0).dump(1);
  if (name == "thermal-short") return thermal_program("thermal-short", 14, 36.0).dump(1);
  if (name == "rate-steps") return rate_steps_program(name, {1, 2, 5, 10, 20, 50, 100, 150, 200, 250, 300}, 20.0).dump(1);
  if (name == "rate-steps-short") return rate_steps_program(name, {5, 10, 20, 50, 100, 150, 200, 300}, 10.0).dump(1);
  if (name == "tumble") return tumble_program(name, 24, 36.0).dump(1);
  if (name == "tumble-short") return tumble_program(name, 12, 20.0).dump(1);
  if (name == "warm-up") return warm_up_program(name, 7200.0).dump(1);
  if (name == "warm-up-short") return warm_up_program(name, 1800.0).dump(1);
  if (name == "repeatability") return repeatability_program(name, 8, 30.0, 300.0, 600.0).dump(1);
  if (name == "repeatability-short") return repeatability_program(name, 6, 10.0, 30.0, 120.0).dump(1);
  throw std::invalid_argument("unknown built-in program '" + name + "'");
}

}  // namespace imucal::motion
