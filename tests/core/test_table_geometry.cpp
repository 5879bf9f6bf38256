// The table's own errors (CONVENTIONS.md, "The table's own errors"): the kinematics against
// first-order reasoning and finite differences, the ideal table unchanged, and the JSON of
// formats.md's `table`.
#include <cmath>
#include <optional>
#include <string>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "core/table.hpp"
#include "core/table_json.hpp"
#include "core/units.hpp"
#include "tests/core/imperfect_table.hpp"

using namespace imucal;
using Eigen::Matrix3d;
using Eigen::Vector3d;

namespace {

constexpr double kAs = units::kArcsecToRad;

using tabletest::imperfect;

// Today's formulas of the ideal table, written out as CONVENTIONS.md states them (the code that
// was in core/table.cpp before the geometry), for the comparison with the geometry zero.
Matrix3d ideal_C_p_n(const Vector3d& a, const Matrix3d& C0) {
  return table::Rz(a[0]) * C0 * table::Rx(a[1]) * table::Rz(a[2]);
}
Vector3d ideal_w_np_p(const table::AxisState& s) {
  const Matrix3d A = table::Rz(-s.angle_rad[2]), B = table::Rx(-s.angle_rad[1]);
  return A * B * Vector3d::UnitZ() * s.rate_radps[0] + A * Vector3d::UnitX() * s.rate_radps[1] +
         Vector3d::UnitZ() * s.rate_radps[2];
}

table::AxisState motion(double t) {
  table::AxisState s;
  s.angle_rad << 0.3 * std::sin(0.7 * t) + 0.1, 1.1 * std::sin(0.5 * t + 0.3), -0.8 * std::cos(1.3 * t);
  s.rate_radps << 0.21 * std::cos(0.7 * t), 0.55 * std::cos(0.5 * t + 0.3), 1.04 * std::sin(1.3 * t);
  s.accel_radps2 << -0.147 * std::sin(0.7 * t), -0.275 * std::sin(0.5 * t + 0.3), 1.352 * std::cos(1.3 * t);
  return s;
}

// The rotation vector of a rotation matrix close to the identity or not.
Vector3d rotation_vector(const Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

}  // namespace

TEST(TableGeometry, ZeroGeometryIsTodaysTable) {
  const table::TableKinematics k(0.35);
  const Matrix3d C0 = table::C_p0_n(0.35);
  EXPECT_TRUE(k.ideal());
  for (double t : {0.0, 0.9, 3.7}) {
    const table::AxisState s = motion(t);
    EXPECT_EQ(k.C_p_n(s.angle_rad), ideal_C_p_n(s.angle_rad, C0));
    EXPECT_LT((k.platform_rates(s).w_np_p - ideal_w_np_p(s)).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_EQ(k.true_angles_rad(s.angle_rad), s.angle_rad);
    EXPECT_EQ(k.encoder_angles_rad(s.angle_rad), s.angle_rad);
    const table::AxisState tr = k.true_axes(s);
    EXPECT_EQ(tr.angle_rad, s.angle_rad);
    EXPECT_EQ(tr.rate_radps, s.rate_radps);
    EXPECT_EQ(tr.accel_radps2, s.accel_radps2);
    EXPECT_EQ(k.gimbal_axes_p(s.angle_rad) * s.rate_radps, k.platform_rates(s).w_np_p);
  }
  // A geometry of zeros with harmonics of no amplitude is the ideal table too.
  table::TableGeometry g;
  g.encoder_error[1] = {{3, 0.0, 0.2}};
  EXPECT_TRUE(g.ideal());
  EXPECT_TRUE(table::TableKinematics(0.35, g).ideal());
}

// To first order C_p_n differs from the ideal one by the small rotation
// delta_p = C_p_n' t + Rz(-i) Rx(-m) m + Rz(-i) k, each error carried into p.
TEST(TableGeometry, FirstOrderAgreesWithTheProduct) {
  const table::TableGeometry g = imperfect();
  const table::TableKinematics k(0.35, g), ideal(0.35);
  const Vector3d t(g.outer_tilt_rad[0], g.outer_tilt_rad[1], 0.0), m(0.0, g.middle_axis_rad[0], g.middle_axis_rad[1]),
      kk(g.inner_axis_rad[0], g.inner_axis_rad[1], 0.0);
  for (double time : {0.0, 1.3, 4.4, 7.0}) {
    const Vector3d a = motion(time).angle_rad * 3.0;
    const Matrix3d C = ideal.C_p_n(a);
    const Vector3d predicted = C.transpose() * t + table::Rz(-a[2]) * table::Rx(-a[1]) * m + table::Rz(-a[2]) * kk;
    const Vector3d actual = rotation_vector(C.transpose() * k.C_p_n(a));
    // The second-order rest: products of two errors of ~1e-5 rad.
    EXPECT_LT((actual - predicted).norm(), 3e-10) << actual.transpose() << " vs " << predicted.transpose();
    EXPECT_GT(actual.norm(), 1e-5);  // the errors are there at all
    EXPECT_LT((k.C_p_n(a) * k.C_p_n(a).transpose() - Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-15);
  }
}

// Each key does what CONVENTIONS.md says: the outer axis is E(t) Up; the middle axis at zero
// outer angle is C_p0_n E(m) e1; the middle encoder's zero offset is k.x.
TEST(TableGeometry, EachErrorMovesItsOwnAxis) {
  const Matrix3d C0 = table::C_p0_n(0.35);
  table::TableGeometry g;
  g.outer_tilt_rad = {2.0 * kAs, 1.2 * kAs};
  g.middle_axis_rad = {3.0 * kAs, -1.5 * kAs};
  const table::TableKinematics k(0.35, g);
  const Vector3d a(0.2, 0.5, -0.4);
  // Turning the outer gimbal alone turns the platform about the outer axis, resolved in n.
  const Vector3d outer = rotation_vector(k.C_p_n(a + Vector3d(0.3, 0, 0)) * k.C_p_n(a).transpose());
  const Vector3d outer_axis_n = Vector3d(1.2 * kAs, -2.0 * kAs, 1.0).normalized();  // E([e, n, 0]) Up
  EXPECT_LT((outer.normalized() - outer_axis_n).norm(), 1e-10);
  EXPECT_NEAR(outer.norm(), 0.3, 1e-12);
  // The middle gimbal alone, at zero outer angle: about C_p0_n E(m) e1 = C_p0_n [1, z, -y].
  const Vector3d z0(0.0, 0.5, -0.4);
  const Vector3d middle = rotation_vector(k.C_p_n(z0 + Vector3d(0, 0.2, 0)) * k.C_p_n(z0).transpose());
  const Vector3d E_t_middle = Vector3d(C0 * Vector3d(1.0, -1.5 * kAs, -3.0 * kAs)).normalized();
  // The outer tilt carries the middle axis with it: compare in the tilted outer frame.
  const Matrix3d E_t = Eigen::AngleAxisd(Vector3d(2.0 * kAs, 1.2 * kAs, 0).norm(), Vector3d(2.0, 1.2, 0).normalized())
                           .toRotationMatrix();
  EXPECT_LT((E_t.transpose() * middle.normalized() - E_t_middle).norm(), 1e-10);
  // The middle encoder's zero offset: k = [x, 0, 0] is the middle angle read x short.
  table::TableGeometry off;
  off.inner_axis_rad = {2.0 * kAs, 0.0};
  const table::TableKinematics ko(0.35, off), ideal(0.35);
  EXPECT_LT((ko.C_p_n(a) - ideal.C_p_n(a + Vector3d(0, 2.0 * kAs, 0))).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(TableGeometry, EncoderErrorAndItsInverse) {
  const table::TableGeometry g = imperfect();
  const table::TableKinematics k(0.0, g);
  const Vector3d enc(0.7, -2.1, 3.0);
  const Vector3d th = k.true_angles_rad(enc);
  for (int axis = 0; axis < 3; ++axis) {
    double e = 0;
    for (const auto& h : g.encoder_error[static_cast<std::size_t>(axis)])
      e += h.amplitude_rad * std::sin(h.k * enc[axis] + h.phase_rad);
    EXPECT_EQ(th[axis], enc[axis] + e);
  }
  EXPECT_LT((k.encoder_angles_rad(th) - enc).cwiseAbs().maxCoeff(), 1e-15);
}

// The rate of the product and its derivative against finite differences, with the geometry; and
// the encoder's rates mapped to true rates against the derivative of the true angles.
TEST(TableGeometry, RatesAreTheDerivativeOfTheAttitude) {
  const table::TableKinematics k(0.4, imperfect());
  for (double t : {0.0, 0.7, 2.3, 5.1}) {
    const double h = 1e-5;
    const Matrix3d Cp = k.C_p_n(motion(t + h).angle_rad), Cm = k.C_p_n(motion(t - h).angle_rad);
    const Matrix3d C = k.C_p_n(motion(t).angle_rad);
    const Matrix3d W = C.transpose() * (Cp - Cm) / (2 * h);  // [w_np_p x]
    const table::PlatformRates pr = k.platform_rates(motion(t));
    EXPECT_NEAR(W(2, 1), pr.w_np_p.x(), 1e-9);
    EXPECT_NEAR(W(0, 2), pr.w_np_p.y(), 1e-9);
    EXPECT_NEAR(W(1, 0), pr.w_np_p.z(), 1e-9);
    // The geometry moves the rate by ~1e-5 of it: the check above resolves that.
    const Vector3d ideal = table::platform_rates(motion(t)).w_np_p;
    EXPECT_GT((pr.w_np_p - ideal).norm(), 1e-6 * ideal.norm());
    const Vector3d dw = (k.platform_rates(motion(t + h)).w_np_p - k.platform_rates(motion(t - h)).w_np_p) / (2 * h);
    EXPECT_TRUE(dw.isApprox(pr.dw_np_p, 1e-7)) << dw.transpose() << " vs " << pr.dw_np_p.transpose();

    // Encoder motion -> true motion.
    const table::AxisState tr = k.true_axes(motion(t));
    const Vector3d rate = (k.true_angles_rad(motion(t + h).angle_rad) - k.true_angles_rad(motion(t - h).angle_rad)) / (2 * h);
    EXPECT_LT((rate - tr.rate_radps).cwiseAbs().maxCoeff(), 1e-9);
    const Vector3d accel = (k.true_axes(motion(t + h)).rate_radps - k.true_axes(motion(t - h)).rate_radps) / (2 * h);
    EXPECT_LT((accel - tr.accel_radps2).cwiseAbs().maxCoeff(), 1e-8);
    EXPECT_GT((tr.rate_radps - motion(t).rate_radps).cwiseAbs().maxCoeff(), 1e-7);  // the slope is there
  }
}

TEST(TableGeometryJson, ReadsTheFormatsExample) {
  const auto j = nlohmann::json::parse(R"({
    "geometry": {"outer_tilt_arcsec": [2.0, 1.2], "middle_axis_arcsec": [3.0, -1.5],
                 "inner_axis_arcsec": [2.1, -3.0],
                 "encoder_error_arcsec": {"outer": [[1, 1.0, 90.0], [2, 0.5, 0.0]], "inner": []}},
    "sigma": {"outer_tilt_arcsec": [0.2, 0.2], "encoder_error_arcsec": {"middle": [[1, 0.1, 0.0]]}},
    "certificate": "TBL-7 of 2026-03-01"})");
  ObjectReader r(j, "table", ObjectReader::ThrowAtFirst{});
  const auto c = table::read_table_certificate(r);
  r.finish();
  ASSERT_TRUE(c);
  // The inner optionals named: clang-tidy 16's optional check does not follow them through `->`.
  const std::optional<table::TableGeometry>& geometry = c->geometry;
  const std::optional<table::TableGeometry>& sigma = c->sigma;
  ASSERT_TRUE(geometry && sigma);
  EXPECT_EQ(c->certificate, "TBL-7 of 2026-03-01");
  EXPECT_DOUBLE_EQ(geometry->outer_tilt_rad[0], 2.0 * kAs);
  EXPECT_DOUBLE_EQ(geometry->middle_axis_rad[1], -1.5 * kAs);
  EXPECT_DOUBLE_EQ(geometry->inner_axis_rad[0], 2.1 * kAs);
  ASSERT_EQ(geometry->encoder_error[0].size(), 2u);
  EXPECT_EQ(geometry->encoder_error[0][1].k, 2);
  EXPECT_DOUBLE_EQ(geometry->encoder_error[0][0].phase_rad, units::kPi / 2);
  EXPECT_TRUE(geometry->encoder_error[1].empty());
  EXPECT_DOUBLE_EQ(sigma->encoder_error[1][0].amplitude_rad, 0.1 * kAs);
  EXPECT_EQ(sigma->middle_axis_rad[0], 0.0);  // absent: zero

  // Written and read again: the same values (arc seconds and back, to an ulp).
  const nlohmann::json again = nlohmann::json(table::table_certificate_to_json(*c));
  ObjectReader r2(again, "table", ObjectReader::ThrowAtFirst{});
  const auto c2 = table::read_table_certificate(r2);
  ASSERT_TRUE(c2);
  const std::optional<table::TableGeometry>& geometry2 = c2->geometry;
  const std::optional<table::TableGeometry>& sigma2 = c2->sigma;
  ASSERT_TRUE(geometry2 && sigma2);
  EXPECT_EQ(c2->certificate, c->certificate);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_NEAR(geometry2->outer_tilt_rad[i], geometry->outer_tilt_rad[i], 1e-20);
    EXPECT_NEAR(geometry2->middle_axis_rad[i], geometry->middle_axis_rad[i], 1e-20);
    EXPECT_NEAR(geometry2->inner_axis_rad[i], geometry->inner_axis_rad[i], 1e-20);
  }
  EXPECT_EQ(geometry2->encoder_error[0].size(), 2u);
  EXPECT_NEAR(geometry2->encoder_error[0][0].phase_rad, units::kPi / 2, 1e-15);
  EXPECT_NEAR(sigma2->encoder_error[1][0].amplitude_rad, 0.1 * kAs, 1e-20);
}

TEST(TableGeometryJson, ProblemsAreNamedByPath) {
  const auto problem = [](const std::string& text) {
    const auto j = nlohmann::json::parse(text);
    try {
      ObjectReader r(j, "table", ObjectReader::ThrowAtFirst{});
      table::read_table_certificate(r);
      r.finish();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(problem(R"({"geometry": {"outer_tilt": [1, 2]}})").find("table.geometry"), std::string::npos);
  EXPECT_NE(problem(R"({"geometry": {"outer_tilt_arcsec": [1]}})").find("table.geometry.outer_tilt_arcsec"),
            std::string::npos);
  EXPECT_NE(problem(R"({"sigma": {"middle_axis_arcsec": [1, -0.1]}})").find("table.sigma.middle_axis_arcsec[1]"),
            std::string::npos);
  EXPECT_NE(problem(R"({"geometry": {"encoder_error_arcsec": {"outer": [[1.5, 1, 0]]}}})")
                .find("table.geometry.encoder_error_arcsec.outer[0][0]"),
            std::string::npos);
  EXPECT_NE(problem(R"({"geometry": {"encoder_error_arcsec": {"outr": []}}})").find("outr"), std::string::npos);
  // Degrees by mistake.
  EXPECT_NE(problem(R"({"geometry": {"inner_axis_arcsec": [0, 7200]}})").find("table.geometry.inner_axis_arcsec[1]"),
            std::string::npos);
  EXPECT_EQ(problem(R"({"certificate": "none"})"), "accepted");
}
