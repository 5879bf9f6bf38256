// `imucal plan` names what a program leaves weakly observable, with the coefficient and the motion
// that would fix it, predicts in the shape of a model's sigma, and refuses a model it cannot
// predict from.
#include <gtest/gtest.h>


#include <nlohmann/json.hpp>

#include "motion_programs/program.hpp"
#include "plan/plan.hpp"

using namespace imucal;
using nlohmann::json;

namespace {

ImuModel nav_grade() { return read_imu_model_file(IMUCAL_SOURCE_DIR "/examples/truth-nav-grade.json"); }

}  // namespace

TEST(Plan, TheDirectProgramIsPredictedInTheShapeOfAModelsSigma) {
  const plan::Prediction prediction =
      plan::predict(motion::load_program("direct-short", motion::TableLimits{}), nav_grade());
  const json j = prediction.to_json();
  const json& sigma = j.at("stages").at("direct").at("sigma");
  EXPECT_EQ(j.at("stages").at("direct").at("frame"), "instrument");
  ASSERT_TRUE(sigma.contains("gyro")) << j.dump().substr(0, 500);
  EXPECT_EQ(sigma.at("gyro").at("bias_dph").size(), 3u);
  for (const auto& v : sigma.at("gyro").at("bias_dph")) EXPECT_GT(v.get<double>(), 0.0);
  EXPECT_GT(sigma.at("accel").at("misalignment_arcsec").at("zy").get<double>(), 0.0);
  EXPECT_NEAR(j.at("duration_s").get<double>(), 402.6, 1.0);
}

TEST(Plan, AModelWithoutNoiseIsRefusedWithWhatToGive) {
  ImuModel quiet = nav_grade();
  quiet.gyro.noise = {};
  quiet.accel.noise = {};
  try {
    plan::predict(motion::load_program("direct-short", motion::TableLimits{}), quiet);
    FAIL() << "predicted from a model without noise";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("arw_deg_rth"), std::string::npos) << e.what();
  }
}
