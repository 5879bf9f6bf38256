// The rate-steps test over twenty noise seeds: the degree of the nonlinearity is chosen right every
// time (none invented, none missed), and the sigmas it states are the scatter it shows.
#include "rate_steps_fixture.hpp"

using namespace imucal;
using namespace imucal::ratestepstest;

TEST(RateStepsLong, DegreesAndSigmasOverTwentySeeds) {
  ImuModel cubic = nonlinear_truth();
  cubic.gyro.scale_nonlinear.row(2) = Eigen::RowVector3d(-2.0, 2.0, 0.3) * 1e-6;
  struct Case {
    const char* program;
    const ImuModel* truth;
    std::array<int, 3> degree;
  };
  const ImuModel quadratic = nonlinear_truth();
  const Case cases[] = {{"rate-steps-short", &quadratic, {0, 2, 2}}, {"rate-steps", &cubic, {0, 2, 3}}};
  for (const Case& c : cases) {
    int wrong = 0;
    double ss_scale = 0, ss_step = 0;
    int n_scale = 0, n_step = 0;
    for (std::uint64_t seed = 100; seed < 120; ++seed) {
      const rate_steps::Result r = run_rate_steps(c.program, *c.truth, 100, seed);
      for (int j = 0; j < 3; ++j) {
        const rate_steps::Axis& ax = r.axes[static_cast<std::size_t>(j)];
        wrong += ax.degree != c.degree[static_cast<std::size_t>(j)];
        const double zp = (ax.scale_pos_ppm - c.truth->gyro.scale_pos[j] * 1e6) / ax.scale_pos_sigma_ppm;
        const double zn = (ax.scale_neg_ppm - c.truth->gyro.scale_neg[j] * 1e6) / ax.scale_neg_sigma_ppm;
        ss_scale += zp * zp + zn * zn;
        n_scale += 2;
        for (const rate_steps::Step& st : ax.steps) {
          const double z = (st.scale_ppm - truth_scale_ppm(*c.truth, j, st.rate_dps)) / st.sigma_ppm;
          ss_step += z * z;
          ++n_step;
        }
      }
    }
    const double rms_scale = std::sqrt(ss_scale / n_scale), rms_step = std::sqrt(ss_step / n_step);
    std::printf("%s: %d wrong degrees of 60; error/sigma RMS: scale factors %.3f (%d), steps %.3f (%d)\n", c.program,
                wrong, rms_scale, n_scale, rms_step, n_step);
    EXPECT_EQ(wrong, 0) << c.program;
    // An honest sigma gives an RMS near 1: 120 independent ones would stay within 0.81 .. 1.20 at
    // 99.9 %; the two scale factors of a gyro share its nonlinear terms, hence the wider band.
    EXPECT_GT(rms_scale, 0.75) << c.program;
    EXPECT_LT(rms_scale, 1.25) << c.program;
    EXPECT_GT(rms_step, 0.75) << c.program;
    EXPECT_LT(rms_step, 1.25) << c.program;
  }
}

// Issue 34's cubic: c3 = 0.2 ppm alone (CONVENTIONS.md's q = 1 at 100 deg/s: 5.4 ppm at 300 deg/s)
// on gyro z, over twenty IMUs' noise, on each ladder: how often the degree rule finds it. The full
// ladder, which `imucal plan` recommends for a unit with a cubic term, must find it in 19 of 20 at
// least (measured: 20; the short one 19, with one term invented on gyro x, which has none).
TEST(RateStepsLong, ACubicOfPointTwoPpmOverTwentySeeds) {
  ImuModel truth = nonlinear_truth();
  truth.gyro.scale_nonlinear.row(2) = Eigen::RowVector3d(0.0, 0.0, 0.2) * 1e-6;
  for (const char* program : {"rate-steps-short", "rate-steps"}) {
    int found = 0, invented = 0;
    for (std::uint64_t seed = 200; seed < 220; ++seed) {
      const rate_steps::Result r = run_rate_steps(program, truth, 100, seed);
      found += r.axes[2].degree == 3;
      invented += r.axes[0].degree != 0;
    }
    std::printf("%s: cubic found in %d of 20, a term invented on gyro x in %d\n", program, found, invented);
    if (std::string(program) == "rate-steps") {
      EXPECT_GE(found, 19);
      EXPECT_EQ(invented, 0);
    }
  }
}
