// Simulated tumbles and their comparison with the truth (test_tumble, test_tumble_long).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "calib_fixture.hpp"
#include "estimators/tumble.hpp"
#include "sim_run.hpp"

namespace imucal::tumbletest {

// A stage-1 IMU with the nonlinear terms the issue names at realistic sizes: K2 20-50 ug/g^2,
// K3 1-5 ug/g^3, g-sensitivity 0.001-0.01 deg/h/g.
inline ImuModel tumble_truth() {
  ImuModel m = calibtest::random_stage1_imu(31);
  m.accel.k2_per_g = Eigen::Vector3d(30, -45, 22) * 1e-6;
  m.accel.k3_per_g2 = Eigen::Vector3d(2.0, -4.5, 1.2) * 1e-6;
  Eigen::Matrix3d G;
  G << 0.008, -0.002, 0.005, 0.001, 0.006, -0.009, -0.004, 0.003, 0.010;
  m.gyro.g_sensitivity_radps_per_g = G * units::kDphToRadps;
  return m;
}

inline tumble::Result run_tumble(const std::string& program, const ImuModel& truth, double rate_hz, std::uint64_t seed) {
  // The prior a stage-1 run gives: the gyro scale factors and angles (what removes the Earth rate).
  ImuModel prior;
  prior.gyro.scale_pos = truth.gyro.scale_pos;
  prior.gyro.scale_neg = truth.gyro.scale_neg;
  prior.gyro.misalignment_rad = truth.gyro.misalignment_rad;
  return simrun::simulate_into<tumble::TumbleEstimator>(program, truth, rate_hz, seed,
                                                        [&](auto& est) { return est.finish(prior); });
}

struct Check {
  double sum_z2 = 0;
  int n = 0;
  bool verbose = true;
  void operator()(const std::string& name, double truth, double est, double sigma, double scale, const char* unit) {
    const double err = (est - truth) * scale, sig = sigma * scale;
    if (sig > 0) {
      sum_z2 += err * err / (sig * sig);
      ++n;
    }
    if (verbose)
      std::printf("  %-34s truth %+12.5f est %+12.5f err %+10.5f sigma %9.5f %s\n", name.c_str(), truth * scale,
                est * scale, err, sig, unit);
    EXPECT_GT(sig, 0.0) << name;
    if (verbose) {
      EXPECT_LE(std::abs(err), 3.0 * sig) << name << ": outside 3 sigma";
    }
  }
};

// Every coefficient the tumble gives against the truth.
inline void check_all(Check& check, const ImuModel& truth, const tumble::Result& r) {
  const ImuErrorSet& sg = *r.model.sigma;
  const char* ax[3] = {"x", "y", "z"};
  for (int j = 0; j < 3; ++j) {
    const std::string a = ax[j];
    check("accel.bias_mps2." + a, truth.accel.bias_mps2[j], r.model.accel.bias_mps2[j], sg.accel.bias_mps2[j], 1e6 / units::kStandardGravity_mps2, "ug");
    check("accel.scale_ppm." + a, truth.accel.scale[j], r.model.accel.scale[j], sg.accel.scale[j], 1e6, "ppm");
    check("accel.k2_ug_per_g2." + a, truth.accel.k2_per_g[j], r.model.accel.k2_per_g[j], sg.accel.k2_per_g[j], 1e6, "ug/g^2");
    check("accel.k3_ug_per_g3." + a, truth.accel.k3_per_g2[j], r.model.accel.k3_per_g2[j], sg.accel.k3_per_g2[j], 1e6, "ug/g^3");
    check("gyro.bias_dph." + a, truth.gyro.bias_radps[j], r.model.gyro.bias_radps[j], sg.gyro.bias_radps[j], units::kRadpsToDph, "deg/h");
    for (int k = 0; k < 3; ++k)
      check("gyro.g_sensitivity_dph_per_g." + a + ax[k], truth.gyro.g_sensitivity_radps_per_g(j, k),
            r.model.gyro.g_sensitivity_radps_per_g(j, k), sg.gyro.g_sensitivity_radps_per_g(j, k), units::kRadpsToDph,
            "deg/h/g");
  }
  for (const auto& [name, k] : kMisalignmentKeys)
    check(std::string("accel.misalignment_arcsec.") + name, truth.accel.misalignment_rad.*k,
          r.model.accel.misalignment_rad.*k, sg.accel.misalignment_rad.*k, units::kRadToArcsec, "arcsec");
}

}  // namespace imucal::tumbletest

