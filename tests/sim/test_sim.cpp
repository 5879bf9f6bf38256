// The simulated table + Earth + IMU against closed-form truths.
#include <cmath>

#include <gtest/gtest.h>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"
#include "sim/simulator.hpp"

using namespace imucal;
using Eigen::Vector3d;

namespace {
motion::Program program(const std::string& json) { return motion::compile_program(json, motion::TableLimits{}); }
}  // namespace

TEST(Simulator, StaticIdealImuSensesEarthRateAndGravity) {
  const auto p = program(R"({"name":"s","start_deg":[30,90,90],"segments":[{"type":"hold","duration_s":2}]})");
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  cfg.site.middle_axis_azimuth_deg = 20;
  sim::Simulator s(p, ImuModel{}, cfg);
  const double lat = cfg.site.latitude_deg * units::kDegToRad, g = earth::site_gravity_mps2(cfg.site);
  const Eigen::Matrix3d C_o_n = table::C_p_n(Vector3d(30, 90, 90) * units::kDegToRad, table::C_p0_n(20 * units::kDegToRad));
  Vector3d sum_th = Vector3d::Zero(), sum_v = Vector3d::Zero();
  ImuFrame f;
  int n = 0;
  while (s.next(f)) {
    sum_th += f.dtheta_rad;
    sum_v += f.dv_mps;
    ++n;
  }
  EXPECT_EQ(n, 200);
  EXPECT_EQ(f.t_ns, 2'000'000'000);
  // x up: the accelerometers read +g on x; the gyros the Earth rate in o.
  EXPECT_LT((sum_v - C_o_n.transpose() * Vector3d(0, 0, g) * 2.0).norm(), 1e-9);
  EXPECT_LT((sum_th - C_o_n.transpose() * earth::w_ie_n(lat) * 2.0).norm(), 1e-10);
  EXPECT_NEAR(sum_v[0] / 2.0, g, 1e-9);
}

TEST(Simulator, RateRunTurnsTheTableAngleExactly) {
  const auto p = program(R"({"name":"r","segments":[{"type":"hold","duration_s":1},
    {"type":"rate","axis":"outer","rate_dps":50,"revolutions":3,"accel_dps2":100},{"type":"hold","duration_s":1}]})");
  sim::SimConfig cfg;
  cfg.rate_hz = 200;
  sim::Simulator s(p, ImuModel{}, cfg);
  double sum_z = 0;
  ImuFrame f;
  while (s.next(f)) sum_z += f.dtheta_rad[2];
  const double lat = cfg.site.latitude_deg * units::kDegToRad;
  // 3 turns plus the vertical Earth rate over the run (z stays up).
  EXPECT_NEAR(sum_z, 6 * units::kPi + earth::w_ie_n(lat).z() * p.duration_s(), 1e-9);
  EXPECT_NEAR(f.table_deg[0], 1080.0, 1e-9);
}

TEST(Simulator, ReproducibleForASeedAndDifferentAcrossSeeds) {
  const auto p = program(R"({"name":"s","segments":[{"type":"hold","duration_s":1}]})");
  ImuModel truth;
  truth.gyro.noise.arw_rad_rts = 0.001 * units::kDegRthToRadRts;
  truth.accel.noise.vrw_mps_rts = 0.002 * units::kMpsRthToMpsRts;
  truth.gyro.noise.bias_instability_radps = 0.001 * units::kDphToRadps;
  auto run = [&](std::uint64_t seed) {
    sim::SimConfig cfg;
    cfg.rate_hz = 100;
    cfg.seed = seed;
    sim::Simulator s(p, truth, cfg);
    std::vector<double> out;
    ImuFrame f;
    while (s.next(f))
      for (int j = 0; j < 3; ++j) out.insert(out.end(), {f.dtheta_rad[j], f.dv_mps[j]});
    return out;
  };
  EXPECT_EQ(run(7), run(7));
  EXPECT_NE(run(7), run(8));
}

TEST(Simulator, WhiteNoiseHasTheConfiguredDensity) {
  const auto p = program(R"({"name":"s","segments":[{"type":"hold","duration_s":400}]})");
  ImuModel truth;
  truth.gyro.noise.arw_rad_rts = 0.0005 * units::kDegRthToRadRts;
  truth.accel.noise.vrw_mps_rts = 0.002 * units::kMpsRthToMpsRts;
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  sim::Simulator ideal(p, ImuModel{}, cfg), noisy(p, truth, cfg);
  ImuFrame a, b;
  double sg = 0, sa = 0;
  int n = 0;
  while (ideal.next(a) && noisy.next(b)) {
    sg += std::pow(b.dtheta_rad[1] - a.dtheta_rad[1], 2);
    sa += std::pow(b.dv_mps[2] - a.dv_mps[2], 2);
    ++n;
  }
  const double dt = 0.01;
  EXPECT_NEAR(std::sqrt(sg / n) / (truth.gyro.noise.arw_rad_rts * std::sqrt(dt)), 1.0, 0.03);
  EXPECT_NEAR(std::sqrt(sa / n) / (truth.accel.noise.vrw_mps_rts * std::sqrt(dt)), 1.0, 0.03);
}

// A delayed channel reports the input it had tau earlier: for tau = 3 samples, exactly the ideal
// stream shifted by three samples.
TEST(Simulator, DelaysShiftTheChannel) {
  const auto p = program(R"({"name":"s","segments":[{"type":"hold","duration_s":1},
    {"type":"sine","axis":"outer","amplitude_deg":30,"period_s":2,"cycles":2,"phase_deg":0,"ramp_s":1}]})");
  sim::SimConfig cfg;
  cfg.rate_hz = 1000;
  ImuModel truth;
  truth.gyro.delay_s[2] = 3e-3;
  truth.accel.delay_s[0] = 3e-3;
  sim::Simulator ideal(p, ImuModel{}, cfg), delayed(p, truth, cfg);
  std::vector<ImuFrame> a, b;
  ImuFrame f;
  while (ideal.next(f)) a.push_back(f);
  while (delayed.next(f)) b.push_back(f);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 3; k < a.size(); ++k) {
    EXPECT_NEAR(b[k].dtheta_rad[2], a[k - 3].dtheta_rad[2], 2e-11) << k;
    EXPECT_NEAR(b[k].dtheta_rad[0], a[k].dtheta_rad[0], 2e-11) << k;
  }
}

// Gyro scale asymmetry and misalignment enter as eq. 1 says.
TEST(Simulator, ScaleAndMisalignmentFollowEquationOne) {
  const auto p = program(R"({"name":"r","segments":[{"type":"hold","duration_s":1},
    {"type":"rate","axis":"outer","rate_dps":-40,"revolutions":2,"accel_dps2":80},{"type":"hold","duration_s":1}]})");
  ImuModel truth;
  truth.gyro.scale_neg[2] = 100e-6;
  truth.gyro.scale_pos[2] = -300e-6;
  truth.gyro.misalignment_rad.xy = 50 * units::kArcsecToRad;  // x senses -xy * w_z
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  cfg.site.latitude_deg = 0;  // no vertical Earth rate: gyro z sees the table alone
  sim::Simulator ideal(p, ImuModel{}, cfg), s(p, truth, cfg);
  Vector3d si = Vector3d::Zero(), st = Vector3d::Zero();
  ImuFrame f;
  while (ideal.next(f)) si += f.dtheta_rad;
  while (s.next(f)) st += f.dtheta_rad;
  const double turn = -4 * units::kPi;
  EXPECT_NEAR(st[2] - si[2], 100e-6 * turn, 1e-10);
  EXPECT_NEAR(st[0] - si[0], -50 * units::kArcsecToRad * (1 + 100e-6) * turn, 1e-10);
}

// A proof mass off the rotation axis senses the centripetal acceleration.
TEST(Simulator, ProofMassesSenseCentripetalForce) {
  const auto p = program(R"({"name":"r","segments":[
    {"type":"rate","axis":"outer","rate_dps":90,"duration_s":12,"accel_dps2":90}]})");
  ImuModel truth;
  truth.accel.lever_arm_y_m << 0.0, 0.05, 0.0;  // y proof mass 5 cm along y
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  sim::Simulator ideal(p, ImuModel{}, cfg), s(p, truth, cfg);
  ImuFrame a, b;
  for (int k = 0; k < 600; ++k) {
    ideal.next(a);
    s.next(b);
  }
  const double w = 90 * units::kDegToRad;  // cruising at t = 6 s
  EXPECT_NEAR((b.dv_mps[1] - a.dv_mps[1]) / 0.01, -w * w * 0.05, 1e-4);
}

// The nonlinear terms (CONVENTIONS.md, "Nonlinear terms") in a static of a general pose: each
// accelerometer gains (k2 a + k3 a^2) f_j with a = f_j / g_std, each gyro g-sensitivity G f / g_std;
// against the same run of an ideal IMU, to the quantisation of the sums.
TEST(Simulator, AccelerometerNonlinearityAndGSensitivityInAStatic) {
  const auto p = program(R"({"name":"s","start_deg":[30,40,25],"segments":[{"type":"hold","duration_s":2}]})");
  ImuModel truth;
  truth.accel.k2_per_g << 25e-6, -40e-6, 50e-6;
  truth.accel.k3_per_g2 << 2e-6, -1e-6, 5e-6;
  truth.gyro.g_sensitivity_radps_per_g << 0.004, -0.002, 0.008, 0.001, 0.006, -0.003, -0.005, 0.002, 0.009;
  truth.gyro.g_sensitivity_radps_per_g *= units::kDphToRadps;
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  cfg.site.middle_axis_azimuth_deg = 20;
  sim::Simulator ideal(p, ImuModel{}, cfg), s(p, truth, cfg);
  Vector3d d_th = Vector3d::Zero(), d_v = Vector3d::Zero();
  ImuFrame a, b;
  while (ideal.next(a) && s.next(b)) {
    d_th += b.dtheta_rad - a.dtheta_rad;
    d_v += b.dv_mps - a.dv_mps;
  }
  const Eigen::Matrix3d C_o_n = table::C_p_n(Vector3d(30, 40, 25) * units::kDegToRad, table::C_p0_n(20 * units::kDegToRad));
  const Vector3d f = C_o_n.transpose() * Vector3d(0, 0, earth::site_gravity_mps2(cfg.site));
  ASSERT_GT(f.cwiseAbs().minCoeff(), 2.0);  // every axis sees gravity
  for (int j = 0; j < 3; ++j) {
    const double a_g = f[j] / units::kStandardGravity_mps2;
    const double expected = (truth.accel.k2_per_g[j] * a_g + truth.accel.k3_per_g2[j] * a_g * a_g) * f[j] * 2.0;
    EXPECT_NEAR(d_v[j], expected, 3 * sim::Simulator::kAccelLsbAt1kHz_mps * 10) << j;
  }
  const Vector3d expected_th = truth.gyro.g_sensitivity_radps_per_g * f / units::kStandardGravity_mps2 * 2.0;
  EXPECT_LT((d_th - expected_th).cwiseAbs().maxCoeff(), 3 * sim::Simulator::kGyroLsbAt1kHz_rad * 10);
  EXPECT_GT(expected_th.cwiseAbs().minCoeff(), 100 * sim::Simulator::kGyroLsbAt1kHz_rad * 10);
}

// The gyro scale nonlinearity at 300 deg/s, negative: the scale error is s_neg plus the
// polynomial in |w| / (100 deg/s).
TEST(Simulator, GyroNonlinearityAtFullRate) {
  const auto p = program(R"({"name":"r","segments":[{"type":"hold","duration_s":1},
    {"type":"rate","axis":"outer","rate_dps":-300,"revolutions":5,"accel_dps2":300},{"type":"hold","duration_s":1}]})");
  ImuModel truth;
  truth.gyro.scale_pos[2] = -300e-6;
  truth.gyro.scale_neg[2] = 100e-6;
  truth.gyro.scale_nonlinear.row(2) << 1e-6, 1.2e-6, 0.25e-6;
  sim::SimConfig cfg;
  cfg.rate_hz = 100;
  cfg.site.latitude_deg = 0;  // no vertical Earth rate: gyro z sees the table alone
  sim::Simulator ideal(p, ImuModel{}, cfg), s(p, truth, cfg);
  const double step_deg = -300.0 / cfg.rate_hz;
  double d_th = 0, angle = 0;
  int n = 0;
  ImuFrame a, b;
  double prev_deg = 0;
  int cruising_for = 0;
  while (ideal.next(a) && s.next(b)) {
    cruising_for = std::abs(a.table_deg[0] - prev_deg - step_deg) < 1e-9 ? cruising_for + 1 : 0;
    prev_deg = a.table_deg[0];
    if (cruising_for < 3) continue;  // well inside the constant rate
    d_th += b.dtheta_rad[2] - a.dtheta_rad[2];
    angle += a.dtheta_rad[2];
    ++n;
  }
  ASSERT_GT(n, 300);
  const double q = 3.0, s_expected = 100e-6 + 1e-6 * q + 1.2e-6 * q * q + 0.25e-6 * q * q * q;
  EXPECT_NEAR(d_th, s_expected * angle, 3 * sim::Simulator::kGyroLsbAt1kHz_rad * 10);
}

// A motion signal shared by runs of other seeds (the suite's many-seed tests): the frames are bit
// for bit those each simulator computes itself, and a signal of another bench is refused.
TEST(Simulator, ASharedMotionSignalGivesEachSeedTheFramesItWouldComputeItself) {
  const auto p = program(R"({"name":"osc","start_deg":[10,20,30],"segments":[{"type":"hold","duration_s":1},
    {"type":"sine","axis":"outer","amplitude_deg":90,"period_s":4,"cycles":1,"phase_deg":0,"ramp_s":1},
    {"type":"rate","axis":"middle","rate_dps":30,"revolutions":1,"accel_dps2":60},{"type":"hold","duration_s":1}]})");
  ImuModel truth;
  truth.gyro.delay_s = Vector3d(1e-6, 3e-6, -2e-6);
  truth.accel.delay_s = Vector3d(2e-3, 2.1e-3, 1.9e-3);
  truth.accel.lever_arm_y_m = Vector3d(5e-3, -2e-3, 1e-3);
  truth.gyro.scale_pos = Vector3d(10, -20, 30) * 1e-6;
  truth.gyro.bias_radps = Vector3d(1, 2, 3) * units::kDphToRadps;
  truth.gyro.noise.arw_rad_rts = 0.001 * units::kDegRthToRadRts;
  truth.accel.noise.vrw_mps_rts = 0.002 * units::kMpsRthToMpsRts;
  truth.gyro.noise.bias_instability_radps = 0.001 * units::kDphToRadps;
  sim::SimConfig cfg;
  cfg.rate_hz = 200;
  cfg.mount.r0_p_m = Vector3d(0.05, -0.02, 0.1);
  auto frames = [&](sim::Simulator& s) {
    std::vector<double> out;
    ImuFrame f;
    while (s.next(f)) {
      out.push_back(static_cast<double>(f.t_ns));
      for (int j = 0; j < 3; ++j) out.insert(out.end(), {f.dtheta_rad[j], f.dv_mps[j], f.table_deg[j]});
    }
    return out;
  };
  cfg.seed = 1;
  const std::shared_ptr<const sim::MotionSignal> signal = sim::Simulator(p, truth, cfg).motion_signal();
  for (std::uint64_t seed : {1u, 2u}) {
    cfg.seed = seed;
    sim::Simulator own(p, truth, cfg), shared(p, truth, cfg);
    shared.use_motion_signal(signal);
    EXPECT_EQ(frames(own), frames(shared)) << "seed " << seed;
  }
  // The noise is not the signal's: a noise-free truth shares it too.
  ImuModel quiet = truth;
  quiet.gyro.noise = {};
  quiet.accel.noise = {};
  sim::Simulator own_quiet(p, quiet, cfg), shared_quiet(p, quiet, cfg);
  shared_quiet.use_motion_signal(signal);
  EXPECT_EQ(frames(own_quiet), frames(shared_quiet));

  auto refusal = [&](const ImuModel& t, const sim::SimConfig& c) {
    sim::Simulator s(p, t, c);
    try {
      s.use_motion_signal(signal);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  ImuModel scaled = truth;
  scaled.gyro.scale_pos[1] += 1e-6;
  EXPECT_NE(refusal(scaled, cfg).find("another truth"), std::string::npos) << refusal(scaled, cfg);
  sim::SimConfig other = cfg;
  other.rate_hz = 100;
  EXPECT_NE(refusal(truth, other).find("another rate"), std::string::npos) << refusal(truth, other);
  other = cfg;
  other.mount.r0_p_m.x() += 1e-3;
  EXPECT_NE(refusal(truth, other).find("another mount"), std::string::npos) << refusal(truth, other);
  other = cfg;
  other.site.latitude_deg += 1.0;
  EXPECT_NE(refusal(truth, other).find("another site"), std::string::npos) << refusal(truth, other);
  other = cfg;
  other.duration_s = 2.0;
  EXPECT_NE(refusal(truth, other).find("another length"), std::string::npos) << refusal(truth, other);
  const auto longer = program(R"({"name":"osc","segments":[{"type":"hold","duration_s":9}]})");
  sim::Simulator another_program(longer, truth, cfg);
  EXPECT_THROW(another_program.use_motion_signal(signal), std::invalid_argument);
}
