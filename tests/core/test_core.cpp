// Conventions in code: Earth, table kinematics, the sensor model and its JSON form.
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/coefficients.hpp"
#include "core/earth.hpp"
#include "core/expect_value.hpp"
#include "core/imu_model.hpp"
#include "core/json_reader.hpp"
#include "core/number_text.hpp"
#include "core/table.hpp"
#include "core/units.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using Eigen::Matrix3d;
using Eigen::Vector3d;

TEST(Earth, NormalGravityMatchesWgs84) {
  EXPECT_NEAR(earth::normal_gravity_mps2(0.0, 0.0), 9.7803253359, 1e-9);
  EXPECT_NEAR(earth::normal_gravity_mps2(units::kPi / 2, 0.0), 9.8321849378, 1e-9);
  // Somigliana with the published WGS-84 constants (NIMA TR8350.2, eq. 4-1).
  const double s2 = 0.5;
  EXPECT_NEAR(earth::normal_gravity_mps2(45.0 * units::kDegToRad, 0.0),
              9.7803253359 * (1 + 0.00193185265241 * s2) / std::sqrt(1 - 0.00669437999013 * s2), 1e-9);
  // Free-air gradient is about -3.086e-6 m/s^2 per metre.
  const double dg = earth::normal_gravity_mps2(0.8, 100.0) - earth::normal_gravity_mps2(0.8, 0.0);
  EXPECT_NEAR(dg, -3.086e-4, 3e-6);
  Site s;
  s.gravity_mps2 = 9.81925;
  EXPECT_EQ(earth::site_gravity_mps2(s), 9.81925);
}

TEST(Table, ZeroAnglesFollowTheAzimuth) {
  const Matrix3d C0 = table::C_p0_n(0.0);
  EXPECT_TRUE(C0.col(0).isApprox(Vector3d(0, 1, 0)));   // middle axis North
  EXPECT_TRUE(C0.col(1).isApprox(Vector3d(-1, 0, 0)));  // eta West
  EXPECT_TRUE(C0.col(2).isApprox(Vector3d(0, 0, 1)));
  const Matrix3d C90 = table::C_p0_n(90.0 * units::kDegToRad);
  EXPECT_TRUE(C90.col(0).isApprox(Vector3d(1, 0, 0)));  // middle axis East
  EXPECT_NEAR((C90 * C90.transpose() - Matrix3d::Identity()).norm(), 0.0, 1e-15);
}

TEST(Table, DiagonalPoseHasAllAxesEquallyUp) {
  const Vector3d a(0.3, std::atan(std::sqrt(2.0)), units::kPi / 4);
  const Matrix3d C = table::C_p_n(a, table::C_p0_n(0.2));
  const Vector3d up_p = C.transpose() * Vector3d::UnitZ();
  EXPECT_NEAR(up_p[0], 1 / std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(up_p[1], 1 / std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(up_p[2], 1 / std::sqrt(3.0), 1e-12);
}

TEST(Table, AxisPosesOfTheBuiltInPrograms) {
  const Matrix3d C0 = table::C_p0_n(0.35);
  auto up_in_p = [&](double o, double m, double i) {
    return Vector3d(table::C_p_n(Vector3d(o, m, i) * units::kDegToRad, C0).transpose() * Vector3d::UnitZ());
  };
  EXPECT_TRUE(up_in_p(30, 90, 90).isApprox(Vector3d::UnitX(), 1e-12));
  EXPECT_TRUE(up_in_p(30, 90, -90).isApprox(-Vector3d::UnitX(), 1e-12));
  EXPECT_TRUE(up_in_p(30, 90, 0).isApprox(Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(up_in_p(30, -90, 0).isApprox(-Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(up_in_p(30, 180, 0).isApprox(-Vector3d::UnitZ(), 1e-12));
}

// Analytic rate and its derivative against finite differences of the attitude and the rate.
TEST(Table, RatesAgreeWithFiniteDifferences) {
  const Matrix3d C0 = table::C_p0_n(0.4);
  auto state = [](double t) {
    table::AxisState s;
    s.angle_rad << 0.3 * std::sin(0.7 * t) + 0.1, 1.1 * std::sin(0.5 * t + 0.3), -0.8 * std::cos(1.3 * t);
    s.rate_radps << 0.21 * std::cos(0.7 * t), 0.55 * std::cos(0.5 * t + 0.3), 1.04 * std::sin(1.3 * t);
    s.accel_radps2 << -0.147 * std::sin(0.7 * t), -0.275 * std::sin(0.5 * t + 0.3), 1.352 * std::cos(1.3 * t);
    return s;
  };
  for (double t : {0.0, 0.7, 2.3, 5.1}) {
    const double h = 1e-5;
    const Matrix3d Cp = table::C_p_n(state(t + h).angle_rad, C0), Cm = table::C_p_n(state(t - h).angle_rad, C0);
    const Matrix3d C = table::C_p_n(state(t).angle_rad, C0);
    const Matrix3d W = C.transpose() * (Cp - Cm) / (2 * h);  // [w_np_p x]
    const table::PlatformRates pr = table::platform_rates(state(t));
    EXPECT_NEAR(W(2, 1), pr.w_np_p.x(), 1e-8);
    EXPECT_NEAR(W(0, 2), pr.w_np_p.y(), 1e-8);
    EXPECT_NEAR(W(1, 0), pr.w_np_p.z(), 1e-8);
    const Vector3d dw = (table::platform_rates(state(t + h)).w_np_p - table::platform_rates(state(t - h)).w_np_p) / (2 * h);
    EXPECT_TRUE(dw.isApprox(pr.dw_np_p, 1e-7)) << dw.transpose() << " vs " << pr.dw_np_p.transpose();
  }
}

TEST(SensorModel, MisalignmentSignsFollowTheSeed) {
  Misalignment m;
  m.xy = 1e-3;  // sensor x rotated right-handed about instrument y: x tips towards -z
  const Matrix3d D = misalignment_matrix(m);
  EXPECT_DOUBLE_EQ(D(0, 2), -1e-3);
  m = {};
  m.yx = 2e-3;  // sensor y about x: y tips towards +z
  EXPECT_DOUBLE_EQ(misalignment_matrix(m)(1, 2), 2e-3);
  m = {};
  m.zx = 3e-3;  // sensor z about x: z tips towards -y
  EXPECT_DOUBLE_EQ(misalignment_matrix(m)(2, 1), -3e-3);
}

TEST(SensorModel, CompensationInvertsTheForwardModel) {
  GyroErrors g;
  g.bias_radps << 1e-7, -2e-7, 3e-7;
  g.scale_pos << 50e-6, -20e-6, 10e-6;
  g.scale_neg << 40e-6, -10e-6, 30e-6;
  g.misalignment_rad = {1e-4, -2e-4, 3e-4, 5e-5, -7e-5, 9e-5};
  for (const Vector3d& w : {Vector3d(0.1, -0.2, 0.3), Vector3d(-0.5, 0.01, -0.02)}) {
    const double dt = 1e-3;
    const Vector3d u = (apply_gyro_scale_misalignment(g, w) + g.bias_radps) * dt;
    // First-order D: the inverse is exact, so the residual is rounding only.
    EXPECT_LT((compensate_gyro_increment(g, u, dt) - w * dt).norm(), 1e-15);
  }
  AccelErrors a;
  a.bias_mps2 << 1e-4, 2e-4, -3e-4;
  a.scale << 100e-6, -50e-6, 20e-6;
  a.misalignment_rad = {2e-4, -1e-4, 5e-5, 3e-4, -2e-4, 1e-4};
  const Vector3d f(0.3, -1.2, 9.7);
  const Vector3d dv = (apply_accel_scale_misalignment(a, f) + a.bias_mps2) * 0.01;
  EXPECT_LT((compensate_accel_increment(a, dv, 0.01) - f * 0.01).norm(), 1e-15);
}

TEST(ModelJson, RoundTripKeepsEveryCoefficient) {
  ImuModel m;
  m.gyro.bias_radps << 0.01 * units::kDphToRadps, -0.02 * units::kDphToRadps, 0.03 * units::kDphToRadps;
  m.gyro.scale_pos << 1e-6, 2e-6, 3e-6;
  m.gyro.scale_neg << -1e-6, -2e-6, -3e-6;
  m.gyro.misalignment_rad.zy = 12 * units::kArcsecToRad;
  m.gyro.delay_s << 1e-6, 2e-6, 3e-6;
  m.accel.lever_arm_y_m << 0.001, 0.002, 0.003;
  m.accel.noise.vrw_mps_rts = 0.002 / 60;
  m.sigma = ImuErrorSet{};
  m.sigma->gyro.bias_radps.setConstant(1e-9);
  const ImuModel r = imu_model_from_json_text(imu_model_to_json_text(m), "test");
  EXPECT_TRUE(r.gyro.bias_radps.isApprox(m.gyro.bias_radps, 1e-14));
  EXPECT_TRUE(r.gyro.delay_s.isApprox(m.gyro.delay_s, 1e-14));
  EXPECT_NEAR(r.gyro.misalignment_rad.zy, m.gyro.misalignment_rad.zy, 1e-18);
  EXPECT_TRUE(r.accel.lever_arm_y_m.isApprox(m.accel.lever_arm_y_m, 1e-14));
  EXPECT_NEAR(r.accel.noise.vrw_mps_rts, m.accel.noise.vrw_mps_rts, 1e-18);
  ASSERT_TRUE(r.sigma.has_value());
  EXPECT_TRUE(r.sigma->gyro.bias_radps.isApprox(m.sigma->gyro.bias_radps, 1e-14));
}

TEST(ModelJson, RoundTripKeepsTheCommentAndSerial) {
  // Writing the extra keys back once iterated a destroyed temporary (and hung imucald).
  const ImuModel m = imu_model_from_json_text(
      R"({"format":"imucal-imu-model/1","comment":"a note","serial":"FOG-7","gyro":{"bias_dph":[0.04,0,0]}})", "m");
  const std::string text = imu_model_to_json_text(m);
  const auto j = nlohmann::json::parse(text);
  EXPECT_EQ(j.at("comment"), "a note");
  EXPECT_EQ(j.at("serial"), "FOG-7");
  EXPECT_EQ(imu_model_from_json_text(text, "again").extra_json, m.extra_json);
}

TEST(ModelJson, UnknownKeysAndBadValuesAreNamed) {
  try {
    imu_model_from_json_text(R"({"format":"imucal-imu-model/1","gyro":{"bias_dhp":[0,0,0]}})", "m.json");
    FAIL() << "typo accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("m.json.gyro: unknown key \"bias_dhp\""), std::string::npos) << e.what();
  }
  EXPECT_THROW(imu_model_from_json_text(R"({"format":"other"})", "m"), std::runtime_error);
  EXPECT_THROW(imu_model_from_json_text(R"({"format":"imucal-imu-model/1","accel":{"bias_mps2":[0,0]}})", "m"),
               std::runtime_error);
}

TEST(ModelJson, ReadsTheIndependentSimulatorsTruth) {
  const ImuModel m = read_imu_model_file(imucaltest::test_data_dir() + "/example-direct/truth.json");
  EXPECT_NEAR(m.gyro.bias_radps[0] * units::kRadpsToDph, 0.03721472649399559, 1e-15);
  EXPECT_NEAR(m.accel.misalignment_rad.zy * units::kRadToArcsec, 20.657489403031462, 1e-12);
  EXPECT_NEAR(m.gyro.noise.arw_rad_rts / units::kDegRthToRadRts, 0.0005, 1e-15);
}

// The nonlinear terms (CONVENTIONS.md, "Nonlinear terms") at the sizes of issue 19's acceptance:
// gyro nonlinearity 5-20 ppm at 300 deg/s, K2 20-50 ug/g^2, K3 1-5 ug/g^3, g-sensitivity
// 0.001-0.01 deg/h/g.
namespace {
GyroErrors gyro_with_every_term() {
  GyroErrors g;
  g.bias_radps << 0.02 * units::kDphToRadps, -0.03 * units::kDphToRadps, 0.01 * units::kDphToRadps;
  g.scale_pos << 250e-6, -220e-6, 280e-6;
  g.scale_neg << 240e-6, -210e-6, 295e-6;
  g.misalignment_rad = {50 * units::kArcsecToRad, -45 * units::kArcsecToRad, 55 * units::kArcsecToRad,
                        -60 * units::kArcsecToRad, 42 * units::kArcsecToRad, -48 * units::kArcsecToRad};
  // At q = 3 (300 deg/s): x 3*3 + 0.5*9 + 0.1*27 = 16.2 ppm, y -7.5 ppm, z 19.2 ppm.
  g.scale_nonlinear << 3e-6, 0.5e-6, 0.1e-6,
                      -2.5e-6, 0.0, 0.0,
                       1e-6, 1.2e-6, 0.2e-6;
  g.g_sensitivity_radps_per_g << 0.004, -0.002, 0.008,
                                 0.001, 0.006, -0.003,
                                -0.005, 0.002, 0.009;
  g.g_sensitivity_radps_per_g *= units::kDphToRadps;
  return g;
}

AccelErrors accel_with_every_term() {
  AccelErrors a;
  a.bias_mps2 << 3e-4, -5e-4, 2e-4;
  a.scale << 250e-6, -280e-6, 210e-6;
  a.misalignment_rad = {-52 * units::kArcsecToRad, 44 * units::kArcsecToRad, 58 * units::kArcsecToRad,
                        -41 * units::kArcsecToRad, 47 * units::kArcsecToRad, 53 * units::kArcsecToRad};
  a.lever_arm_y_m << 0.01, 0.035, -0.02;
  a.lever_arm_z_m << -0.03, 0.01, 0.04;
  a.k2_per_g << 25e-6, -40e-6, 50e-6;  // ug/g^2 * 1e-6
  a.k3_per_g2 << 2e-6, -1e-6, 5e-6;    // ug/g^3 * 1e-6
  return a;
}

// The accelerometer forward model written out from CONVENTIONS.md, row by row: channel j is row j
// of D S applied to the force at its own proof mass, S with each channel's s at its own f_j[j].
Vector3d accel_forward(const AccelErrors& a, const Vector3d& f_origin, const Matrix3d& size_effect) {
  Matrix3d f_at;  // rows j: f_j
  for (int j = 0; j < 3; ++j) f_at.row(j) = f_origin.transpose() + size_effect.row(j);
  const Vector3d s = accel_scale_errors(a, f_at.diagonal());
  const Matrix3d DS = misalignment_matrix(a.misalignment_rad) * (Vector3d::Ones() + s).asDiagonal();
  Vector3d u;
  for (int j = 0; j < 3; ++j) u[j] = DS.row(j).dot(f_at.row(j));
  return u + a.bias_mps2;
}
}  // namespace

// Each term enters as the spec writes it: K2 of 1 ug/g^2 is 1 ug of output at 1 g (both readings
// of "s_j + k2 a" with k2 in ug/g^2 agree), c_k scales q^k of the rate in units of 100 deg/s, and
// g-sensitivity is a bias per g of specific force.
TEST(SensorModel, NonlinearTermsFollowTheConventions) {
  const double g = units::kStandardGravity_mps2;
  AccelErrors a;
  a.k2_per_g[2] = 40e-6;
  a.k3_per_g2[2] = 3e-6;
  for (const double a_g : {1.0, -1.0, 0.5, 2.0}) {
    const Vector3d u = apply_accel_scale_misalignment(a, Vector3d(0, 0, a_g * g));
    const double output_error_ug = (u[2] - a_g * g) / (1e-6 * g);
    EXPECT_NEAR(output_error_ug, 40 * a_g * a_g + 3 * a_g * a_g * a_g, 1e-9) << a_g;
  }
  GyroErrors gy;
  gy.scale_pos[0] = 10e-6;
  gy.scale_neg[0] = -10e-6;
  gy.scale_nonlinear.row(0) << 2e-6, 1e-6, 0.5e-6;
  for (const double rate_dps : {300.0, -300.0, 100.0, -50.0}) {
    const double w = rate_dps * units::kDegToRad, q = std::abs(rate_dps) / 100.0;
    const double s = (w >= 0 ? 10e-6 : -10e-6) + 2e-6 * q + 1e-6 * q * q + 0.5e-6 * q * q * q;
    EXPECT_NEAR(apply_gyro_scale_misalignment(gy, Vector3d(w, 0, 0))[0], (1 + s) * w, 1e-15) << rate_dps;
  }
  gy.g_sensitivity_radps_per_g << 0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.005;
  const Vector3d b = gyro_g_sensitivity_radps(gy, Vector3d(g, 0.0, -2 * g));
  EXPECT_NEAR(b[0], 0.01, 1e-15);
  EXPECT_NEAR(b[2], 0.01, 1e-15);
}

// Forward then inverse with every term at once, proof-mass offsets and delays' worth of rate
// included: the fixed-point inverse returns the input to rounding, at full rate both ways and at
// low rates. Without its nonlinear terms the same model is off by their size.
TEST(SensorModel, CompensationInvertsTheNonlinearTerms) {
  const GyroErrors g = gyro_with_every_term();
  const AccelErrors a = accel_with_every_term();
  Matrix3d offsets = Matrix3d::Zero();
  offsets.col(1) = a.lever_arm_y_m;
  offsets.col(2) = a.lever_arm_z_m;
  const double dt = 1e-2, d = units::kDegToRad;
  const std::vector<std::pair<Vector3d, Vector3d>> cases = {
      {Vector3d(300 * d, -300 * d, 250 * d), Vector3d(0.3, -1.2, 9.7)},
      {Vector3d(-300 * d, 120 * d, -2 * d), Vector3d(-9.78, 0.5, -0.4)},
      {Vector3d(0.01 * d, -0.5 * d, 60 * d), Vector3d(5.0, -6.9, 5.1)},
      {Vector3d(7.3e-5, -2e-5, 4e-5), Vector3d(0.0, 0.0, 9.81)}};
  for (const auto& [w, f] : cases) {
    const Vector3d dw(0.3, -0.2, 0.5);
    const Matrix3d e = size_effect_mps2(offsets, w, dw);
    const Vector3d dtheta = (apply_gyro_scale_misalignment(g, w) + g.bias_radps + gyro_g_sensitivity_radps(g, f)) * dt;
    const Vector3d dv = accel_forward(a, f, e) * dt;
    const CompensatedIncrements c = compensate_imu_increments(g, a, dtheta, dv, dt, e);
    EXPECT_LT((c.dtheta_rad - w * dt).norm(), 1e-12 * (w * dt).norm()) << w.transpose();
    EXPECT_LT((c.dv_mps - f * dt).norm(), 1e-12 * (f * dt).norm()) << f.transpose();
    // The parts on their own: the accelerometers with their size effect, the gyros given f.
    EXPECT_LT((compensate_accel_increment(a, dv, dt, e) - f * dt).norm(), 1e-12 * (f * dt).norm());
    EXPECT_LT((compensate_gyro_increment(g, dtheta, dt, f) - w * dt).norm(), 1e-12 * (w * dt).norm());
  }
  // The terms matter at these sizes: left out, the full-rate case is off by ppm.
  GyroErrors g_linear = g;
  g_linear.scale_nonlinear.setZero();
  g_linear.g_sensitivity_radps_per_g.setZero();
  AccelErrors a_linear = a;
  a_linear.k2_per_g.setZero();
  a_linear.k3_per_g2.setZero();
  const Vector3d w = cases[0].first, f = cases[0].second;
  const Matrix3d e = size_effect_mps2(offsets, w, Vector3d::Zero());
  const Vector3d dtheta = (apply_gyro_scale_misalignment(g, w) + g.bias_radps + gyro_g_sensitivity_radps(g, f)) * dt;
  const Vector3d dv = accel_forward(a, f, e) * dt;
  EXPECT_GT((compensate_gyro_increment(g_linear, dtheta, dt) - w * dt).norm(), 5e-6 * (w * dt).norm());
  EXPECT_GT((compensate_accel_increment(a_linear, dv, dt, e) - f * dt).norm(), 2e-5 * (f * dt).norm());
}

// The one list of coefficients (core/coefficients.hpp): every key of the model JSON, each with the
// value and sigma of the model in the key's unit, the same keys for every model.
TEST(ModelCoefficients, ListEveryKeyOfTheModelInItsUnit) {
  ImuModel m;
  m.gyro = gyro_with_every_term();
  m.accel = accel_with_every_term();
  m.accel.lever_arm_y_m = {0.001, 0.0125, -0.002};
  m.gyro.delay_s = {1e-6, 2e-6, 3e-6};
  m.sigma = ImuErrorSet{};
  m.sigma->accel.k3_per_g2.setConstant(0.5e-6);
  const std::vector<Coefficient> all = model_coefficients(m);
  // 15 gyro + 12 accelerometer linear terms; 9 + 3 + 3 + 9 nonlinear; 6 delays; 6 proof-mass offsets.
  ASSERT_EQ(all.size(), 63u);
  EXPECT_EQ(model_coefficients(ImuModel{}).size(), all.size());
  std::map<std::string, Coefficient> by_key;
  for (const Coefficient& c : all) EXPECT_TRUE(by_key.emplace(c.key, c).second) << "twice: " << c.key;
  EXPECT_NEAR(by_key.at("gyro.scale_nonlinear_ppm.x.c1").value, m.gyro.scale_nonlinear(0, 0) * 1e6, 1e-9);
  EXPECT_NEAR(by_key.at("gyro.g_sensitivity_dph_per_g.z.z").value,
              m.gyro.g_sensitivity_radps_per_g(2, 2) * units::kRadpsToDph, 1e-12);
  EXPECT_NEAR(by_key.at("accel.k2_ug_per_g2.y").value, m.accel.k2_per_g[1] * 1e6, 1e-9);
  EXPECT_NEAR(by_key.at("accel.k3_ug_per_g3.x").sigma, 0.5, 1e-12);
  EXPECT_NEAR(by_key.at("accel.lever_arm_mm.y.y").value, 12.5, 1e-12);
  EXPECT_NEAR(by_key.at("gyro.delay_us.z").value, 3.0, 1e-12);
  EXPECT_FALSE(by_key.at("gyro.bias_dph.x").optional);
  EXPECT_TRUE(by_key.at("accel.k3_ug_per_g3.x").optional);
  // A triad's vector is estimated together; a matrix term alone.
  EXPECT_EQ(by_key.at("accel.k3_ug_per_g3.y").group, "accel.k3_ug_per_g3");
  EXPECT_EQ(by_key.at("gyro.scale_nonlinear_ppm.y.c2").group, "gyro.scale_nonlinear_ppm.y.c2");
}

TEST(ModelJson, RoundTripKeepsTheNonlinearTermsAndTheirSigmas) {
  ImuModel m;
  m.gyro = gyro_with_every_term();
  m.accel = accel_with_every_term();
  m.sigma = ImuErrorSet{};
  m.sigma->gyro.scale_nonlinear.setConstant(0.3e-6);
  m.sigma->gyro.g_sensitivity_radps_per_g.setConstant(0.0005 * units::kDphToRadps);
  m.sigma->accel.k2_per_g.setConstant(2e-6);
  m.sigma->accel.k3_per_g2.setConstant(0.5e-6);
  const std::string text = imu_model_to_json_text(m);
  const auto j = nlohmann::json::parse(text);
  // The units of formats.md: ppm, deg/h per g, ug per g^2 and per g^3.
  EXPECT_NEAR(j.at("gyro").at("scale_nonlinear_ppm").at("x")[0].get<double>(), 3.0, 1e-12);
  EXPECT_NEAR(j.at("gyro").at("g_sensitivity_dph_per_g")[2][2].get<double>(), 0.009, 1e-15);
  EXPECT_NEAR(j.at("accel").at("k2_ug_per_g2")[1].get<double>(), -40.0, 1e-12);
  EXPECT_NEAR(j.at("accel").at("k3_ug_per_g3")[2].get<double>(), 5.0, 1e-12);
  EXPECT_NEAR(j.at("sigma").at("accel").at("k3_ug_per_g3")[0].get<double>(), 0.5, 1e-12);
  const ImuModel r = imu_model_from_json_text(text, "test");
  EXPECT_TRUE(r.gyro.scale_nonlinear.isApprox(m.gyro.scale_nonlinear, 1e-14));
  EXPECT_TRUE(r.gyro.g_sensitivity_radps_per_g.isApprox(m.gyro.g_sensitivity_radps_per_g, 1e-14));
  EXPECT_TRUE(r.accel.k2_per_g.isApprox(m.accel.k2_per_g, 1e-14));
  EXPECT_TRUE(r.accel.k3_per_g2.isApprox(m.accel.k3_per_g2, 1e-14));
  ASSERT_TRUE(r.sigma.has_value());
  EXPECT_TRUE(r.sigma->gyro.scale_nonlinear.isApprox(m.sigma->gyro.scale_nonlinear, 1e-14));
  EXPECT_TRUE(r.sigma->gyro.g_sensitivity_radps_per_g.isApprox(m.sigma->gyro.g_sensitivity_radps_per_g, 1e-14));
  EXPECT_TRUE(r.sigma->accel.k2_per_g.isApprox(m.sigma->accel.k2_per_g, 1e-14));
  EXPECT_TRUE(r.sigma->accel.k3_per_g2.isApprox(m.sigma->accel.k3_per_g2, 1e-14));
}

TEST(ModelJson, NonlinearTermsReadAsTheSpecWritesThem) {
  // One to three terms per axis, axes and keys left out read as zero; a one-term model writes one.
  const ImuModel m = imu_model_from_json_text(R"({"format":"imucal-imu-model/1",
    "gyro":{"scale_nonlinear_ppm":{"x":[4],"z":[1,-2]}},"accel":{"k3_ug_per_g3":[0,1,0]}})", "m");
  EXPECT_NEAR(m.gyro.scale_nonlinear(0, 0), 4e-6, 1e-20);
  EXPECT_NEAR(m.gyro.scale_nonlinear(2, 1), -2e-6, 1e-20);
  EXPECT_EQ(m.gyro.scale_nonlinear(1, 0), 0.0);
  EXPECT_TRUE(m.accel.k2_per_g.isZero(0.0));
  EXPECT_TRUE(m.gyro.g_sensitivity_radps_per_g.isZero(0.0));
  const auto j = nlohmann::json::parse(imu_model_to_json_text(m));
  EXPECT_EQ(j.at("gyro").at("scale_nonlinear_ppm").at("y").size(), 2u);
  EXPECT_FALSE(j.at("accel").contains("k2_ug_per_g2"));
  const ImuModel one = imu_model_from_json_text(
      R"({"format":"imucal-imu-model/1","gyro":{"scale_nonlinear_ppm":{"y":[7]}}})", "m");
  EXPECT_EQ(nlohmann::json::parse(imu_model_to_json_text(one)).at("gyro").at("scale_nonlinear_ppm").at("x").size(), 1u);
}

// A model without the terms writes exactly the keys it wrote before they existed (their values go
// through unchanged code), in the sigma section too.
TEST(ModelJson, AModelWithoutTheTermsWritesNoneOfTheirKeys) {
  ImuModel m = read_imu_model_file(imucaltest::test_data_dir() + "/example-direct/truth.json");
  m.sigma = ImuErrorSet{};
  m.sigma->gyro.bias_radps.setConstant(1e-9);
  const auto j = nlohmann::json::parse(imu_model_to_json_text(m));
  const auto keys = [](const nlohmann::json& o) {
    std::vector<std::string> k;
    for (const auto& [key, value] : o.items()) k.push_back(key);
    return k;
  };
  using V = std::vector<std::string>;
  const V gyro = {"bias_dph", "delay_us", "misalignment_arcsec", "scale_neg_ppm", "scale_pos_ppm"};
  const V accel = {"bias_mps2", "delay_us", "lever_arm_mm", "misalignment_arcsec", "scale_ppm"};
  EXPECT_EQ(keys(j.at("gyro")), V({"bias_dph", "delay_us", "misalignment_arcsec", "noise", "scale_neg_ppm", "scale_pos_ppm"}));
  EXPECT_EQ(keys(j.at("accel")), V({"bias_mps2", "delay_us", "lever_arm_mm", "misalignment_arcsec", "noise", "scale_ppm"}));
  EXPECT_EQ(keys(j.at("sigma").at("gyro")), gyro);
  EXPECT_EQ(keys(j.at("sigma").at("accel")), accel);
}

// Issue 34's budget: each source with the keys of `sigma`, read back as written; a model without
// one (every model before it) reads with none and writes no key; a malformed source is named.
TEST(ModelJson, TheBudgetRoundTripsAndAnOlderModelStillReads) {
  ImuModel m = read_imu_model_file(imucaltest::test_data_dir() + "/example-direct/truth.json");
  EXPECT_TRUE(m.budget.empty());
  EXPECT_FALSE(nlohmann::json::parse(imu_model_to_json_text(m)).contains("budget"));
  m.sigma = ImuErrorSet{};
  m.sigma->gyro.misalignment_rad.yx = 5e-7;
  m.budget["type_a"].gyro.misalignment_rad.yx = 3e-7;
  m.budget["table.middle_axis_arcsec"].gyro.misalignment_rad.yx = 4e-7;
  m.budget["start_model.accel.k3_ug_per_g3"].accel.scale[2] = 1.25e-6;
  const std::string text = imu_model_to_json_text(m);
  const auto j = nlohmann::json::parse(text);
  EXPECT_NEAR(j.at("budget").at("table.middle_axis_arcsec").at("gyro").at("misalignment_arcsec").at("yx").get<double>(),
              4e-7 * units::kRadToArcsec, 1e-12);
  const ImuModel r = imu_model_from_json_text(text, "test");
  ASSERT_EQ(r.budget.size(), 3u);
  EXPECT_NEAR(r.budget.at("type_a").gyro.misalignment_rad.yx, 3e-7, 1e-20);
  EXPECT_NEAR(r.budget.at("table.middle_axis_arcsec").gyro.misalignment_rad.yx, 4e-7, 1e-20);
  EXPECT_NEAR(r.budget.at("start_model.accel.k3_ug_per_g3").accel.scale[2], 1.25e-6, 1e-18);
  EXPECT_EQ(nlohmann::json::parse(imu_model_to_json_text(r)).at("budget"), j.at("budget"));
  try {
    imu_model_from_json_text(R"({"format":"imucal-imu-model/1","budget":{"type_a":{"gyro":{"bias_dhp":[0,0,0]}}}})",
                             "m.json");
    FAIL() << "a misspelt key in a budget source must be refused";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("budget.type_a.gyro"), std::string::npos) << e.what();
  }
  EXPECT_THROW(imu_model_from_json_text(R"({"format":"imucal-imu-model/1","budget":[1]})", "m"), std::runtime_error);
}

TEST(ModelJson, MalformedNonlinearTermsAreNamed) {
  const auto refused = [](const std::string& section, const std::string& expected) {
    try {
      imu_model_from_json_text(R"({"format":"imucal-imu-model/1",)" + section + "}", "m.json");
      return std::string("accepted");
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      return what.find(expected) != std::string::npos ? std::string() : what;
    }
  };
  EXPECT_EQ(refused(R"("accel":{"k2_ug_per_g":[1,2,3]})", "m.json.accel: unknown key \"k2_ug_per_g\""), "");
  EXPECT_EQ(refused(R"("gyro":{"g_sensitivity_dps_per_g":[[0,0,0],[0,0,0],[0,0,0]]})",
                    "m.json.gyro: unknown key \"g_sensitivity_dps_per_g\""), "");
  EXPECT_EQ(refused(R"("gyro":{"scale_nonlinear_ppm":{"w":[1]}})", "m.json.gyro.scale_nonlinear_ppm: unknown key \"w\""), "");
  EXPECT_EQ(refused(R"("gyro":{"scale_nonlinear_ppm":{"x":[1,2,3,4]}})", "m.json.gyro.scale_nonlinear_ppm.x"), "");
  EXPECT_EQ(refused(R"("gyro":{"scale_nonlinear_ppm":{"x":[]}})", "m.json.gyro.scale_nonlinear_ppm.x"), "");
  EXPECT_EQ(refused(R"("gyro":{"scale_nonlinear_ppm":[1,2,3]})", "m.json.gyro.scale_nonlinear_ppm"), "");
  EXPECT_EQ(refused(R"("gyro":{"scale_nonlinear_ppm":{"y":[1,"a"]}})", "m.json.gyro.scale_nonlinear_ppm.y[1]"), "");
  EXPECT_EQ(refused(R"("gyro":{"g_sensitivity_dph_per_g":[[0,0,0],[0,0],[0,0,0]]})",
                    "m.json.gyro.g_sensitivity_dph_per_g[1]"), "");
  EXPECT_EQ(refused(R"("gyro":{"g_sensitivity_dph_per_g":[0,0,0]})", "m.json.gyro.g_sensitivity_dph_per_g"), "");
  EXPECT_EQ(refused(R"("accel":{"k3_ug_per_g3":[1,2]})", "m.json.accel.k3_ug_per_g3"), "");
  EXPECT_EQ(refused(R"("sigma":{"accel":{"k2_ug_per_g3":[1,2,3]}})", "m.json.sigma.accel: unknown key \"k2_ug_per_g3\""), "");
}

// Numbers in messages for people (issue 18, item 3): no noise digits, units as people write them.
TEST(NumberText, ShortestFormWithoutNoiseDigits) {
  EXPECT_EQ(imucal::number_text(46.6), "46.6");           // was "46.600000" (resumed ... from 46.6 s)
  EXPECT_EQ(imucal::number_text(4.0), "4");               // was "4.000000x" (time scale 4x)
  EXPECT_EQ(imucal::number_text(5000.0), "5000");         // was "5000.0" (campaign.rate_hz)
  EXPECT_EQ(imucal::number_text(0.25), "0.25");
  EXPECT_EQ(imucal::number_text(1234.56789), "1234.57");
  EXPECT_EQ(imucal::number_text(62.8319, 4), "62.83");
  EXPECT_EQ(imucal::celsius_text(31.0), "31 °C");          // was "31.00 C"
  EXPECT_EQ(imucal::celsius_text(31.4321), "31.43 °C");
  EXPECT_EQ(imucal::celsius_text(-40.0), "-40 °C");
}

TEST(NumberText, TheWholeTextIsANumberOrNothing) {
  EXPECT_EQ(imucal::parse_number_text("46.6"), 46.6);
  EXPECT_EQ(imucal::parse_number_text("-1.5e-3"), -1.5e-3);
  EXPECT_EQ(imucal::parse_number_text("+3"), 3.0);
  for (const char* text : {"", "soon", "3 s", "-", "-x", "1,5"}) EXPECT_FALSE(imucal::parse_number_text(text)) << text;
}

// The one strict reader of people's JSON (core/json_reader.hpp), in both ways of reporting.
TEST(ObjectReader, CollectsEveryProblemOrThrowsTheFirst) {
  const auto j = nlohmann::json::parse(R"({"rate": "fast", "count": 7, "speling": 1, "_note": "a comment"})");
  std::vector<std::string> problems;
  {
    ObjectReader r(j, "cfg", problems);
    EXPECT_FALSE(r.number("rate").has_value());
    EXPECT_EQ(r.integer("count", 0, 5), std::nullopt);
    EXPECT_FALSE(r.string("name", true).has_value());
  }
  EXPECT_EQ(problems, (std::vector<std::string>{"cfg.rate must be a number, not a string",
                                                 "cfg.count is 7, must be between 0 and 5", "cfg.name is required",
                                                 "cfg: unknown key \"speling\""}));

  const auto first = [&](auto&& read) {
    try {
      ObjectReader r(j, "cfg", ObjectReader::ThrowAtFirst{"unit.json: "});
      read(r);
      r.finish();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(first([](ObjectReader& r) { r.number("rate"); }), "unit.json: cfg.rate must be a number, not a string");
  EXPECT_EQ(first([](ObjectReader& r) { r.get("rate"); r.get("count"); }), "unit.json: cfg: unknown key \"speling\"");
  EXPECT_EQ(first([](ObjectReader& r) { r.get("rate"); r.get("count"); r.get("speling"); }), "accepted");
  // A top-level reader without a name: the key alone.
  EXPECT_EQ(first([&](ObjectReader&) {
              ObjectReader top(nlohmann::json::array(), "", ObjectReader::ThrowAtFirst{"x: "});
            }),
            "x: the document must be an object, not an array");
}

// An exchange format another writer may extend: foreign keys are read past, a near miss of a key
// asked for is not (and says which key it resembles).
TEST(ObjectReader, AnExtensibleObjectRefusesOnlyNearMisses) {
  const auto finish = [](const char* text, std::vector<const char*> asked) {
    const auto j = nlohmann::json::parse(text);
    std::vector<std::string> problems;
    ObjectReader r(j, "site", problems);
    for (const char* key : asked) r.get(key);
    r.finish_extensible();
    return problems;
  };
  EXPECT_EQ(finish(R"({"height_m": 1, "vendor_tag": "x", "_c": 0})", {"height_m", "gravity_mps2"}),
            std::vector<std::string>{});
  EXPECT_EQ(finish(R"({"height_m": 1, "gravity_mps": 9.8})", {"height_m", "gravity_mps2"}),
            std::vector<std::string>{"site: unknown key \"gravity_mps\" (is it \"gravity_mps2\"?)"});
  EXPECT_EQ(finish(R"({"heigth_m": 1})", {"height_m"}),
            std::vector<std::string>{"site: unknown key \"heigth_m\" (is it \"height_m\"?)"});
  // Both present: the second is something else, not a typo of the first.
  EXPECT_EQ(finish(R"({"t0_s": 0, "t1_s": 1, "t2_s": 2})", {"t0_s", "t1_s"}), std::vector<std::string>{});
}

// A value the code itself guarantees: taken as it is, or a logic_error naming it (never the
// undefined behaviour of `*opt` on an empty optional).
TEST(ExpectValue, GivesTheValueOrALogicErrorNamingIt) {
  std::optional<int> three = 3;
  const std::optional<int> four = 4;
  EXPECT_EQ(expect_value(three, "three"), 3);
  EXPECT_EQ(expect_value(four, "four"), 4);
  EXPECT_EQ(expect_value(std::optional<std::string>("moved"), "a temporary"), "moved");
  expect_value(three, "three") = 5;  // a reference into the optional
  EXPECT_EQ(three, 5);
  try {
    (void)expect_value(std::optional<double>(), "the state after a command that succeeded");
    ADD_FAILURE() << "no exception";
  } catch (const std::logic_error& e) {
    EXPECT_STREQ(e.what(), "internal error: the state after a command that succeeded is missing");
  }
}
