// Issue 33's acceptance: the disk filled during a `full` run (direct, lever-arm, navigation,
// evaluate: 6.2 h of program, 2.2 M frames at 100 Hz) at the fastest time scale. The run suspends
// with the operator's alarm ("disk full: at least N MB free needed ..."), resumes when space
// returns, and ends `done` with every frame of the program once, bit for bit the frames of the
// same program and seed simulated straight through. Recording only (no online estimator): the
// stages' online results on `full` are test_daemon_full's.
#include <gtest/gtest.h>

#include "disk_full_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(DaemonDiskFullLong, TheFullProgramAtTheFastestTimeScaleSurvivesAFullDiskWithEveryFrameOnce) {
  LocalDaemon d("disk-full-long");
  const json campaign = {{"name", "full, disk full"}, {"program", "full"},     {"rate_hz", 100}, {"seed", 11},
                         {"time_scale", 0},           {"truth", noisy_truth()}, {"estimators", json::array()}};
  const auto started = std::chrono::steady_clock::now();
  const DiskFullRun r = run_with_a_full_disk(d, campaign, 3.0, 1200);
  const double took_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::printf("full program: %zu frames, suspended after %.1f s, whole test %.1f s\n", r.reference_frames,
              r.suspended_after_s, took_s);
  EXPECT_GT(r.reference_frames, 2'000'000u);
  EXPECT_EQ(r.refused_post, 503) << r.refused_post_body;
  EXPECT_EQ(r.campaign.at("state"), "done");
}
