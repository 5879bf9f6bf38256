// Simulated rate-steps runs and their comparison with the truth (test_rate_steps, test_rate_steps_long).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <Eigen/QR>

#include "calib_fixture.hpp"
#include "estimators/rate_steps.hpp"
#include "sim_run.hpp"

namespace imucal::ratestepstest {

// A stage-1 IMU whose gyros have the scale nonlinearity the issue names (5-20 ppm at 300 deg/s):
// x none at all (the test must not invent one), y and z quadratic of two shapes.
inline ImuModel nonlinear_truth() {
  ImuModel m = calibtest::random_stage1_imu(21);
  m.gyro.scale_nonlinear.row(1) = Eigen::RowVector3d(3.0, 1.0, 0.0) * 1e-6;   // 18 ppm at 300 deg/s
  m.gyro.scale_nonlinear.row(2) = Eigen::RowVector3d(-4.0, 2.5, 0.0) * 1e-6;  // 10.5 ppm at 300 deg/s
  return m;
}

inline double truth_scale_ppm(const ImuModel& m, int j, double rate_dps) {
  const double q = std::abs(rate_dps) / 100.0;
  double s = rate_dps >= 0 ? m.gyro.scale_pos[j] : m.gyro.scale_neg[j];
  for (int k = 0; k < 3; ++k) s += m.gyro.scale_nonlinear(j, k) * std::pow(q, k + 1);
  return s * 1e6;
}

// IEEE 952's figure from scale errors at rates: the largest deviation of (1 + s) r from its
// least-squares line, in ppm of the full-scale output.
inline double ieee_nonlinearity_ppm(const std::vector<double>& rates_dps, const std::vector<double>& scale_ppm) {
  const auto n = static_cast<Eigen::Index>(rates_dps.size());
  Eigen::MatrixXd A(n, 2);
  Eigen::VectorXd o(n);
  double fs = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    A(i, 0) = rates_dps[k];
    A(i, 1) = 1.0;
    o[i] = (1.0 + scale_ppm[k] * 1e-6) * rates_dps[k];
    fs = std::max(fs, std::abs(rates_dps[k]));
  }
  const Eigen::VectorXd line = A.colPivHouseholderQr().solve(o);
  return (o - A * line).cwiseAbs().maxCoeff() / (std::abs(line[0]) * fs) * 1e6;
}

inline rate_steps::Result run_rate_steps(const std::string& program, const ImuModel& truth, double rate_hz,
                                  std::uint64_t seed) {
  // The prior a stage-1 run would give: the gyro misalignments (to 0.3"), nothing of the scales.
  ImuModel prior;
  prior.gyro.misalignment_rad = truth.gyro.misalignment_rad;
  return simrun::simulate_into<rate_steps::RateStepsEstimator>(program, truth, rate_hz, seed,
                                                               [&](auto& est) { return est.finish(prior); });
}

// Every step's scale at its rate, the fitted model there, the scale factors, the asymmetry and the
// IEEE 952 nonlinearity of every gyro within 3 sigma of the truth.
inline void expect_truth_within_3_sigma(const ImuModel& truth, const rate_steps::Result& r, std::size_t steps_per_axis) {
  for (const auto& n : r.notes) std::printf("%s\n", n.c_str());
  for (int j = 0; j < 3; ++j) {
    const rate_steps::Axis& ax = r.axes[static_cast<std::size_t>(j)];
    ASSERT_TRUE(ax.tested) << "gyro " << j;
    std::printf("gyro %d: degree %d, s+ %+.3f (truth %+.3f) +- %.3f, s- %+.3f (truth %+.3f) +- %.3f ppm, "
                "residual rms %.3f ppm\n",
                j, ax.degree, ax.scale_pos_ppm, truth.gyro.scale_pos[j] * 1e6, ax.scale_pos_sigma_ppm,
                ax.scale_neg_ppm, truth.gyro.scale_neg[j] * 1e6, ax.scale_neg_sigma_ppm, ax.residual_rms_ppm);
    for (const auto& sc : ax.scores) std::printf("  degree %d: held-back rms %.3f ppm\n", sc.degree, sc.held_back_rms_ppm);
    for (int k = 0; k < ax.degree; ++k)
      std::printf("  c%d %+.3f +- %.3f ppm (truth %+.3f)\n", k + 1, ax.nonlinear_ppm[static_cast<std::size_t>(k)],
                  ax.nonlinear_sigma_ppm[static_cast<std::size_t>(k)], truth.gyro.scale_nonlinear(j, k) * 1e6);
    EXPECT_EQ(ax.steps.size(), steps_per_axis);
    std::vector<double> rates, truth_ppm;
    for (const rate_steps::Step& st : ax.steps) {
      const double t = truth_scale_ppm(truth, j, st.rate_dps);
      double model_sigma = 0;
      const double model = ax.scale_ppm_at(st.rate_dps, &model_sigma);
      std::printf("  %-14s %+8.2f deg/s  step %+9.3f +- %.3f  model %+9.3f +- %.3f  truth %+9.3f ppm\n",
                  st.segment.c_str(), st.rate_dps, st.scale_ppm, st.sigma_ppm, model, model_sigma, t);
      EXPECT_GT(st.sigma_ppm, 0.0);
      EXPECT_LE(std::abs(st.scale_ppm - t), 3.0 * st.sigma_ppm) << st.segment;
      EXPECT_LE(std::abs(model - t), 3.0 * model_sigma) << st.segment;
      rates.push_back(st.rate_dps);
      truth_ppm.push_back(t);
    }
    EXPECT_NEAR(ax.scale_pos_ppm, truth.gyro.scale_pos[j] * 1e6, 3.0 * ax.scale_pos_sigma_ppm);
    EXPECT_NEAR(ax.scale_neg_ppm, truth.gyro.scale_neg[j] * 1e6, 3.0 * ax.scale_neg_sigma_ppm);
    EXPECT_NEAR(ax.asymmetry_ppm, (truth.gyro.scale_pos[j] - truth.gyro.scale_neg[j]) * 1e6, 3.0 * ax.asymmetry_sigma_ppm);
    // The seed's figure for a scale factor, 0.5 ppm (here at zero rate, the constant of the model).
    EXPECT_LE(ax.scale_pos_sigma_ppm, 0.5);
    EXPECT_LE(ax.scale_neg_sigma_ppm, 0.5);
    const double nl_truth = ieee_nonlinearity_ppm(rates, truth_ppm);
    std::printf("  IEEE 952 nonlinearity %.3f +- %.3f ppm FS at %+.0f deg/s (truth %.3f)\n", ax.nonlinearity_ppm_fs,
                ax.nonlinearity_sigma_ppm_fs, ax.nonlinearity_at_dps, nl_truth);
    EXPECT_NEAR(ax.nonlinearity_ppm_fs, nl_truth, 3.0 * ax.nonlinearity_sigma_ppm_fs);
  }
  // The model carries what the test found, with sigma.
  ASSERT_TRUE(r.model.sigma.has_value());
  for (int j = 0; j < 3; ++j) {
    const rate_steps::Axis& ax = r.axes[static_cast<std::size_t>(j)];
    EXPECT_DOUBLE_EQ(r.model.gyro.scale_pos[j] * 1e6, ax.scale_pos_ppm);
    for (int k = 0; k < 3; ++k) {
      if (k < ax.degree) {
        EXPECT_GT(r.model.sigma->gyro.scale_nonlinear(j, k), 0.0);
        EXPECT_NEAR(r.model.gyro.scale_nonlinear(j, k), truth.gyro.scale_nonlinear(j, k),
                    3.0 * r.model.sigma->gyro.scale_nonlinear(j, k));
      } else {
        EXPECT_EQ(r.model.gyro.scale_nonlinear(j, k), 0.0);
      }
    }
  }
}

}  // namespace imucal::ratestepstest

