// A simulated stage-2 run in memory: program + chamber profile + thermal model + simulator, the
// per-cycle estimates streamed, then the fits. No database, so a 12 h run stays in seconds.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "sim/simulator.hpp"
#include "sim/thermal_model.hpp"
#include "estimators/thermal.hpp"
#include "motion_programs/chamber.hpp"
#include "motion_programs/program.hpp"
#include "tests/test_paths.hpp"

namespace imucal::thermaltest {

inline ImuModel truth_thermal() { return read_imu_model_file(imucaltest::source_dir() + "/examples/truth-thermal.json"); }

// The truth without noise and without the unmodelled oscillation ("clean").
inline ImuModel clean(ImuModel m) {
  m.gyro.noise = {};
  m.accel.noise = {};
  auto j = nlohmann::json::parse(m.thermal_json);
  j.erase("sim_oscillation");
  m.thermal_json = j.dump();
  return m;
}

// Stage 1 as if done at 25 C: the truth's constants, no thermal section.
inline ImuModel stage1_of(const ImuModel& truth) {
  ImuModel m = truth;
  m.thermal_json.clear();
  return m;
}

// A stretch of the thermal-short chamber run at 20 Hz, the truth's coefficients following its own
// thermal section: what the compensation tests navigate with and without that section.
struct ChamberStretch {
  ImuModel truth = clean(truth_thermal());
  motion::Program program = motion::load_program("thermal-short", motion::TableLimits{});
  sim::SimConfig cfg;
  explicit ChamberStretch(double duration_s)
      : tm_(motion::load_chamber_profile("thermal-short"), truth, sim::ThermalConfig{}, duration_s) {
    cfg.rate_hz = 20;
    cfg.duration_s = duration_s;
    cfg.thermal = &tm_;
  }
  ChamberStretch(const ChamberStretch&) = delete;  // cfg points into it
  ChamberStretch& operator=(const ChamberStretch&) = delete;

 private:
  sim::ThermalModel tm_;
};

struct Run {
  std::string program = "thermal";
  std::string chamber = "thermal";
  double rate_hz = 20.0;
  double duration_s = 0.0;  // 0: the program's
  std::uint64_t seed = 7;
  sim::ThermalConfig thermal;
  thermal::Options options;
};

struct Outcome {
  thermal::Result result;
  nlohmann::json report;
  double sim_and_cycles_s = 0, fit_s = 0;
  std::vector<TempSample> temps;
};

// Simulates and fits; with `earlier` set, judges that model on the run (mode "judge") or keeps its
// shape and fits the constants (mode "constants") instead of fitting everything.
inline Outcome run(const ImuModel& truth, const Run& r, const ImuModel* earlier = nullptr,
                   const std::string& mode = "judge") {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const motion::Program program = motion::load_program(r.program, motion::TableLimits{});
  const motion::ChamberProfile profile = motion::load_chamber_profile(r.chamber);
  sim::SimConfig cfg;
  cfg.rate_hz = r.rate_hz;
  cfg.seed = r.seed;
  cfg.duration_s = r.duration_s;
  cfg.site.middle_axis_azimuth_deg = 15;
  const double duration = r.duration_s > 0 ? r.duration_s : program.duration_s();
  const sim::ThermalModel thermal(profile, truth, r.thermal, duration);
  cfg.thermal = &thermal;
  sim::Simulator s(program, truth, cfg);
  const RecordingMeta meta = s.meta();
  thermal::CycleEstimator est(meta, thermal::find_cycles(meta.segments), stage1_of(truth));
  Outcome out;
  ImuFrame f;
  while (s.next(f)) est.push(f);
  out.temps = s.take_temps();
  const std::vector<thermal::CycleEstimate> cycles = est.finish();
  const auto t1 = Clock::now();
  out.result = !earlier            ? thermal::calibrate(meta, cycles, out.temps, stage1_of(truth), r.options)
               : mode == "judge" ? thermal::evaluate(meta, cycles, out.temps, *earlier, r.options)
                                 : thermal::refit_constants(meta, cycles, out.temps, *earlier, r.options);
  out.report = nlohmann::json::parse(out.result.report_json);
  out.sim_and_cycles_s = std::chrono::duration<double>(t1 - t0).count();
  out.fit_s = std::chrono::duration<double>(Clock::now() - t1).count();
  return out;
}

inline void print(const Outcome& o) {
  for (const auto& n : o.result.notes) std::printf("  note: %s\n", n.c_str());
  std::printf("  cycles %d of %d used; sim + per-cycle %.1f s, fits + report %.1f s\n", o.result.cycles_used,
              o.result.cycles_total, o.sim_and_cycles_s, o.fit_s);
  std::printf("  %-26s %12s %12s %12s %12s\n", "coefficient", "before", "residual", "est.error", "truth p-p");
  for (const char* g : thermal::groups()) {
    auto val = [&](const char* k) { return o.report.contains(k) ? o.report[k].value(g, 0.0) : 0.0; };
    std::printf("  %-26s %12.4g %12.4g %12.4g %12.4g\n", g, val("before"), val("residual"), val("estimate_error"),
                val("truth_peak_to_peak"));
  }
}

}  // namespace imucal::thermaltest
