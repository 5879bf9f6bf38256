// Stage 3 consistency over 5 seeds of the stress case (slow): at least 95 % of the coefficients
// within 3 of their own sigma, and the NEES of the calibration states within its chi-square 99 %
// band. The filter is told what the simulated table gives (docs/stage3.md, Honest sigmas): its
// reference is exact, so the table's noise is the strapdown algorithm's floor at 200 Hz, not the
// real-table defaults, which would make every sigma too large (mean NEES 24 of 39); and the
// simulated scale factors are constant, so the filter models no scale-factor random walk (its
// real-sensor default of 1e-9/sqrt(s) adds 0.1 ppm over the program that the truth does not have).
#include <gtest/gtest.h>

#include "nav_calib_fixture.hpp"

using namespace imucal;

TEST(NavFilterConsistency, FiveSeeds) {
  constexpr int kSeeds = 5;
  int inside = 0, total = 0;
  double nees_sum = 0;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    const auto s = navcaltest::make_stress_scenario(static_cast<unsigned>(seed), 200);
    Eigen::Matrix<double, 6, 1> drift = Eigen::Matrix<double, 6, 1>::Zero();
    navfilter::Options simulated_table;
    simulated_table.velocity_noise_mps = 1e-5;
    simulated_table.position_noise_m = 1e-4;
    simulated_table.attitude_noise_rad = 0.05 * units::kArcsecToRad;
    simulated_table.scale_rw_rts = 0.0;
    const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1, 0, &drift, simulated_table);
    ASSERT_TRUE(r.converged) << r.status;
    // The truth the filter should end at: the constant coefficients plus the biases' drift.
    navfilter::StateVector truth = navfilter::model_to_state(s.truth_body);
    truth.segment<3>(navfilter::state::kGyroBias.index) += drift.head<3>();
    truth.segment<3>(navfilter::state::kAccelBias.index) += drift.tail<3>();
    constexpr int kN = navfilter::state::kCalibrationSize;
    const Eigen::Matrix<double, kN, 1> e = (r.model_values - truth).tail<kN>();
    const double nees = e.dot(r.P_calibration.ldlt().solve(e));
    nees_sum += nees;
    int seed_inside = 0;
    for (int i = 0; i < kN; ++i) {
      const double sigma = std::sqrt(r.P_calibration(i, i));
      const bool ok = std::abs(e[i]) <= 3 * sigma;
      seed_inside += ok;
      if (!ok) std::printf("seed %d: state %d error %.3g = %.1f sigma\n", seed, 9 + i, e[i], e[i] / sigma);
    }
    inside += seed_inside;
    total += kN;
    std::printf("seed %d: NEES %.1f, %d/%d within 3 sigma\n", seed, nees, seed_inside, kN);
  }
  const double mean_nees = nees_sum / kSeeds;
  // The sum of 5 NEES is chi-square with 5 N degrees of freedom: its 0.5 % and 99.5 % quantiles.
  const int dof = kSeeds * navfilter::state::kCalibrationSize;
  const double lo = navcaltest::chi2_quantile(dof, -2.5758) / kSeeds, hi = navcaltest::chi2_quantile(dof, 2.5758) / kSeeds;
  std::printf("mean NEES %.1f (%d states; 99 %% band of the mean of %d: [%.1f, %.1f])\n", mean_nees,
              navfilter::state::kCalibrationSize, kSeeds, lo, hi);
  EXPECT_GE(static_cast<double>(inside) / total, 0.95);
  EXPECT_GE(mean_nees, lo);
  EXPECT_LE(mean_nees, hi);
}
