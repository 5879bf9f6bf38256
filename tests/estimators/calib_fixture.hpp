// Random IMUs of the sizes the issues name, and comparison of a calibration against its truth.
#pragma once

#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/imu_model.hpp"
#include "core/units.hpp"
#include "estimators/direct_calibration.hpp"

namespace imucal::calibtest {

// Stage-1 acceptance IMU: gyro bias ~0.05 deg/h, scale ~50 ppm with ~10 ppm asymmetry, angles ~30";
// accelerometer bias ~5e-4 m/s^2, scale ~100 ppm, angles ~30"; ARW 0.0005 deg/rt-h, VRW 0.002 m/s/rt-h.
inline ImuModel random_stage1_imu(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  using namespace units;
  ImuModel m;
  for (int j = 0; j < 3; ++j) {
    m.gyro.bias_radps[j] = 0.05 * n01(rng) * kDphToRadps;
    const double s = 50e-6 * n01(rng), asym = 10e-6 * n01(rng);
    m.gyro.scale_pos[j] = s + asym;
    m.gyro.scale_neg[j] = s - asym;
    m.accel.bias_mps2[j] = 5e-4 * n01(rng);
    m.accel.scale[j] = 100e-6 * n01(rng);
  }
  for (Misalignment* mis : {&m.gyro.misalignment_rad, &m.accel.misalignment_rad})
    for (const MisalignmentKey& key : kMisalignmentKeys)
      mis->*key.member = 30.0 * n01(rng) * kArcsecToRad;
  m.gyro.noise.arw_rad_rts = 0.0005 * kDegRthToRadRts;
  m.accel.noise.vrw_mps_rts = 0.002 * kMpsRthToMpsRts;
  return m;
}

// Limits by group: gyro bias deg/h, scale ppm, angles arcsec; accelerometer bias m/s^2, scale ppm,
// angles arcsec.
using Limits = direct::Limits;

// Every coefficient within its limit and within 3 of its own sigma; prints a table of errors.
inline void expect_within(const ImuModel& truth, const ImuModel& est, const Limits& lim, bool check_sigma = true) {
  using namespace units;
  ASSERT_TRUE(est.sigma.has_value());
  const ImuErrorSet& sg = *est.sigma;
  auto check = [&](const std::string& name, double t, double e, double s, double scale, double limit) {
    const double err = (e - t) * scale, sig = s * scale;
    std::printf("  %-22s truth %+12.6f est %+12.6f err %+10.6f sigma %9.6f\n", name.c_str(), t * scale, e * scale,
                err, sig);
    EXPECT_LE(std::abs(err), limit) << name;
    if (check_sigma) {
      EXPECT_GT(sig, 0.0) << name << ": sigma must be positive";
      EXPECT_LE(std::abs(err), 3.0 * sig) << name << ": outside 3 sigma";
    }
  };
  const char* ax[3] = {"x", "y", "z"};
  for (int j = 0; j < 3; ++j) {
    check(std::string("gyro.bias_dph.") + ax[j], truth.gyro.bias_radps[j], est.gyro.bias_radps[j],
          sg.gyro.bias_radps[j], kRadpsToDph, lim.gyro_bias_dph);
    check(std::string("gyro.scale_pos_ppm.") + ax[j], truth.gyro.scale_pos[j], est.gyro.scale_pos[j],
          sg.gyro.scale_pos[j], 1e6, lim.gyro_scale_ppm);
    check(std::string("gyro.scale_neg_ppm.") + ax[j], truth.gyro.scale_neg[j], est.gyro.scale_neg[j],
          sg.gyro.scale_neg[j], 1e6, lim.gyro_scale_ppm);
    check(std::string("accel.bias_mps2.") + ax[j], truth.accel.bias_mps2[j], est.accel.bias_mps2[j],
          sg.accel.bias_mps2[j], 1.0, lim.accel_bias_mps2);
    check(std::string("accel.scale_ppm.") + ax[j], truth.accel.scale[j], est.accel.scale[j], sg.accel.scale[j], 1e6,
          lim.accel_scale_ppm);
  }
  for (const auto& [name, k] : kMisalignmentKeys) {
    check(std::string("gyro.misalignment.") + name, truth.gyro.misalignment_rad.*k, est.gyro.misalignment_rad.*k,
          sg.gyro.misalignment_rad.*k, kRadToArcsec, lim.gyro_angle_arcsec);
    check(std::string("accel.misalignment.") + name, truth.accel.misalignment_rad.*k, est.accel.misalignment_rad.*k,
          sg.accel.misalignment_rad.*k, kRadToArcsec, lim.accel_angle_arcsec);
  }
}

inline const Limits kStage1Limits{};  // stage 1's own (direct::Limits)

// |error| / sigma of the 27 linear coefficients stage 1 estimates: per axis gyro bias, scale +,
// scale -, accelerometer bias, scale; then per angle gyro, accelerometer.
inline std::vector<double> stage1_abs_z(const ImuModel& truth, const ImuModel& est, const ImuErrorSet& s) {
  std::vector<double> z;
  auto add = [&](double t, double e, double sigma) { z.push_back(std::abs(e - t) / sigma); };
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

}  // namespace imucal::calibtest
