// Stage 3 consistency over 5 seeds (slow): at least 95 % of the coefficients within 3 of their own
// sigma, and the NEES of the 30 calibration states within its chi-square 99 % band.
#include <gtest/gtest.h>

#include "nav_calib_fixture.hpp"

using namespace imucal;

TEST(NavFilterConsistency, FiveSeeds) {
  constexpr int kSeeds = 5;
  int inside = 0, total = 0;
  double nees_sum = 0;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    const auto s = navcaltest::make_scenario(static_cast<unsigned>(100 + seed), 200);
    Eigen::Matrix<double, 6, 1> drift = Eigen::Matrix<double, 6, 1>::Zero();
    const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1, 0, &drift);
    ASSERT_TRUE(r.converged) << r.status;
    // The truth the filter should end at: the constant coefficients plus the biases' drift.
    navfilter::StateVector truth = navfilter::model_to_state(s.truth_body);
    truth.segment<3>(navfilter::state::kGyroBias.index) += drift.head<3>();
    truth.segment<3>(navfilter::state::kAccelBias.index) += drift.tail<3>();
    const Eigen::Matrix<double, 30, 1> e = (r.model_values - truth).tail<30>();
    const double nees = e.dot(r.P_calibration.ldlt().solve(e));
    nees_sum += nees;
    int seed_inside = 0;
    for (int i = 0; i < 30; ++i) {
      const double sigma = std::sqrt(r.P_calibration(i, i));
      const bool ok = std::abs(e[i]) <= 3 * sigma;
      seed_inside += ok;
      if (!ok) std::printf("seed %d: state %d error %.3g = %.1f sigma\n", seed, 9 + i, e[i], e[i] / sigma);
    }
    inside += seed_inside;
    total += 30;
    std::printf("seed %d: NEES %.1f, %d/30 within 3 sigma\n", seed, nees, seed_inside);
  }
  const double mean_nees = nees_sum / kSeeds;
  std::printf("mean NEES %.1f (chi-square 30 dof; 99 %% band of the mean of 5: [22.1, 39.2])\n", mean_nees);
  EXPECT_GE(static_cast<double>(inside) / total, 0.95);
  // chi2(150) 0.5 % and 99.5 % quantiles are 110.5 and 196.0; divided by 5.
  EXPECT_GE(mean_nees, 110.5 / kSeeds);
  EXPECT_LE(mean_nees, 196.0 / kSeeds);
}
