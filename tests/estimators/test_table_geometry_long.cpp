// Stage 3 on an imperfect table (issue 34): the navigation program simulated on a table with the
// errors the issue measured with (2" tilt, 3" non-perpendicularity, 1" + 0.5" encoder harmonics),
// the recording's geometry applied by the filter's table reference (attitude, velocity, position).
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include "core/units.hpp"
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
