// Accelerated simulated time: the direct + navigation campaign through the daemon's own
// sequencer, recorder and online estimators (stage 1, stage 3 on the navigation part from stage
// 1's model, the free-inertial display), every estimator done (slow: release). How fast it goes is
// a benchmark, not a test (bench/README.md: `imucal campaign run bench/campaign-direct-navigation.json`):
// a loaded machine must not fail the suite.
#include <gtest/gtest.h>

#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(Accelerated, DirectPlusNavigationRunsEveryEstimatorOnline) {
  LocalDaemon d("speed");
  const auto id = d.post_campaign({{"name", "direct+navigation"},
                                   {"program", {"direct", "navigation"}},
                                   {"rate_hz", 100},
                                   {"time_scale", 0},
                                   {"estimators", {"direct", "stage3", "navigation"}}});
  ASSERT_EQ(d.command(id, "start"), 200);
  // Generous: ~9 s on an idle two-core machine; the bound only stops a hung run.
  const json c = d.wait_final(id, 1800);
  ASSERT_EQ(c.at("state"), "done") << c.dump().substr(0, 2000);
  EXPECT_NEAR(c.at("duration_s").get<double>(), 10428.5, 1.0);
  EXPECT_EQ(c.at("frames").get<std::int64_t>(), 1042850);
  EXPECT_EQ(c.at("results").at("direct").at("status"), "done");
  EXPECT_EQ(c.at("results").at("navigation").at("status"), "done");
  EXPECT_EQ(c.at("results").at("stage3").at("status"), "done") << c.at("results").at("stage3").dump().substr(0, 2000);
  EXPECT_EQ(c.at("results").at("stage3").at("model").at("frame"), "body");
}
