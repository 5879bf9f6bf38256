// Motion programs: analytic functions, built-ins, validation against the table's limits.
#include <cmath>

#include <gtest/gtest.h>

#include "core/units.hpp"
#include "motion_programs/program.hpp"

using namespace imucal;
using namespace imucal::motion;

namespace {
bool contains(const std::vector<std::string>& v, const std::string& needle) {
  for (const auto& s : v)
    if (s.find(needle) != std::string::npos) return true;
  return false;
}
}  // namespace

TEST(Program, BuiltinsCompileAndPassTheDefaultLimits) {
  const TableLimits limits;
  for (const auto& name : builtin_program_names()) {
    const Program p = compile_program(builtin_program_json(name), limits);
    EXPECT_GT(p.duration_s(), 0) << name;
    const auto problems = validate_program(p, limits);
    EXPECT_TRUE(problems.empty()) << name << ": " << (problems.empty() ? "" : problems.front());
  }
}

TEST(Program, DirectHoldsTwentyMinutesOfStatics) {
  const Program p = load_program("direct", TableLimits{});
  double statics = 0;
  int rate_plus = 0, rate_minus = 0;
  for (const auto& s : p.segments()) {
    if (s.kind == "static") statics += s.t1_s - s.t0_s;
    if (s.kind == "rate") (s.name.back() == '+' ? rate_plus : rate_minus)++;
  }
  EXPECT_GE(statics, 1200.0);
  EXPECT_EQ(rate_plus, 3);
  EXPECT_EQ(rate_minus, 3);
}

TEST(Program, NavigationProgramHasTheSeedsThreeParts) {
  const Program p = load_program("navigation", TableLimits{});
  EXPECT_GT(p.duration_s(), 2.0 * 3600.0);
  int slow = 0, diag = 0, single = 0;
  for (const auto& s : p.segments()) {
    if (s.name.rfind("swing-", 0) == 0) ++slow;
    if (s.name == "diagonal-osc") ++diag;
    if (s.name.rfind("osc-", 0) == 0) ++single;
  }
  EXPECT_EQ(slow, 6);
  EXPECT_EQ(diag, 1);
  EXPECT_EQ(single, 3);
}

// Every piece's analytic rate and acceleration are the derivatives of its angle.
TEST(Program, RatesAreDerivativesOfAngles) {
  const std::string json = R"({"name":"t","segments":[
    {"type":"hold","duration_s":2},
    {"type":"move","to_deg":[30,-40,50]},
    {"type":"rate","axis":"inner","rate_dps":25,"revolutions":1.5,"accel_dps2":40},
    {"type":"sine","axis":"middle","amplitude_deg":20,"period_s":4,"cycles":3,"phase_deg":0,"ramp_s":3},
    {"type":"coning","axes":["outer","inner"],"amplitude_deg":[5,8],"period_s":2,"cycles":5},
    {"type":"tilts","positions_deg":[[0,10,0],[0,0,0]],"dwell_s":3}]})";
  const Program p = compile_program(json, TableLimits{});
  EXPECT_TRUE(validate_program(p, TableLimits{}).empty());
  const double h = 1e-5;
  for (double t = 0.05; t < p.duration_s(); t += 0.37) {
    const auto a = p.evaluate(t), ap = p.evaluate(t + h), am = p.evaluate(t - h);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR((ap.angle_rad[k] - am.angle_rad[k]) / (2 * h), a.rate_radps[k], 1e-6) << "t=" << t << " axis " << k;
      EXPECT_NEAR((ap.rate_radps[k] - am.rate_radps[k]) / (2 * h), a.accel_radps2[k], 2e-4) << "t=" << t;
    }
  }
  // The rate run turns exactly 1.5 revolutions on the inner axis.
  double start = 0, end = 0;
  for (const auto& s : p.segments())
    if (s.kind == "rate") {
      start = p.evaluate(s.t0_s).angle_rad[2];
      end = p.evaluate(s.t1_s).angle_rad[2];
    }
  EXPECT_NEAR((end - start) * units::kRadToDeg, 540.0, 1e-9);
}

TEST(Program, LimitViolationsNameSegmentAxisAndLimit) {
  const std::string json = R"({"name":"fast","segments":[
    {"type":"hold","duration_s":1},
    {"type":"rate","name":"too-fast","axis":"middle","rate_dps":400,"duration_s":10,"accel_dps2":100}]})";
  TableLimits limits;
  const auto problems = validate_program(compile_program(json, limits), limits);
  EXPECT_TRUE(contains(problems, "segment 'too-fast'")) << problems.size();
  EXPECT_TRUE(contains(problems, "axis middle: rate 400 deg/s exceeds the limit 300 deg/s"));
  // Beyond the table's rate, too few revolutions for the ramps is not the problem named: the rate is.
  const std::string few = R"({"name":"few","segments":[
    {"type":"rate","name":"spin","axis":"outer","rate_dps":400,"revolutions":1,"accel_dps2":100}]})";
  const auto few_problems = validate_program(compile_program(few, limits), limits);
  EXPECT_TRUE(contains(few_problems, "axis outer: rate 400 deg/s exceeds the limit 300 deg/s"));
  // Within the limits the ramps are judged as before.
  const std::string within = R"({"name":"few","segments":[
    {"type":"rate","name":"spin","axis":"outer","rate_dps":290,"revolutions":0.5,"accel_dps2":100}]})";
  EXPECT_THROW(compile_program(within, limits), std::exception);

  limits.axis[2].min_deg = -90;
  limits.axis[2].max_deg = 90;
  const std::string range = R"({"name":"r","segments":[{"type":"move","name":"far","to_deg":[0,0,120]}]})";
  EXPECT_TRUE(contains(validate_program(compile_program(range, limits), limits), "segment 'far'"));
  EXPECT_TRUE(contains(validate_program(compile_program(range, limits), limits), "axis inner: angle range"));

  TableLimits slow;
  slow.axis[0].accel_dps2 = 10;
  const std::string sine = R"({"name":"s","segments":[{"type":"sine","name":"osc","axis":"outer",
      "amplitude_deg":90,"period_s":10,"cycles":1}]})";
  EXPECT_TRUE(contains(validate_program(compile_program(sine, slow), slow), "axis outer: acceleration"));
}

TEST(Program, RateJumpsAreRefused) {
  const std::string json = R"({"name":"j","segments":[{"type":"sine","name":"jump","axis":"outer",
      "amplitude_deg":10,"period_s":5,"cycles":2,"phase_deg":0}]})";
  const auto problems = validate_program(compile_program(json, TableLimits{}), TableLimits{});
  EXPECT_TRUE(contains(problems, "segment 'jump' (t=0.0 s) axis outer: the rate jumps")) << problems.size();
}

TEST(Program, BadJsonNamesTheSegment) {
  try {
    compile_program(R"({"name":"x","segments":[{"type":"hold","duration_s":1},{"type":"sine","axis":"side"}]})",
                    TableLimits{});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("segment 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unknown axis \"side\""), std::string::npos) << e.what();
  }
  EXPECT_THROW(compile_program(R"({"segments":[{"type":"spin"}]})", TableLimits{}), std::invalid_argument);
  EXPECT_THROW(load_program("no-such-program", TableLimits{}), std::invalid_argument);
}

TEST(Program, AMisspeltOptionalKeyIsRefusedNotDefaulted) {
  // "rampp_s" would otherwise leave ramp_s at its default of 0 without a word.
  const auto error_of = [](const std::string& json) {
    try {
      compile_program(json, TableLimits{});
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(error_of(R"({"segments":[{"type":"sine","name":"osc","axis":"inner","amplitude_deg":10,"period_s":10,)"
                     R"("cycles":2,"rampp_s":1}]})"),
            "program segment 1 'osc': unknown key \"rampp_s\"");
  // A key of another segment type is as wrong: a hold has no rate.
  EXPECT_EQ(error_of(R"({"segments":[{"type":"hold","duration_s":5,"rate_dps":10}]})"),
            "program segment 1 'hold-1': unknown key \"rate_dps\"");
  EXPECT_EQ(error_of(R"({"segments":[{"type":"hold","duration_s":5}],"segmnets":[]})"), "program unknown key \"segmnets\"");
  // '_' keys are comments.
  EXPECT_EQ(error_of(R"({"_why":"x","segments":[{"type":"hold","duration_s":5,"_note":"settle"}]})"), "accepted");
}
