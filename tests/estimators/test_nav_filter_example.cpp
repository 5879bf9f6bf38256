// Stage 3 on a recording imucal did not make: ../shared/data/example-navigation, a noise-free
// navigation-style run from an independent simulator (proof masses tens of mm apart, every channel
// with its own delay; its README). Started from its start model, stage 3 must return every
// coefficient within three times the seed's 1-sigma figures, as on imucal's own simulator.
#include <filesystem>

#include <gtest/gtest.h>

#include "estimators/direct_calibration.hpp"
#include "nav_calib_fixture.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;

namespace {
// CI checks the project out beside ../shared (the brief); a missing example is a failure, not a skip.
const std::string kExample = imucaltest::source_dir() + "/../shared/data/example-navigation";
}  // namespace

TEST(NavFilterExample, IndependentRecordingWithinTheSeedsLimits) {
  ASSERT_TRUE(std::filesystem::exists(kExample + "/frames.csv"))
      << kExample << " missing: the suite expects ../shared beside the checkout";
  std::filesystem::create_directories(imucaltest::test_tmp_dir());
  const std::string db_path = imucaltest::test_tmp_dir() + "/example-navigation.db";
  std::filesystem::remove(db_path);
  storage::import_bundle(kExample, db_path);
  const auto db = storage::RunDb::open(db_path);
  const ImuModel start = read_imu_model_file(kExample + "/start-model.json");
  const ImuModel truth_body = direct::to_body_frame(read_imu_model_file(kExample + "/truth.json"));
  const navfilter::Result r = navfilter::calibrate_offline(
      db.meta(), start, [&](const auto& fn) { db.for_each_frame(fn); }, 1, navfilter::Options{}, db.temps());
  ASSERT_TRUE(r.converged) << r.status;
  std::printf("updates %lld, rejected %lld\n", static_cast<long long>(r.updates), static_cast<long long>(r.rejected));
  navcaltest::expect_stage3_limits(truth_body, r.model);
  // Seed ch. 4: the gyro delays relative to gyro x to 0.2 us (1 sigma).
  const double tau_yx = truth_body.gyro.delay_s[1] - truth_body.gyro.delay_s[0];
  const double tau_zx = truth_body.gyro.delay_s[2] - truth_body.gyro.delay_s[0];
  EXPECT_LE(std::abs(r.tau_yx_s - tau_yx) * 1e6, 0.6);
  EXPECT_LE(std::abs(r.tau_zx_s - tau_zx) * 1e6, 0.6);
  // The proof-mass offsets the filter refined from the start model's 0.1 mm.
  const Eigen::Matrix3d est = proof_mass_offsets_m(r.model), truth = proof_mass_offsets_m(truth_body);
  ASSERT_TRUE(r.model.sigma.has_value());  // the filter's model carries its sigma
  const ImuErrorSet& model_sigma = *r.model.sigma;
  for (int c = 1; c < 3; ++c)
    for (int i = 0; i < 3; ++i) {
      const double sigma = (c == 1 ? model_sigma.accel.lever_arm_y_m : model_sigma.accel.lever_arm_z_m)[i];
      std::printf("  proof mass %c [%d]: err %+.4f mm, sigma %.4f mm\n", "xyz"[c], i, (est(i, c) - truth(i, c)) * 1e3,
                  sigma * 1e3);
      EXPECT_LE(std::abs(est(i, c) - truth(i, c)), 3 * sigma) << c << " " << i;
    }
}
