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
#include <utility>
#include <vector>

#include "calib_fixture.hpp"
#include "core/expect_value.hpp"
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

// |error| / sigma of the 27 linear coefficients stage 1 estimates, against the model's own sigma.
std::vector<double> z_of(const ImuModel& truth, const ImuModel& est) {
  return calibtest::stage1_abs_z(truth, est, expect_value(est.sigma, "the sigma of a stage-1 result"));
}

ImuModel direct_stage(const ImuModel& truth, std::uint64_t seed, const ImuModel& start) {
  return simrun::simulate_into<direct::DirectCalibrator>("direct", truth, 20, seed,
                                                         [&](auto& est) { return est.finish(start).model; });
}

}  // namespace

namespace {

// |error| / sigma of the 27 linear coefficients of the last stage 1 of the chain, per IMU, with its
// combined sigma (`z`) and with the fit's own alone (`z_type_a`, all the sigma said before).
struct ChainOutcome {
  std::vector<std::vector<double>> z, z_type_a;
};
ChainOutcome run_chains() {
  ChainOutcome out;
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
    EXPECT_TRUE(last.budget.count("start_model.accel.k3_ug_per_g3")) << "the tumble's K3 sigma is in the budget";
    ImuModel type_a = last;
    type_a.sigma = last.budget.at("type_a");
    out.z.push_back(z_of(truth, last));
    out.z_type_a.push_back(z_of(truth, type_a));
    const std::vector<double>&z = out.z.back(), &z_a = out.z_type_a.back();
    for (std::size_t c = 0; c < z.size(); ++c)
      if (z[c] > 3.0) std::printf("IMU %u: coefficient %zu at %.2f sigma (type A alone %.2f)\n", i, c, z[c], z_a[c]);
    const ImuErrorSet& tumbled_sigma = expect_value(tumbled.sigma, "the sigma of the tumble's result");
    for (int j = 0; j < 3; ++j)
      std::printf("IMU %u gyro %d: c1 c2 truth %+.3f %+.3f, the rate-steps test's %+.3f %+.3f (sigma %.3f %.3f) ppm\n", i,
                  j, truth.gyro.scale_nonlinear(j, 0) * 1e6, truth.gyro.scale_nonlinear(j, 1) * 1e6,
                  tumbled.gyro.scale_nonlinear(j, 0) * 1e6, tumbled.gyro.scale_nonlinear(j, 1) * 1e6,
                  tumbled_sigma.gyro.scale_nonlinear(j, 0) * 1e6, tumbled_sigma.gyro.scale_nonlinear(j, 1) * 1e6);
  }
  return out;
}

// Within k sigma, and the largest z, over every IMU.
std::pair<std::size_t, double> within(const std::vector<std::vector<double>>& zs, double k, std::size_t& n) {
  std::size_t in = 0;
  double worst = 0;
  n = 0;
  for (const auto& z : zs)
    for (const double x : z) {
      ++n;
      in += x <= k;
      worst = std::max(worst, x);
    }
  return {in, worst};
}

}  // namespace

// At least 95 % of the linear coefficients within 3 sigma over twenty IMUs, none beyond 4.
// Measured 540 of 540, the worst at 2.93 sigma (the fit's own sigma alone: 512, 94.8 %, the worst
// at 12 sigma). Before the rate-steps test's degree rule found the terms the data holds, two IMUs
// (1 and 9) ended with a gyro's scale factors at 7-8 sigma: that test had kept the gyro linear
// and stated neither a term nor a sigma, so the start model had nothing for stage 1 to carry.
TEST(BudgetChainLong, StartModelTermsReachStageOnesSigma) {
  const ChainOutcome out = run_chains();
  std::size_t n = 0;
  const auto [in, worst] = within(out.z, 3.0, n);
  const auto [in_a, worst_a] = within(out.z_type_a, 3.0, n);
  std::printf("all: within 3 sigma %zu of %zu (%.1f %%, worst %.2f); type A alone %zu (%.1f %%, worst %.2f)\n", in, n,
              100.0 * static_cast<double>(in) / static_cast<double>(n), worst, in_a,
              100.0 * static_cast<double>(in_a) / static_cast<double>(n), worst_a);
  EXPECT_GE(static_cast<double>(in), 0.95 * static_cast<double>(n));
  for (std::size_t i = 0; i < out.z.size(); ++i)
    EXPECT_LE(*std::max_element(out.z[i].begin(), out.z[i].end()), 4.0) << "IMU " << i;
}
