// Conventions in code: Earth, table kinematics, the sensor model and its JSON form.
#include <cmath>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/earth.hpp"
#include "core/imu_model.hpp"
#include "core/number_text.hpp"
#include "core/table.hpp"
#include "core/units.hpp"

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
    EXPECT_NE(std::string(e.what()).find("m.json.gyro: unknown key 'bias_dhp'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(imu_model_from_json_text(R"({"format":"other"})", "m"), std::runtime_error);
  EXPECT_THROW(imu_model_from_json_text(R"({"format":"imucal-imu-model/1","accel":{"bias_mps2":[0,0]}})", "m"),
               std::runtime_error);
}

TEST(ModelJson, ReadsTheIndependentSimulatorsTruth) {
  const ImuModel m = read_imu_model_file(IMUCAL_TEST_DATA "/example-direct/truth.json");
  EXPECT_NEAR(m.gyro.bias_radps[0] * units::kRadpsToDph, 0.03721472649399559, 1e-15);
  EXPECT_NEAR(m.accel.misalignment_rad.zy * units::kRadToArcsec, 20.657489403031462, 1e-12);
  EXPECT_NEAR(m.gyro.noise.arw_rad_rts / units::kDegRthToRadRts, 0.0005, 1e-15);
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
