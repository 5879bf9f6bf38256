// Thermal-chamber profiles as data (set points, ramps, soaks; JSON documented in docs/thermal.md)
// and the (T, dT/dt) coverage a profile reaches, predicted before the run from a lag model of
// chamber air -> IMU case -> sensor. Pure functions of time: no I/O, no clock.
#pragma once

#include <string>
#include <vector>

namespace imucal::motion {

// What the chamber can do; a profile outside these is refused before anything starts. The one
// definition: imucald's configuration (`chamber`) holds one, `imucal simulate` checks against the
// defaults.
struct ChamberLimits {
  double min_C = -40.0;
  double max_C = 85.0;
  double max_ramp_C_per_min = 5.0;
};

// One step of the set point: a soak holds it, a ramp moves it linearly, a set jumps to it and
// holds (the chamber then follows at its own rate).
struct ChamberStep {
  std::string name;
  std::string kind;  // soak, ramp, set
  double t0_s = 0, t1_s = 0;
  double from_C = 0, to_C = 0;  // set point at t0 (after a set: the new value) and at t1
};

class ChamberProfile {
 public:
  std::string name;
  std::string source_json;
  double start_C = 25.0;
  std::vector<ChamberStep> steps;

  double duration_s() const { return steps.empty() ? 0.0 : steps.back().t1_s; }
  // The set point at t; before the start the start value, after the end the last one.
  double setpoint_C(double t_s) const;
  // The step in force at t (the last one after the end, nullptr for an empty profile).
  const ChamberStep* step_at(double t_s) const;
};

// Whether the set point moves (a ramp) somewhere inside (t0_s, t1_s): a program segment that
// overlaps a ramp cannot be redone as it was (the chamber's history cannot be repeated).
bool ramps_within(const ChamberProfile& profile, double t0_s, double t1_s);

// A set-point change as a campaign's `chamber.steps` gives it (docs/api.md): at program time at_s
// the set point goes to setpoint_C at ramp_C_per_min (0: at once), then holds until the next one.
struct SetpointChange {
  double at_s = 0.0;
  double setpoint_C = 25.0;
  double ramp_C_per_min = 0.0;
};
// The profile such changes make from start_C, held to end_s (the program's end); a ramp the next
// change cuts short ends where it got to. The changes must be in time order.
ChamberProfile profile_of_changes(double start_C, const std::vector<SetpointChange>& changes, double end_s);
// A profile as its changes (holds and soaks implicit): the campaign's stored form of it.
std::vector<SetpointChange> changes_of(const ChamberProfile& profile);

// Compiles a profile from JSON. Throws std::invalid_argument naming the step and the key.
ChamberProfile compile_chamber_profile(const std::string& json_text);
// Every set point outside the limits and every ramp faster than the chamber, naming the step.
std::vector<std::string> validate_chamber_profile(const ChamberProfile& profile, const ChamberLimits& limits);

// Built-in profiles: thermal (about 12 h over 15..35 C), thermal-short (about 2 h, for checks).
std::vector<std::string> builtin_chamber_names();
bool is_builtin_chamber(const std::string& name);
std::string builtin_chamber_json(const std::string& name);  // throws for an unknown name
// A built-in name or a path to a JSON file.
ChamberProfile load_chamber_profile(const std::string& name_or_path);

// First-order lags of the thermal path; the simulator's defaults (sim/thermal_model.hpp)
// are the same numbers, so the predicted coverage is what the simulated run reaches.
struct ThermalLags {
  double chamber_tau_s = 180.0;               // chamber air behind the set point
  double chamber_max_rate_C_per_min = 2.0;    // heater/cooler capacity
  double case_tau_s = 900.0;                  // IMU case behind the air
  double sensor_tau_s = 540.0;                // FOG coil / accelerometer behind the case
};

// Exact response over one step h of y' = (u - y) / tau to an input going linearly u0 -> u1.
double first_order_lag_step(double y0, double u0, double u1, double h_s, double tau_s);

// Seconds spent in each cell of a (T, dT/dt) grid.
struct CoverageMap {
  double T_lo_C = 15, T_hi_C = 35, T_bin_C = 1.0;
  double rate_lo_C_per_min = -1.0, rate_hi_C_per_min = 1.0, rate_bin_C_per_min = 0.1;
  std::vector<double> seconds;  // row-major: [T bin][rate bin]
  double T_min_C = 0, T_max_C = 0;                    // reached, over the whole run
  double rate_min_C_per_min = 0, rate_max_C_per_min = 0;
  double total_s = 0;

  int T_bins() const;
  int rate_bins() const;
  void add(double T_C, double rate_C_per_min, double seconds);
  // Share of the T bins (inside [T_lo, T_hi]) visited while heating, while cooling, and near
  // rest (|rate| below one bin).
  double heating_T_fraction(double min_seconds = 60.0) const;
  double cooling_T_fraction(double min_seconds = 60.0) const;
  double rest_T_fraction(double min_seconds = 60.0) const;
  // The map as text: one row per T bin, one character per rate bin (' ', '.', ':', '#' by time).
  std::string ascii() const;
  std::string to_json() const;
};

// The sensor temperature the lag model predicts for the profile, binned every step_s.
CoverageMap predict_coverage(const ChamberProfile& profile, const ThermalLags& lags, CoverageMap grid = {},
                             double step_s = 10.0);

}  // namespace imucal::motion
