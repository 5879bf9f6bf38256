// A recorded run as plot series (GET /api/campaigns/{id}/series): every frame counted once, each
// column's minimum and maximum those of its frames, temperatures beside them, clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/units.hpp"
#include "service_fixture.hpp"
#include "storage/run_db.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(Series, ColumnsHoldTheMinimumAndMaximumOfTheirFrames) {
  LocalDaemon d("series");
  const auto id = d.post_campaign({{"name", "series"}, {"program", "direct-short"}, {"rate_hz", 20}, {"seed", 3},
                                   {"time_scale", 0}, {"estimators", json::array()}});
  const std::string target = "/api/campaigns/" + std::to_string(id) + "/series";
  EXPECT_EQ(d.call("GET", target).status, 404) << "never started: no recording";
  ASSERT_EQ(d.command(id, "start"), 200);
  const json done = d.wait_final(id);
  ASSERT_EQ(done.at("state"), "done");

  const auto run = storage::RunDb::open(d.run_path(done), storage::OpenMode::Read);
  const auto frames = run.read_frames();
  ASSERT_GT(frames.size(), 1000u);

  const auto r = d.call("GET", target + "?points=100");
  ASSERT_EQ(r.status, 200) << r.body;
  const json s = json::parse(r.body);
  EXPECT_EQ(s.at("format"), "imucal-series/1");
  ASSERT_EQ(s.at("t_s").size(), 100u);
  std::int64_t counted = 0;
  for (const auto& n : s.at("frames")) counted += n.get<std::int64_t>();
  EXPECT_EQ(counted, static_cast<std::int64_t>(frames.size())) << "every frame in exactly one column";

  // The whole run's extremes are the extremes of the columns (min/max decimation loses none).
  double outer_max = -1e9, outer_min = 1e9, gz_max = -1e9;
  for (const auto& f : frames) {
    outer_max = std::max(outer_max, f.table_deg[0]);
    outer_min = std::min(outer_min, f.table_deg[0]);
    gz_max = std::max(gz_max, f.dtheta_rad[2] * 20.0 * units::kRadToDeg);
  }
  const auto extreme = [](const json& channel, const char* which, bool largest) {
    double v = largest ? -1e9 : 1e9;
    for (const auto& x : channel.at(which))
      if (!x.is_null()) v = largest ? std::max(v, x.get<double>()) : std::min(v, x.get<double>());
    return v;
  };
  EXPECT_DOUBLE_EQ(extreme(s.at("table_deg").at("outer"), "max", true), outer_max);
  EXPECT_DOUBLE_EQ(extreme(s.at("table_deg").at("outer"), "min", false), outer_min);
  EXPECT_NEAR(extreme(s.at("gyro_dps").at("z"), "max", true), gz_max, 1e-9 * std::abs(gz_max));
  EXPECT_GT(gz_max, 20.0) << "direct-short turns at 30 deg/s";
  ASSERT_TRUE(s.at("temperature_C").contains("chamber")) << s.at("temperature_C").dump().substr(0, 300);
  EXPECT_NEAR(extreme(s.at("temperature_C").at("chamber"), "max", true), 25.0, 5.0);

  // A part of the run: only its frames.
  const json part = d.get(target + "?from_s=100&to_s=200&points=10");
  ASSERT_EQ(part.at("t_s").size(), 10u);
  EXPECT_DOUBLE_EQ(part.at("t_s")[0].get<double>(), 100.0);
  std::int64_t in_part = 0;
  for (const auto& n : part.at("frames")) in_part += n.get<std::int64_t>();
  const auto expected = std::count_if(frames.begin(), frames.end(),
                                      [](const ImuFrame& f) { return f.t_ns >= 100'000'000'000 && f.t_ns <= 200'000'000'000; });
  EXPECT_EQ(in_part, expected);

  // Bad requests name what is wrong.
  const auto bad_points = d.call("GET", target + "?points=0");
  EXPECT_EQ(bad_points.status, 400);
  EXPECT_NE(bad_points.body.find("points must be a number from 1 to 4000"), std::string::npos) << bad_points.body;
  const auto bad_from = d.call("GET", target + "?from_s=soon");
  EXPECT_EQ(bad_from.status, 400);
  EXPECT_NE(bad_from.body.find("from_s must be a number of seconds, not 'soon'"), std::string::npos) << bad_from.body;
  EXPECT_EQ(d.call("GET", "/api/campaigns/999/series").status, 404);
}
