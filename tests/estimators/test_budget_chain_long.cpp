// Stage 1's budget of the start model's terms (issue 34): the chain direct -> rate-steps -> tumble
// -> direct on IMUs with nonlinear terms. The last stage 1 removes the scale nonlinearity, K2, K3
// and g-sensitivity the rate-steps test and the tumble found, and their sigmas must reach its own:
// before the budget an accelerometer scale factor ended 6-8 sigma off.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <random>
#include <vector>

#include "calib_fixture.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/rate_steps.hpp"
#include "estimators/tumble.hpp"
#include "sim_run.hpp"

using namespace imucal;

namespace {

// A stage-1 IMU with the nonlinear terms the issue names at realistic sizes, drawn per seed:
// a quadratic gyro scale nonlinearity (5-20 ppm at 300 deg/s), K2 20-50 ug/g^2, K3 1-5 ug/g^3,
// g-sensitivity 0.001-0.01 deg/h/g.
ImuModel nonlinear_imu(unsigned seed) {
  ImuModel m = calibtest::random_stage1_imu(seed);
  std::mt19937_64 rng(seed + 7);
  std::normal_distribution<double> n01;
  for (int j = 0; j < 3; ++j) {
    m.gyro.scale_nonlinear.row(j) = Eigen::RowVector3d(3.0 * n01(rng), 1.5 * n01(rng), 0.0) * 1e-6;
    m.accel.k2_per_g[j] = 35e-6 * n01(rng);
    m.accel.k3_per_g2[j] = 3e-6 * n01(rng);
    for (int k = 0; k < 3; ++k) m.gyro.g_sensitivity_radps_per_g(j, k) = 0.005 * n01(rng) * units::kDphToRadps;
  }
  return m;
}

// |error| / sigma of the 27 linear coefficients stage 1 estimates.
std::vector<double> z_of(const ImuModel& truth, const ImuModel& est) {
  const ImuErrorSet& s = *est.sigma;
  std::vector<double> z;
  auto add = [&](double t, double e, double sigma) { z.push_back(std::abs(e - t) / sigma); };
  // (the order below: per axis gyro bias, scale +, scale -, accel bias, scale; then per angle
  // gyro, accel)
  for (int j = 0; j < 3; ++j) {
    add(truth.gyro.bias_radps[j], est.gyro.bias_radps[j], s.gyro.bias_radps[j]);
    add(truth.gyro.scale_pos[j], est.gyro.scale_pos[j], s.gyro.scale_pos[j]);
    add(truth.gyro.scale_neg[j], est.gyro.scale_neg[j], s.gyro.scale_neg[j]);
    add(truth.accel.bias_mps2[j], est.accel.bias_mps2[j], s.accel.bias_mps2[j]);
    add(truth.accel.scale[j], est.accel.scale[j], s.accel.scale[j]);
  }
  for (const auto& [name, k] : kMisalignmentKeys) {
    add(truth.gyro.misalignment_rad.*k, est.gyro.misalignment_rad.*k, s.gyro.misalignment_rad.*k);
    add(truth.accel.misalignment_rad.*k, est.accel.misalignment_rad.*k, s.accel.misalignment_rad.*k);
  }
  return z;
}

ImuModel direct_stage(const ImuModel& truth, std::uint64_t seed, const ImuModel& start) {
  return simrun::simulate_into<direct::DirectCalibrator>("direct", truth, 20, seed,
                                                         [&](auto& est) { return est.finish(start).model; });
}

}  // namespace

TEST(BudgetChainLong, StartModelTermsReachStageOnesSigma) {
  std::size_t n = 0, within = 0, within_type_a = 0;
  double worst = 0, worst_type_a = 0;
  const char* only = std::getenv("IMUCAL_CHAIN_IMU");  // one IMU, to look at it
  for (unsigned i = 0; i < 20; ++i) {
    if (only && std::to_string(i) != only) continue;
    const ImuModel truth = nonlinear_imu(900 + i);
    const std::uint64_t seed = 1000 + 10 * i;
    const ImuModel first = direct_stage(truth, seed, ImuModel{});
    const ImuModel steps = simrun::simulate_into<rate_steps::RateStepsEstimator>(
        "rate-steps", truth, 100, seed + 1, [&](auto& est) { return est.finish(first).model; });
    const ImuModel tumbled = simrun::simulate_into<tumble::TumbleEstimator>(
        "tumble", truth, 100, seed + 2, [&](auto& est) { return est.finish(steps).model; });
    const ImuModel last = direct_stage(truth, seed + 3, tumbled);
    ASSERT_TRUE(last.budget.count("start_model.accel.k3_ug_per_g3")) << "the tumble's K3 sigma is in the budget";
    ImuModel type_a = last;
    type_a.sigma = last.budget.at("type_a");
    const std::vector<double> z = z_of(truth, last), z_a = z_of(truth, type_a);
    const auto count3 = [](const std::vector<double>& v) {
      return static_cast<std::size_t>(std::count_if(v.begin(), v.end(), [](double x) { return x <= 3.0; }));
    };
    const double w = *std::max_element(z.begin(), z.end()), w_a = *std::max_element(z_a.begin(), z_a.end());
    std::printf("IMU %u: within 3 sigma %zu of %zu (worst %.2f); type A alone %zu (worst %.2f)\n", i, count3(z), z.size(),
                w, count3(z_a), w_a);
    for (std::size_t c = 0; c < z.size(); ++c)
      if (z[c] > 3.0) std::printf("  coefficient %zu at %.2f sigma (type A alone %.2f)\n", c, z[c], z_a[c]);
    EXPECT_LE(w, 4.0) << "IMU " << i;
    n += z.size();
    within += count3(z);
    within_type_a += count3(z_a);
    worst = std::max(worst, w);
    worst_type_a = std::max(worst_type_a, w_a);
  }
  std::printf("all: within 3 sigma %zu of %zu (%.1f %%, worst %.2f); type A alone %zu (%.1f %%, worst %.2f)\n", within, n,
              100.0 * static_cast<double>(within) / static_cast<double>(n), worst, within_type_a,
              100.0 * static_cast<double>(within_type_a) / static_cast<double>(n), worst_type_a);
  EXPECT_GE(static_cast<double>(within), 0.95 * static_cast<double>(n));
}
