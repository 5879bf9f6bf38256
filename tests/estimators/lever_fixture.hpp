// The lever-arm program simulated once and fed to the stage-1 lever-arm filter (tests only).
#pragma once

#include "sim/simulator.hpp"
#include "estimators/lever_arm.hpp"
#include "motion_programs/program.hpp"

namespace imucal::levertest {

struct LeverRun {
  ImuModel truth;          // what the simulator uses (proof masses, delays, ...)
  ImuModel stage1;         // what the filter starts from: the truth without lever arms
  sim::SimConfig cfg;      // rate, seed, mount.r0_p_m
};

// A run of the built-in lever-arm program: truth with the given proof-mass offsets, stage 1 equal
// to the truth but for the lever arms (tests change either before calling run()).
inline LeverRun make_run(const ImuModel& truth, const Eigen::Vector3d& r_y_m, const Eigen::Vector3d& r_z_m,
                         const Eigen::Vector3d& r0_p_m, double rate_hz, std::uint64_t seed) {
  LeverRun run;
  run.truth = truth;
  run.truth.accel.lever_arm_y_m = r_y_m;
  run.truth.accel.lever_arm_z_m = r_z_m;
  run.stage1 = run.truth;
  run.stage1.accel.lever_arm_y_m.setZero();
  run.stage1.accel.lever_arm_z_m.setZero();
  run.cfg.rate_hz = rate_hz;
  run.cfg.seed = seed;
  run.cfg.mount.r0_p_m = r0_p_m;
  return run;
}

inline lever::Result run(const LeverRun& r) {
  const auto p = motion::load_program("lever-arm", motion::TableLimits{});
  sim::Simulator s(p, r.truth, r.cfg);
  lever::LeverArmFilter filter(s.meta(), r.stage1);
  ImuFrame f;
  while (s.next(f)) filter.push(f);
  return filter.finish();
}

}  // namespace imucal::levertest
