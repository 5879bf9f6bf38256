// The tumble over twenty noise seeds: the sigmas it states are the scatter it shows.
#include "tumble_fixture.hpp"

using namespace imucal;
using namespace imucal::tumbletest;

TEST(TumbleLong, SigmasOverTwentySeeds) {
  const ImuModel truth = tumble_truth();
  for (const char* program : {"tumble", "tumble-short"}) {
    Check check;
    check.verbose = false;
    for (std::uint64_t seed = 200; seed < 220; ++seed) check_all(check, truth, run_tumble(program, truth, 100, seed));
    const double rms = std::sqrt(check.sum_z2 / check.n);
    std::printf("%s: error/sigma RMS %.3f over %d estimates\n", program, rms, check.n);
    // 600 estimates (correlated within a run): an honest sigma gives an RMS near 1.
    EXPECT_GT(rms, 0.8) << program;
    EXPECT_LT(rms, 1.2) << program;
  }
}
