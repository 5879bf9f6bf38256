// Stage 3 on an imperfect table (issue 34): the navigation program simulated on a table with the
// errors the issue measured with (2" tilt, 3" non-perpendicularity, 1" + 0.5" encoder harmonics),
// the recording's geometry applied by the filter's table reference (attitude, velocity, position).
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>

#include "calib_fixture.hpp"
#include "core/expect_value.hpp"
#include "core/earth.hpp"
#include "core/units.hpp"
#include "estimators/direct_calibration.hpp"
#include "motion_programs/program.hpp"
#include "sim/simulator.hpp"
#include "tests/core/imperfect_table.hpp"
#include "nav_calib_fixture.hpp"

using namespace imucal;

TEST(TableGeometryLong, StageThreeOnAnImperfectTable) {
  navcaltest::Scenario s = navcaltest::make_scenario(3, 100);
  const table::TableGeometry g = tabletest::imperfect();
  s.cfg.table = table::TableCertificate{g, std::nullopt, "test table"};
  const navfilter::Result r = navcaltest::run_filter(s, "navigation", 1);
  std::printf("status: %s; updates %lld, rejected %lld, restarts %lld\n", r.status.c_str(),
              static_cast<long long>(r.updates), static_cast<long long>(r.rejected), static_cast<long long>(r.restarts));
  ASSERT_TRUE(r.converged) << r.status;
  navcaltest::expect_stage3_limits(s.truth_body, r.model);
  // The table-attitude measurement meets the table it was made on: no systematic arc seconds for
  // its gate to reject (without sensor noise on the ideal table's reference the issue counted 286 of
  // 5347 rejected).
  EXPECT_LE(r.rejected, r.updates / 1000);

  // The same recording on the ideal table's reference: outside the limits (so this test can fail).
  const auto p = motion::load_program("navigation", motion::TableLimits{});
  ImuModel truth_sim = s.truth;
  truth_sim.mount_r0_p_m.reset();
  RecordingMeta ideal = sim::Simulator(p, truth_sim, s.cfg).meta();
  ideal.table.reset();
  ImuModel start = s.start;
  start.mount_r0_p_m = s.cfg.mount.r0_p_m;
  const navfilter::Result r0 = navfilter::calibrate_offline(
      ideal, start,
      [&](const auto& fn) {
        sim::Simulator sim(p, truth_sim, s.cfg);
        ImuFrame f;
        while (sim.next(f)) fn(f);
      },
      1, navfilter::Options{});
  double worst = 0;
  {
    // Its coefficients beyond the limits are what is expected here, not failures of this test.
    ::testing::TestPartResultArray beyond;
    const ::testing::ScopedFakeTestPartResultReporter quiet(
        ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD, &beyond);
    worst = navcaltest::expect_stage3_limits(s.truth_body, r0.model);
  }
  std::printf("without the geometry: updates %lld, rejected %lld, worst ratio to the limits %.2f\n",
              static_cast<long long>(r0.updates), static_cast<long long>(r0.rejected), worst);
  EXPECT_GT(worst, 1.0);  // 3.0 when this test was written (0.30 with the geometry)
}

// Stage 1's uncertainty budget on the project's own simulator (issue 34): ten random IMUs, each on
// a table of the issue's size with its own signs and encoder phases (2" tilt, 3" axes, 1" + 0.5"
// harmonics), the certificate's sigma the errors' full size. With the geometry stage 1 is within
// its limits; without it (the certificate's sigma only) at least 90 % of the coefficients lie
// within their expanded uncertainty (k = 2) and none beyond 4 sigma, as on example-table.
namespace {

struct TablePair {
  table::TableGeometry geometry, sigma;
};
TablePair random_table_of_the_issues_size(unsigned seed) {
  constexpr double kAs = units::kArcsecToRad;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> phase(0.0, 2.0 * std::numbers::pi);
  auto sign = [&] { return rng() % 2 ? 1.0 : -1.0; };
  TablePair t;
  t.sigma.outer_tilt_rad = {2.0 * kAs, 2.0 * kAs};
  t.sigma.middle_axis_rad = {3.0 * kAs, 3.0 * kAs};
  t.sigma.inner_axis_rad = {3.0 * kAs, 3.0 * kAs};
  using Pair = std::array<double, 2> table::TableGeometry::*;
  for (const Pair member : {&table::TableGeometry::outer_tilt_rad, &table::TableGeometry::middle_axis_rad,
                            &table::TableGeometry::inner_axis_rad})
    for (std::size_t i = 0; i < 2; ++i) (t.geometry.*member)[i] = sign() * (t.sigma.*member)[i];
  for (std::size_t axis = 0; axis < 3; ++axis) {
    t.sigma.encoder_error[axis] = {{1, 1.0 * kAs, 0.0}, {2, 0.5 * kAs, 0.0}};
    t.geometry.encoder_error[axis] = {{1, 1.0 * kAs, phase(rng)}, {2, 0.5 * kAs, phase(rng)}};
  }
  return t;
}

table::TableGeometry scaled(table::TableGeometry g, double factor) {
  for (auto* pair : {&g.outer_tilt_rad, &g.middle_axis_rad, &g.inner_axis_rad})
    for (double& v : *pair) v *= factor;
  for (auto& harmonics : g.encoder_error)
    for (table::EncoderHarmonic& h : harmonics) h.amplitude_rad *= factor;
  return g;
}

// |error| / sigma of the 27 stage-1 coefficients.
std::vector<double> z_of(const ImuModel& truth, const ImuModel& est, const ImuErrorSet& s) {
  return calibtest::stage1_abs_z(truth, est, s);
}

}  // namespace

TEST(TableGeometryLong, StageOneBudgetCoversAnUnknownTable) {
  const auto p = motion::load_program("direct", motion::TableLimits{});
  std::size_t n = 0, within = 0, within_type_a = 0;
  double worst = 0, worst_type_a = 0;
  for (unsigned seed = 0; seed < 10; ++seed) {
    const ImuModel truth = calibtest::random_stage1_imu(500 + seed);
    const TablePair t = random_table_of_the_issues_size(600 + seed);
    sim::SimConfig cfg;
    cfg.rate_hz = 20;
    cfg.seed = 700 + seed;
    cfg.site.middle_axis_azimuth_deg = 20;
    // A measured g (the simulator's own): normal gravity's 30 ppm would cover the scale factors alone.
    cfg.site.gravity_mps2 = earth::normal_gravity_mps2(cfg.site.latitude_deg * units::kDegToRad, cfg.site.height_m);
    cfg.table = table::TableCertificate{t.geometry, std::nullopt, "random table"};
    sim::Simulator sim(p, truth, cfg);
    RecordingMeta meta = sim.meta();
    // With the geometry its certificate's 1-sigma a tenth of it (example-table's), without it the
    // errors' full size.
    table::TableCertificate& certificate = expect_value(meta.table, "the simulated table's certificate");
    certificate.sigma = scaled(t.sigma, 0.1);
    direct::DirectCalibrator with(meta);
    certificate.geometry.reset();
    certificate.sigma = t.sigma;
    direct::DirectCalibrator without(meta);
    ImuFrame f;
    while (sim.next(f)) {
      with.push(f);
      without.push(f);
    }
    const ImuModel with_model = with.finish().model;
    calibtest::expect_within(truth, with_model, calibtest::kStage1Limits);
    const ImuModel est = without.finish().model;
    const std::vector<double> z = z_of(truth, est, expect_value(est.sigma, "the sigma of a stage-1 result")), z_a = z_of(truth, est, est.budget.at("type_a"));
    const auto count = [](const std::vector<double>& v) {
      return static_cast<std::size_t>(std::count_if(v.begin(), v.end(), [](double x) { return x <= 2.0; }));
    };
    const double w = *std::max_element(z.begin(), z.end()), w_a = *std::max_element(z_a.begin(), z_a.end());
    std::printf("IMU %u: within k=2 %zu of %zu (worst %.2f sigma); type A alone %zu (worst %.1f)\n", seed, count(z),
                z.size(), w, count(z_a), w_a);
    EXPECT_LE(w, 4.0) << "IMU " << seed;
    n += z.size();
    within += count(z);
    within_type_a += count(z_a);
    worst = std::max(worst, w);
    worst_type_a = std::max(worst_type_a, w_a);
  }
  std::printf("all: within k=2 %zu of %zu (%.1f %%, worst %.2f sigma); type A alone %zu (%.1f %%, worst %.1f)\n", within,
              n, 100.0 * static_cast<double>(within) / static_cast<double>(n), worst, within_type_a,
              100.0 * static_cast<double>(within_type_a) / static_cast<double>(n), worst_type_a);
  EXPECT_GE(static_cast<double>(within), 0.9 * static_cast<double>(n));
}

// Stage 3's uncertainty on an imperfect table (issue 34): ten random IMUs from the seed's stage-1
// residuals, each on a random table of the issue's size, the `navigation` program with the IMU's
// noise. With the geometry (its certificate's sigma a tenth of it) and without it (the sigma the
// errors' full size: the filter considers the table's errors, weighs its attitude by them and
// states their share), stage 3 lands within its limits, at least 95 % of the coefficients within 3
// sigma, at least 90 % within the expanded uncertainty (k = 2) and none beyond 4 sigma.
TEST(TableGeometryLong, StageThreeBudgetCoversAnUnknownTable) {
  const auto p = motion::load_program("navigation", motion::TableLimits{});
  struct Tally {
    std::vector<double> z;
    double worst_limit_ratio = 0;
  };
  Tally with_geometry, without_geometry;
  for (unsigned seed = 0; seed < 10; ++seed) {
    navcaltest::Scenario s = navcaltest::make_scenario(800 + seed, 100);
    const TablePair t = random_table_of_the_issues_size(900 + seed);
    s.cfg.table = table::TableCertificate{t.geometry, std::nullopt, "random table"};
    ImuModel truth_sim = s.truth;
    truth_sim.mount_r0_p_m.reset();
    sim::Simulator sim(p, truth_sim, s.cfg);
    RecordingMeta meta = sim.meta();
    table::TableCertificate& certificate = expect_value(meta.table, "the simulated table's certificate");
    certificate.sigma = scaled(t.sigma, 0.1);
    ImuModel start = s.start;
    start.mount_r0_p_m = s.cfg.mount.r0_p_m;
    navfilter::NavCalibrationFilter with(meta, start);
    certificate.geometry.reset();
    certificate.sigma = t.sigma;
    navfilter::NavCalibrationFilter without(meta, start);
    ImuFrame f;
    while (sim.next(f)) {
      with.push(f);
      without.push(f);
    }
    const navfilter::Result rw = with.finish(), ro = without.finish();
    // The truth the filter should end at: the constant coefficients plus the biases' drift.
    ImuModel truth = s.truth_body;
    truth.gyro.bias_radps += sim.stochastic_bias().head<3>();
    truth.accel.bias_mps2 += sim.stochastic_bias().tail<3>();
    ASSERT_TRUE(rw.converged) << "IMU " << seed << ": " << rw.status;
    ASSERT_TRUE(ro.converged) << "IMU " << seed << ": " << ro.status;
    std::printf("IMU %u with the geometry (updates %lld, rejected %lld):\n", seed, static_cast<long long>(rw.updates),
                static_cast<long long>(rw.rejected));
    with_geometry.worst_limit_ratio =
        std::max(with_geometry.worst_limit_ratio, navcaltest::expect_stage3_limits(truth, rw.model, &with_geometry.z));
    std::printf("IMU %u without it, the certificate's sigma only (updates %lld, rejected %lld):\n", seed,
                static_cast<long long>(ro.updates), static_cast<long long>(ro.rejected));
    without_geometry.worst_limit_ratio = std::max(
        without_geometry.worst_limit_ratio, navcaltest::expect_stage3_limits(truth, ro.model, &without_geometry.z));
  }
  for (const auto& [name, tally] : {std::pair{"with the geometry", &with_geometry}, {"certificate only", &without_geometry}}) {
    const auto within = [&](double k) {
      return static_cast<double>(std::count_if(tally->z.begin(), tally->z.end(), [&](double z) { return z <= k; }));
    };
    const double n = static_cast<double>(tally->z.size()), worst = *std::max_element(tally->z.begin(), tally->z.end());
    std::printf("%s: worst ratio to the limits %.2f; within 3 sigma %.0f of %.0f (%.1f %%), within k=2 %.0f (%.1f %%), "
                "worst %.2f sigma\n",
                name, tally->worst_limit_ratio, within(3.0), n, 100.0 * within(3.0) / n, within(2.0),
                100.0 * within(2.0) / n, worst);
    EXPECT_GE(within(3.0), 0.95 * n) << name;
    EXPECT_GE(within(2.0), 0.90 * n) << name;
    EXPECT_LE(worst, 4.0) << name;
  }
}
