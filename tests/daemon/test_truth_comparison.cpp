// The one comparison of a model with a simulation's truth (estimators/truth_comparison.hpp), which
// GET /api/campaigns/{id}/truth and `imucal compare` both make (issue 36, item 1): the truth, written
// in the instrument frame, is compared in the model's frame; zeros by the frame's definition are
// not judged.
#include <gtest/gtest.h>

#include "core/imu_model.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/truth_comparison.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;

namespace {

ImuModel nav_grade() { return read_imu_model_file(imucaltest::source_dir() + "/examples/truth-nav-grade.json"); }

const TruthComparisonRow& row_of(const TruthComparison& c, const std::string& key) {
  for (const auto& r : c.rows)
    if (r.key == key) return r;
  throw std::runtime_error("no row " + key);
}

// A body-frame estimate equal to the truth up to `offset` in every coefficient, with a 1-sigma
// of 1 of its unit on everything the body frame leaves free.
ImuModel body_estimate(const ImuModel& truth) {
  ImuModel est = direct::to_body_frame(truth);
  ImuErrorSet sigma;
  sigma.gyro.bias_radps.setConstant(1e-9);
  sigma.gyro.misalignment_rad = {1e-7, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7};
  sigma.accel.misalignment_rad = {0.0, 0.0, 0.0, 1e-7, 1e-7, 1e-7};
  sigma.accel.scale.setConstant(1e-7);
  est.sigma = sigma;
  return est;
}

}  // namespace

TEST(TruthComparison, ABodyFrameModelIsComparedWithTheTruthTurnedIntoTheBodyFrame) {
  const ImuModel truth = nav_grade();
  ASSERT_EQ(truth.frame, "instrument");
  const TruthComparison c = compare_with_truth(body_estimate(truth), truth);
  EXPECT_EQ(c.frame, "body");
  EXPECT_EQ(c.truth_frame, "instrument");
  EXPECT_TRUE(c.converted);
  EXPECT_EQ(c.truth.frame, "body");
  // The estimate is the truth: every judged coefficient agrees, gyro angles included (against the
  // instrument-frame truth they were tens of arcseconds off, issue 36).
  for (const auto& r : c.rows) {
    EXPECT_NEAR(r.error, 0.0, 1e-9 * (1.0 + std::abs(r.truth))) << r.key;
    if (r.error_over_sigma) {
      EXPECT_LT(std::abs(*r.error_over_sigma), 1e-3) << r.key;
    }
  }
  EXPECT_GT(std::abs(row_of(c, "gyro.misalignment_arcsec.xy").truth - 21.0), 1.0)
      << "the body frame's gyro angle differs from the instrument frame's";
  for (const char* key : {"accel.misalignment_arcsec.xy", "accel.misalignment_arcsec.xz", "accel.misalignment_arcsec.yx"}) {
    const TruthComparisonRow& r = row_of(c, key);
    EXPECT_TRUE(r.by_definition) << key;
    EXPECT_FALSE(r.error_over_sigma.has_value()) << key << ": zero by definition is not judged";
    EXPECT_EQ(r.estimate, 0.0) << key;
  }
  EXPECT_FALSE(row_of(c, "accel.misalignment_arcsec.yz").by_definition);
  ASSERT_TRUE(row_of(c, "accel.misalignment_arcsec.yz").error_over_sigma.has_value());
}

TEST(TruthComparison, AnInstrumentFrameModelIsComparedAsWritten) {
  const ImuModel truth = nav_grade();
  ImuModel est = truth;
  est.gyro.bias_radps.x() += 2e-9;
  ImuErrorSet sigma;
  sigma.gyro.bias_radps.setConstant(1e-9);
  est.sigma = sigma;
  const TruthComparison c = compare_with_truth(est, truth);
  EXPECT_EQ(c.frame, "instrument");
  EXPECT_FALSE(c.converted);
  for (const auto& r : c.rows) EXPECT_FALSE(r.by_definition) << r.key;
  const TruthComparisonRow& b = row_of(c, "gyro.bias_dph.x");
  ASSERT_TRUE(b.error_over_sigma.has_value());
  EXPECT_NEAR(*b.error_over_sigma, 2.0, 1e-6);
  EXPECT_EQ(row_of(c, "gyro.misalignment_arcsec.xy").truth, 21.0);
  EXPECT_FALSE(row_of(c, "gyro.scale_pos_ppm.y").error_over_sigma.has_value()) << "no sigma, no ratio";
  // No conversion back from the body frame.
  EXPECT_THROW(compare_with_truth(est, direct::to_body_frame(truth)), std::invalid_argument);
  EXPECT_TRUE(zero_by_frame_definition("body", "accel.misalignment_arcsec.xz"));
  EXPECT_FALSE(zero_by_frame_definition("instrument", "accel.misalignment_arcsec.xz"));
  EXPECT_FALSE(zero_by_frame_definition("body", "gyro.misalignment_arcsec.xz"));
}
