// Stage 1 (direct) on bundles from a generator that shares no code with the project's simulator
// (independent_bundle.*): the bundle is imported as `imucal import` does and calibrated as
// `imucal calibrate --stage direct` does; every coefficient must meet the stage-1 limits and lie
// within 3 of its own sigma.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <nlohmann/json.hpp>

#include "independent_cases.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal_test::cases;
namespace gen = imucal_test::gen;

// ---- the generator checks itself against the conventions' own statements, independently of
// ---- the project's code
TEST(IndependentGenerator, KinematicsFollowTheConventions) {
  gen::Site site;
  site.middle_axis_azimuth_deg = 30;
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
  const double A = 30.0 * std::numbers::pi / 180.0;
  // All-zero angles: xi along azimuth A from North, zeta Up, eta = zeta x xi.
  const gen::Quat q0 = gen::platform_to_level(Eigen::Vector3d::Zero(), 30);
  EXPECT_LT((gen::rotate(q0, X) - Eigen::Vector3d(std::sin(A), std::cos(A), 0)).norm(), 1e-15);
  EXPECT_LT((gen::rotate(q0, Y) - Eigen::Vector3d(-std::cos(A), std::sin(A), 0)).norm(), 1e-15);
  // middle = atan(sqrt 2), inner = 45: the platform diagonal points Up.
  const gen::Quat qd = gen::platform_to_level({17, std::atan(std::sqrt(2.0)) * 180 / std::numbers::pi, 45}, 30);
  EXPECT_LT((gen::rotate(qd, Eigen::Vector3d(1, 1, 1).normalized()) - Z).norm(), 1e-15);
  // The inertial rate integrates to the attitude: compare q(t+h) with q(t) turned by w h.
  gen::Config cfg;
  cfg.site = site;
  cfg.start_deg = {10, 20, 30};
  cfg.steps = {{"o", "move", 0, 0, 50, 10, 2}, {"m", "move", 1, 0, -70, 10, 2}, {"i", "move", 2, 0, 100, 10, 2}};
  const gen::Program p(cfg);
  const double W = gen::kEarthRate_radps, lat = site.latitude_deg * std::numbers::pi / 180.0;
  for (double t = 0.5; t < p.duration_s(); t += 1.7) {
    const double h = 1e-4;
    const gen::TableState s0 = p.at(t - h), s1 = p.at(t + h), sm = p.at(t);
    // o seen from inertial space: the level frame turns about the Earth's axis at W.
    auto inertial = [&](const gen::TableState& s, double tt) {
      const Eigen::Vector3d pole(0, std::cos(lat), std::sin(lat));
      return gen::about_axis(pole, W * tt) * gen::platform_to_level(s.angle_deg, 30);
    };
    const gen::Quat dq = gen::conjugate(inertial(s0, t - h)) * inertial(s1, t + h);
    const Eigen::Vector3d w_fd = Eigen::Vector3d(dq.x, dq.y, dq.z) * (dq.w >= 0 ? 2.0 : -2.0) / (2 * h);
    EXPECT_LT((w_fd - gen::platform_inertial_rate(sm, site)).norm(), 5e-9) << "t = " << t;
  }
  // Sensor axes: "xy" turns sensor x about instrument y, so x gains -xy along z (right-handed).
  gen::Angles a;
  a.xy = 1000;
  const Eigen::Matrix3d D = gen::sensor_axes(a);
  EXPECT_LT(D(0, 2), 0.0);
  EXPECT_NEAR(D(0, 2), -1000.0 / 206264.80624709636, 1e-15);
  // WGS-84 normal gravity on the ellipsoid at the pole, 9.8321849378 m/s^2 (published value).
  EXPECT_NEAR(gen::normal_gravity_mps2(90, 0), 9.8321849378, 1e-10);
  // Rest to rest: each turn starts and ends at zero rate on its exact angle.
  const gen::TableState end = p.at(p.duration_s());
  EXPECT_EQ(end.angle_deg, Eigen::Vector3d(60, -50, 130));
  EXPECT_EQ(end.rate_dps, Eigen::Vector3d::Zero());
}

// The seeds are fixed: with honest sigmas, "every one of 54 coefficients within 3 sigma" fails on
// about one random draw in seven (the slow test_direct_independent_long checks over twenty IMUs
// that err/sigma has unit spread and that every IMU meets the limits).
TEST(IndependentBundle, DirectCalibrationWithSegments) {
  const gen::Config cfg = direct_config(21, 20.0, 60.0);
  run_case(cfg, "independent-direct-segments", 30);
}

TEST(IndependentBundle, DirectCalibrationFindsStaticsFromTheTableAngles) {
  gen::Config cfg = direct_config(25, 20.0, 60.0);
  cfg.write_segments = false;
  cfg.site.gravity_mps2.reset();  // and the project's normal gravity against the generator's
  run_case(cfg, "independent-direct-nosegments", 30);
}

// Without noise the estimator must return the generator's truth up to the two models' numerical
// differences: this separates a modelling disagreement from bad luck in the noise.
TEST(IndependentBundle, NoiseFreeBundleCalibratesExactly) {
  gen::Config cfg = direct_config(23, 20.0, 60.0);
  cfg.truth.arw_deg_rth = cfg.truth.vrw_mps_rth = 0;
  cfg.site.gravity_mps2.reset();  // the project's normal gravity against the generator's
  const calibtest::Limits tight{2e-6, 1e-3, 1e-3, 1e-8, 1e-3, 1e-3};  // a thousandth of the stage-1 limits
  run_case(cfg, "independent-direct-noisefree", 30, tight, false);
}


// ---- an imperfect table (CONVENTIONS.md, "The table's own errors")

namespace {

// The largest |error| / limit over every stage-1 coefficient.
double worst_ratio(const ImuModel& truth, const ImuModel& est) {
  double worst = 0;
  for (const auto& [group, w] : worst_errors(truth, est))
    worst = std::max(worst, w.first / limit_of(group, calibtest::kStage1Limits));
  return worst;
}

}  // namespace

// The independent simulator's run on a table with a 2" leaning outer axis, 3" non-perpendicular
// axes and 1" + 0.5" encoder harmonics (tests/data/example-table/README.md): the recording's
// table.geometry, applied by the reference, brings stage 1 within its limits and its sigma.
TEST(IndependentBundle, ImperfectTableCalibratesWithItsGeometry) {
  std::filesystem::create_directories(imucaltest::test_tmp_dir());
  const Outcome out = import_and_calibrate(imucaltest::test_data_dir() + "/example-table", "example-table");
  const auto run = storage::RunDb::open(imucaltest::test_tmp_dir() + "/example-table.db");
  const auto table = run.meta().table;
  ASSERT_TRUE(table && table->geometry) << "the import keeps the table's certificate";
  const ImuModel truth = read_imu_model_file(imucaltest::test_data_dir() + "/example-table/truth.json");
  calibtest::expect_within(truth, out.result.model, calibtest::kStage1Limits);
  print_worst(truth, out.result.model);
  std::printf("  worst error / limit with the table's geometry: %.3f\n", worst_ratio(truth, out.result.model));
}

namespace {

// The example-table recording with its meta.json edited, imported and calibrated as the command
// line does.
template <class Edit>
Outcome example_table_with(const std::string& name, const Edit& edit) {
  const std::filesystem::path dir = std::filesystem::path(imucaltest::test_tmp_dir()) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::filesystem::create_symlink(std::filesystem::absolute(imucaltest::test_data_dir() + "/example-table/frames.csv"),
                                  dir / "frames.csv");
  {
    std::ifstream in(imucaltest::test_data_dir() + "/example-table/meta.json");
    nlohmann::json meta = nlohmann::json::parse(in);
    edit(meta);
    std::ofstream(dir / "meta.json") << meta.dump(1);
  }
  return import_and_calibrate(dir.string(), name);
}

// The README's second use: no geometry, the certificate's sigma times ten (the errors' full size).
void delete_geometry_and_widen_sigma(nlohmann::json& meta) {
  nlohmann::json& table = meta["table"];
  table.erase("geometry");
  nlohmann::json& sigma = table["sigma"];
  for (const char* key : {"outer_tilt_arcsec", "middle_axis_arcsec", "inner_axis_arcsec"})
    for (auto& v : sigma[key]) v = v.get<double>() * 10.0;
  for (auto& [axis, terms] : sigma["encoder_error_arcsec"].items())
    for (auto& term : terms) term[1] = term[1].get<double>() * 10.0;  // [k, a, phi]: the amplitude
}

// How many of the 27 stage-1 coefficients lie within k sigma, and the largest |error| / sigma.
struct Coverage {
  std::size_t n = 0, within = 0;
  double worst = 0;
};
Coverage coverage(const ImuModel& truth, ImuModel est, const ImuErrorSet& sigma, double k) {
  est.sigma = sigma;
  std::map<std::string, std::vector<double>> z;
  collect_z(truth, est, z);
  Coverage c;
  for (const auto& [group, v] : z)
    for (const double x : v) {
      ++c.n;
      c.within += std::abs(x) <= k;
      c.worst = std::max(c.worst, std::abs(x));
    }
  return c;
}

}  // namespace

// The same recording with its geometry deleted: the ideal table's reference misses the limits
// many times over (14.5x when this test was written), which is what the geometry must remove.
TEST(IndependentBundle, ImperfectTableMissesTheLimitsWithoutItsGeometry) {
  const Outcome out =
      example_table_with("example-table-no-geometry", [](nlohmann::json& meta) { meta["table"].erase("geometry"); });
  const ImuModel truth = read_imu_model_file(imucaltest::test_data_dir() + "/example-table/truth.json");
  const double worst = worst_ratio(truth, out.result.model);
  std::printf("  worst error / limit on the ideal table's reference: %.2f\n", worst);
  EXPECT_GT(worst, 5.0);
}

// Issue 34's acceptance: without the geometry (the certificate's sigma at the errors' full size)
// the errors cannot be removed, so the stated uncertainty must cover them: at least 90 % of the 27
// coefficients within their expanded uncertainty (k = 2), none beyond 4 sigma. The fit's own
// sigma (the budget's type_a, all there was before) covers far fewer.
TEST(IndependentBundle, ImperfectTableWithoutItsGeometryIsCoveredByTheBudget) {
  const Outcome out = example_table_with("example-table-certificate-only", delete_geometry_and_widen_sigma);
  const ImuModel truth = read_imu_model_file(imucaltest::test_data_dir() + "/example-table/truth.json");
  const ImuModel& est = out.result.model;
  ASSERT_TRUE(est.sigma.has_value());
  ASSERT_TRUE(est.budget.count("type_a")) << "the budget lists the fit's own sigma";
  for (const char* source : {"table.outer_tilt_arcsec", "table.middle_axis_arcsec", "table.inner_axis_arcsec",
                             "table.encoder_error_arcsec.outer", "table.encoder_error_arcsec.middle",
                             "table.encoder_error_arcsec.inner", "site.gravity_mps2"})
    EXPECT_TRUE(est.budget.count(source)) << source;
  const Coverage before = coverage(truth, est, est.budget.at("type_a"), 2.0);
  const Coverage after = coverage(truth, est, *est.sigma, 2.0);
  std::printf("  within k=2: type A alone %zu of %zu (worst %.1f sigma), combined %zu of %zu (worst %.2f sigma)\n",
              before.within, before.n, before.worst, after.within, after.n, after.worst);
  ASSERT_EQ(after.n, 27u);
  EXPECT_GE(static_cast<double>(after.within), 0.9 * static_cast<double>(after.n));
  EXPECT_LE(after.worst, 4.0);
}

// With the geometry the budget still holds its uncertainty (the certificate's sigma as given): the
// combined sigma is the type A and the table's sources in root-sum-square, coefficient by
// coefficient, and the model with its budget reads back as written.
namespace {

// One gyro misalignment angle of a result with a budget: its sigma is the root sum of squares of
// the budget's sources, and the table's three axis errors each move it. (This and the next are
// functions of their own: clang-tidy 16's optional-access analysis crashed on the test's body while
// it held both the optional sigma and structured-binding loops; here the sigma is a plain reference.)
void expect_gyro_angle_budget(const ImuModel& est, const ImuErrorSet& sigma, const MisalignmentKey& key) {
  const double rad_to_arcsec = 180.0 / std::numbers::pi * 3600.0;
  double sum_sq = 0;
  for (const auto& [source, set] : est.budget) sum_sq += std::pow(set.gyro.misalignment_rad.*key.member, 2);
  EXPECT_NEAR(std::sqrt(sum_sq), sigma.gyro.misalignment_rad.*key.member, 1e-12) << key.name;
  EXPECT_GT(est.budget.at("table.outer_tilt_arcsec").gyro.misalignment_rad.*key.member +
                est.budget.at("table.middle_axis_arcsec").gyro.misalignment_rad.*key.member +
                est.budget.at("table.inner_axis_arcsec").gyro.misalignment_rad.*key.member,
            0.0)
      << key.name << ": the table's axes move every gyro angle";
  std::printf("  gyro.misalignment_arcsec.%s sigma %.4f (type A %.4f)\n", key.name,
              sigma.gyro.misalignment_rad.*key.member * rad_to_arcsec,
              est.budget.at("type_a").gyro.misalignment_rad.*key.member * rad_to_arcsec);
}

// Every source of `est`'s budget in `back` with the same values (a JSON round trip).
void expect_same_budget(const ImuModel& back, const ImuModel& est) {
  for (const auto& [source, set] : est.budget) {
    ASSERT_TRUE(back.budget.count(source)) << source;
    EXPECT_NEAR(back.budget.at(source).gyro.bias_radps[0], set.gyro.bias_radps[0], 1e-9 * set.gyro.bias_radps[0] + 1e-30);
    EXPECT_NEAR(back.budget.at(source).accel.scale[2], set.accel.scale[2], 1e-9 * set.accel.scale[2] + 1e-30);
  }
}

}  // namespace

TEST(IndependentBundle, ImperfectTableBudgetAddsUpAndRoundTrips) {
  const Outcome out = import_and_calibrate(imucaltest::test_data_dir() + "/example-table", "example-table-budget");
  const ImuModel& est = out.result.model;
  const std::optional<ImuErrorSet>& sigma = est.sigma;
  ASSERT_TRUE(sigma.has_value());
  for (const MisalignmentKey& key : kMisalignmentKeys) expect_gyro_angle_budget(est, *sigma, key);
  const ImuModel back = imu_model_from_json_text(imu_model_to_json_text(est), "budget round trip");
  ASSERT_EQ(back.budget.size(), est.budget.size());
  expect_same_budget(back, est);
}
