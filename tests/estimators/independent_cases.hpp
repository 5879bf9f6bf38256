// Shared by test_direct_independent (short) and test_direct_independent_long (slow): a random IMU
// of the stage-1 issue's sizes for the independent generator, the stage-1 program it runs, and the
// path a bundle takes through the project (import, then stage direct as the command line runs it).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "calib_fixture.hpp"
#include "estimators/direct_calibration.hpp"
#include "independent_bundle.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

namespace imucal_test::cases {

using namespace imucal;

// A random IMU of the stage-1 issue's sizes, drawn in the units of imucal-imu-model/1.
inline gen::Truth random_truth(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  gen::Truth t;
  for (std::size_t j = 0; j < 3; ++j) {
    t.gyro_bias_dph[j] = 0.05 * n01(rng);
    const double scale = 50.0 * n01(rng), asymmetry = 10.0 * n01(rng);
    t.gyro_scale_pos_ppm[j] = scale + asymmetry;
    t.gyro_scale_neg_ppm[j] = scale - asymmetry;
    t.accel_bias_mps2[j] = 5e-4 * n01(rng);
    t.accel_scale_ppm[j] = 100.0 * n01(rng);
  }
  for (gen::Angles* a : {&t.gyro_angles_arcsec, &t.accel_angles_arcsec})
    for (double* v : {&a->xy, &a->xz, &a->yx, &a->yz, &a->zx, &a->zy}) *v = 30.0 * n01(rng);
  t.arw_deg_rth = 0.0005;
  t.vrw_mps_rth = 0.002;
  return t;
}

// The same truth as the project's ImuModel (SI), converted here, not through the project's JSON.
inline ImuModel to_model(const gen::Truth& t) {
  const double deg = std::numbers::pi / 180.0, arcsec = deg / 3600.0;
  ImuModel m;
  for (int j = 0; j < 3; ++j) {
    const auto i = static_cast<std::size_t>(j);
    m.gyro.bias_radps[j] = t.gyro_bias_dph[i] * deg / 3600.0;
    m.gyro.scale_pos[j] = t.gyro_scale_pos_ppm[i] * 1e-6;
    m.gyro.scale_neg[j] = t.gyro_scale_neg_ppm[i] * 1e-6;
    m.accel.bias_mps2[j] = t.accel_bias_mps2[i];
    m.accel.scale[j] = t.accel_scale_ppm[i] * 1e-6;
  }
  auto angles = [&](const gen::Angles& a) {
    return Misalignment{a.xy * arcsec, a.xz * arcsec, a.yx * arcsec, a.yz * arcsec, a.zx * arcsec, a.zy * arcsec};
  };
  m.gyro.misalignment_rad = angles(t.gyro_angles_arcsec);
  m.accel.misalignment_rad = angles(t.accel_angles_arcsec);
  return m;
}

// A multi-position and rate program in the spirit of stage 1: 24 positions (each IMU axis up and
// down, four headings each) reached by single-axis turns, and +-3 turns about the vertical with
// each IMU axis up. 30 holds of `hold_s`.
inline std::vector<gen::Step> direct_program(double hold_s) {
  std::vector<gen::Step> steps;
  int holds = 0, moves = 0;
  auto hold = [&] {
    char name[32];
    std::snprintf(name, sizeof name, "pos-%02d", ++holds);
    steps.push_back({name, "static", -1, hold_s, 0, 0, 0});
  };
  auto turn = [&](int axis, double deg) {
    char name[32];
    std::snprintf(name, sizeof name, "move-%02d", ++moves);
    steps.push_back({name, "move", axis, 0, deg, 10.0, 2.0});
    hold();
  };
  auto rate_runs = [&](const char* axis_name) {
    for (const double sign : {+1.0, -1.0}) {
      steps.push_back({std::string("rate-") + axis_name + (sign > 0 ? "+" : "-"), "rate", 0, 0, sign * 1080.0, 20.0,
                       2.0});
      hold();
    }
  };
  enum { kOuter = 0, kMiddle = 1, kInner = 2 };
  auto headings = [&](double step_deg) {
    for (int i = 0; i < 3; ++i) turn(kOuter, step_deg);
  };
  hold();                                     // z up
  headings(+90);
  rate_runs("z");
  turn(kMiddle, +90);                         // y up
  headings(-90);
  rate_runs("y");
  turn(kInner, +90);                          // x up
  headings(+90);
  rate_runs("x");
  turn(kMiddle, -180);                        // x down
  headings(-90);
  turn(kInner, -90);                          // y down
  headings(+90);
  turn(kMiddle, -90);                         // z down
  headings(-90);
  return steps;
}

struct Outcome {
  direct::Result result;
  storage::ImportReport import;
};

// Import the bundle into a fresh run and calibrate it as `imucal calibrate --stage direct` does.
inline Outcome import_and_calibrate(const std::string& bundle_dir, const std::string& name) {
  const std::string db = imucaltest::test_tmp_dir() + "/" + name + ".db";
  std::filesystem::remove(db);
  Outcome out;
  out.import = storage::import_bundle(bundle_dir, db);
  const auto run = storage::RunDb::open(db);
  RecordingMeta meta = run.meta();
  const bool has_statics = std::any_of(meta.segments.begin(), meta.segments.end(),
                                       [](const SegmentInfo& s) { return s.kind == "static" || s.kind == "tilt"; });
  if (!has_statics) {
    direct::SegmentDetector detector;
    run.for_each_frame([&](const ImuFrame& f) { detector.push(f); });
    meta.segments = detector.finish();
  }
  direct::DirectCalibrator cal(meta);
  run.for_each_frame([&](const ImuFrame& f) { cal.push(f); });
  out.result = cal.finish();
  return out;
}

// The largest error of each group of coefficients, with that coefficient's sigma, in the units of
// the limits: group -> {|error|, sigma}.
using Worst = std::map<std::string, std::pair<double, double>>;
inline Worst worst_errors(const ImuModel& truth, const ImuModel& est) {
  const ImuErrorSet& s = *est.sigma;
  const double rad_to_dph = 180.0 / std::numbers::pi * 3600.0, rad_to_arcsec = rad_to_dph;
  Worst worst;
  auto note = [&](const std::string& group, double t, double e, double sigma, double scale) {
    auto& w = worst[group];
    if (std::abs(e - t) * scale >= w.first) w = {std::abs(e - t) * scale, sigma * scale};
  };
  for (int j = 0; j < 3; ++j) {
    note("gyro bias deg/h", truth.gyro.bias_radps[j], est.gyro.bias_radps[j], s.gyro.bias_radps[j], rad_to_dph);
    note("gyro scale ppm", truth.gyro.scale_pos[j], est.gyro.scale_pos[j], s.gyro.scale_pos[j], 1e6);
    note("gyro scale ppm", truth.gyro.scale_neg[j], est.gyro.scale_neg[j], s.gyro.scale_neg[j], 1e6);
    note("accel bias m/s^2", truth.accel.bias_mps2[j], est.accel.bias_mps2[j], s.accel.bias_mps2[j], 1.0);
    note("accel scale ppm", truth.accel.scale[j], est.accel.scale[j], s.accel.scale[j], 1e6);
  }
  for (double Misalignment::*k : {&Misalignment::xy, &Misalignment::xz, &Misalignment::yx, &Misalignment::yz,
                                  &Misalignment::zx, &Misalignment::zy}) {
    note("gyro angles arcsec", truth.gyro.misalignment_rad.*k, est.gyro.misalignment_rad.*k,
         s.gyro.misalignment_rad.*k, rad_to_arcsec);
    note("accel angles arcsec", truth.accel.misalignment_rad.*k, est.accel.misalignment_rad.*k,
         s.accel.misalignment_rad.*k, rad_to_arcsec);
  }
  return worst;
}

inline double limit_of(const std::string& group, const calibtest::Limits& l) {
  if (group == "gyro bias deg/h") return l.gyro_bias_dph;
  if (group == "gyro scale ppm") return l.gyro_scale_ppm;
  if (group == "gyro angles arcsec") return l.gyro_angle_arcsec;
  if (group == "accel bias m/s^2") return l.accel_bias_mps2;
  if (group == "accel scale ppm") return l.accel_scale_ppm;
  return l.accel_angle_arcsec;
}

inline void print_worst(const ImuModel& truth, const ImuModel& est) {
  for (const auto& [group, w] : worst_errors(truth, est))
    std::printf("  worst %-20s error %.3g (its sigma %.3g)\n", group.c_str(), w.first, w.second);
}

inline gen::Config direct_config(unsigned truth_seed, double rate_hz, double hold_s) {
  gen::Config cfg;
  cfg.site.latitude_deg = 55.7;
  cfg.site.longitude_deg = 37.6;
  cfg.site.height_m = 150;
  cfg.site.middle_axis_azimuth_deg = 33;
  cfg.site.gravity_mps2 = 9.81563;  // "measured": 0.4 mm/s^2 off the normal gravity there
  cfg.rate_hz = rate_hz;
  cfg.steps = direct_program(hold_s);
  cfg.truth = random_truth(truth_seed);
  cfg.noise_seed = truth_seed + 1000;
  return cfg;
}

inline void run_case(const gen::Config& cfg, const std::string& name, int expect_statics,
              const calibtest::Limits& limits = calibtest::kStage1Limits, bool check_sigma = true) {
  const std::string dir = imucaltest::test_tmp_dir() + "/" + name;
  std::filesystem::remove_all(dir);
  gen::write_bundle(cfg, dir);
  const Outcome out = import_and_calibrate(dir, name);
  EXPECT_TRUE(out.import.gaps.empty());
  for (const auto& n : out.result.notes) std::printf("%s\n", n.c_str());
  EXPECT_EQ(out.result.statics, expect_statics);
  EXPECT_GE(out.result.static_time_s, 1200.0);
  EXPECT_EQ(out.result.rotations, expect_statics - 1);  // every move between two holds is one turn
  const ImuModel truth = to_model(cfg.truth);
  calibtest::expect_within(truth, out.result.model, limits, check_sigma);
  print_worst(truth, out.result.model);
  if (!check_sigma) return;  // noise-free
  const double arw = cfg.truth.arw_deg_rth * std::numbers::pi / 180.0 / 60.0;
  EXPECT_NEAR(out.result.model.gyro.noise.arw_rad_rts / arw, 1.0, 0.10);
  EXPECT_NEAR(out.result.model.accel.noise.vrw_mps_rts / (cfg.truth.vrw_mps_rth / 60.0), 1.0, 0.10);
}


// err/sigma of every coefficient, per group, appended to `z` (to judge whether the sigmas are honest).
inline void collect_z(const ImuModel& t, const ImuModel& e, std::map<std::string, std::vector<double>>& z) {
  const ImuErrorSet& s = *e.sigma;
  for (int j = 0; j < 3; ++j) {
    z["gyro bias"].push_back((e.gyro.bias_radps[j] - t.gyro.bias_radps[j]) / s.gyro.bias_radps[j]);
    z["gyro scale"].push_back((e.gyro.scale_pos[j] - t.gyro.scale_pos[j]) / s.gyro.scale_pos[j]);
    z["gyro scale"].push_back((e.gyro.scale_neg[j] - t.gyro.scale_neg[j]) / s.gyro.scale_neg[j]);
    z["accel bias"].push_back((e.accel.bias_mps2[j] - t.accel.bias_mps2[j]) / s.accel.bias_mps2[j]);
    z["accel scale"].push_back((e.accel.scale[j] - t.accel.scale[j]) / s.accel.scale[j]);
  }
  for (double Misalignment::*k : {&Misalignment::xy, &Misalignment::xz, &Misalignment::yx, &Misalignment::yz,
                                  &Misalignment::zx, &Misalignment::zy}) {
    z["gyro angles"].push_back((e.gyro.misalignment_rad.*k - t.gyro.misalignment_rad.*k) / s.gyro.misalignment_rad.*k);
    z["accel angles"].push_back((e.accel.misalignment_rad.*k - t.accel.misalignment_rad.*k) /
                                s.accel.misalignment_rad.*k);
  }
}

}  // namespace imucal_test::cases
