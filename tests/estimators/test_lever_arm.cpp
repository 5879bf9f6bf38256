// Stage 1, size effect: proof-mass positions from the lever-arm program.
#include <gtest/gtest.h>

#include "calib_fixture.hpp"
#include "sim/simulator.hpp"
#include "estimators/lever_arm.hpp"
#include "lever_fixture.hpp"

using namespace imucal;

TEST(LeverArm, FindsTheProofMassesAndTheOriginWithinAFractionOfAMillimetre) {
  levertest::LeverRun run = levertest::make_run(calibtest::random_stage1_imu(21), {0.012, -0.004, 0.007},
                                                {-0.006, 0.010, -0.015}, {0.035, -0.020, 0.060}, 200, 3);
  // The stage-1 model: the truth with small residual errors, as stage 1 leaves them.
  run.stage1.accel.bias_mps2 += Eigen::Vector3d(5e-6, -5e-6, 3e-6);
  run.stage1.accel.scale += Eigen::Vector3d(1e-6, -1e-6, 1e-6);
  const lever::Result r = levertest::run(run);
  const ImuModel& truth = run.truth;
  const sim::SimConfig& cfg = run.cfg;
  for (const auto& n : r.notes) std::printf("%s\n", n.c_str());
  const Eigen::Vector3d ey = (r.model.accel.lever_arm_y_m - truth.accel.lever_arm_y_m) * 1e3;
  const Eigen::Vector3d ez = (r.model.accel.lever_arm_z_m - truth.accel.lever_arm_z_m) * 1e3;
  ASSERT_TRUE(r.model.mount_r0_p_m.has_value());
  const Eigen::Vector3d e0 = (*r.model.mount_r0_p_m - cfg.mount.r0_p_m) * 1e3;
  std::printf("errors, mm: r_y %+.4f %+.4f %+.4f  r_z %+.4f %+.4f %+.4f  r0 %+.4f %+.4f %+.4f\n", ey.x(), ey.y(), ey.z(),
              ez.x(), ez.y(), ez.z(), e0.x(), e0.y(), e0.z());
  EXPECT_LT(ey.cwiseAbs().maxCoeff(), 0.3);
  EXPECT_LT(ez.cwiseAbs().maxCoeff(), 0.3);
  EXPECT_LT(e0.cwiseAbs().maxCoeff(), 0.3);
  // The 9-state filter of the seed does not carry the stage-1 residuals injected above, so its sigma
  // is only checked where the stage-1 model is exact (next test).
}

TEST(LeverArm, SigmaIsConsistentWhenStageOneIsExact) {
  const levertest::LeverRun run = levertest::make_run(calibtest::random_stage1_imu(22), {-0.008, 0.003, 0.009},
                                                      {0.004, -0.011, 0.013}, {-0.02, 0.03, 0.05}, 200, 4);
  const lever::Result r = levertest::run(run);
  const ImuModel& truth = run.truth;
  const sim::SimConfig& cfg = run.cfg;
  ASSERT_TRUE(r.model.sigma.has_value() && r.model.mount_r0_p_m.has_value());
  const ImuErrorSet& sigma = *r.model.sigma;
  const Eigen::Vector3d& r0_p_m = *r.model.mount_r0_p_m;
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(std::abs(r.model.accel.lever_arm_y_m[i] - truth.accel.lever_arm_y_m[i]), 3 * sigma.accel.lever_arm_y_m[i]) << i;
    EXPECT_LE(std::abs(r.model.accel.lever_arm_z_m[i] - truth.accel.lever_arm_z_m[i]), 3 * sigma.accel.lever_arm_z_m[i]) << i;
    EXPECT_LE(std::abs(r0_p_m[i] - cfg.mount.r0_p_m[i]), 3 * r.sigma_m[i]) << i;
  }
}

TEST(LeverArm, StaticRecordingIsRefusedByName) {
  const auto p = motion::compile_program(R"({"name":"s","segments":[{"type":"hold","duration_s":30}]})",
                                         motion::TableLimits{});
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  sim::Simulator s(p, ImuModel{}, cfg);
  lever::LeverArmFilter filter(s.meta(), ImuModel{});
  ImuFrame f;
  while (s.next(f)) filter.push(f);
  try {
    filter.finish();
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("does not determine r0.x"), std::string::npos) << e.what();
  }
}

// The accelerometers' delays (~2 ms in the seed's IMU) are unknown until stage 3. Whenever gravity
// turns in the sensor frame they look like a specific force of tau |w x g|; before the filter left
// those blocks out, 2 ms delays moved the proof masses by a third of a millimetre, and stage 3 then
// paid for it in the gyro axis angles (0.9" instead of 0.1").
TEST(LeverArm, UnknownAccelerometerDelaysDoNotMoveTheProofMasses) {
  levertest::LeverRun run = levertest::make_run(calibtest::random_stage1_imu(23), {0.010, -0.004, 0.006},
                                                {-0.005, 0.008, -0.012}, {0.03, -0.02, 0.05}, 200, 5);
  run.truth.accel.delay_s << 2.0e-3, 2.1e-3, 1.9e-3;  // stage 1 knows no delays
  run.truth.gyro.delay_s << 2e-6, 5e-6, -3e-6;
  const lever::Result r = levertest::run(run);
  const ImuModel& truth = run.truth;
  const sim::SimConfig& cfg = run.cfg;
  const Eigen::Vector3d ey = (r.model.accel.lever_arm_y_m - truth.accel.lever_arm_y_m) * 1e3;
  const Eigen::Vector3d ez = (r.model.accel.lever_arm_z_m - truth.accel.lever_arm_z_m) * 1e3;
  ASSERT_TRUE(r.model.mount_r0_p_m.has_value());
  const Eigen::Vector3d e0 = (*r.model.mount_r0_p_m - cfg.mount.r0_p_m) * 1e3;
  std::printf("errors, mm: r_y %+.4f %+.4f %+.4f  r_z %+.4f %+.4f %+.4f  r0 %+.4f %+.4f %+.4f\n", ey.x(), ey.y(), ey.z(),
              ez.x(), ez.y(), ez.z(), e0.x(), e0.y(), e0.z());
  // A tenth of the issue's 0.3 mm: the effect being guarded against was 0.33 mm.
  EXPECT_LT(ey.cwiseAbs().maxCoeff(), 0.03);
  EXPECT_LT(ez.cwiseAbs().maxCoeff(), 0.03);
  EXPECT_LT(e0.cwiseAbs().maxCoeff(), 0.03);
}
