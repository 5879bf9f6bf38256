// Accelerated simulated time: the direct + navigation campaign through the daemon's own
// sequencer, recorder and online estimators at least 100x faster than real time (slow: release).
#include <gtest/gtest.h>

#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(Speed, DirectPlusNavigationRunsAtLeast100xRealTime) {
  LocalDaemon d("speed");
  const auto id = d.post_campaign({{"name", "direct+navigation"},
                                   {"program", {"direct", "navigation"}},
                                   {"rate_hz", 100},
                                   {"time_scale", 0},
                                   {"estimators", {"direct", "navigation"}}});
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(d.command(id, "start"), 200);
  const json c = d.wait_final(id, 600);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(c.at("state"), "done") << c.dump().substr(0, 2000);
  const double program_s = c.at("duration_s").get<double>();
  const double factor = program_s / wall_s;
  std::printf("direct+navigation: %.0f s of program in %.2f s wall: %.0fx real time, %lld frames\n", program_s, wall_s,
              factor, static_cast<long long>(c.at("frames").get<std::int64_t>()));
  EXPECT_GE(factor, 100.0);
  EXPECT_EQ(c.at("results").at("direct").at("status"), "done");
  EXPECT_EQ(c.at("results").at("navigation").at("status"), "done");
}
