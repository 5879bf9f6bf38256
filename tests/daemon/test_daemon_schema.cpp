// GET /api/schema (issue 37): the coefficients' names, groups, units and the seed's targets as the
// browser reads them, made from the C++ tables that own them, and the copy the browser's unit
// tests read (tests/browser/schema.json) the same document.
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/coefficients.hpp"
#include "plan/optimize.hpp"
#include "service_fixture.hpp"

using namespace imucal;
using namespace imucal::daemontest;

TEST(Schema, ListsExactlyTheModelsCoefficientsWithTheirGroupsAndTheSeedTargets) {
  LocalDaemon d("schema");
  const daemon::HttpReply r = d.call("GET", "/api/schema", "", kViewerToken);
  ASSERT_EQ(r.status, 200) << r.body;
  const json schema = json::parse(r.body);
  // Every key of the model, in model_coefficients' order, none more.
  std::vector<std::string> served, model;
  for (const json& c : schema.at("coefficients")) served.push_back(c.at("key").get<std::string>());
  for (const Coefficient& c : model_coefficients(ImuModel{})) model.push_back(c.key);
  EXPECT_EQ(served, model);
  // Each names a group the document lists, with that group's unit, a title and whether optional.
  std::set<std::string> groups;
  for (const json& g : schema.at("groups")) {
    groups.insert(g.at("key").get<std::string>());
    EXPECT_FALSE(g.at("title").get<std::string>().empty());
  }
  for (const json& c : schema.at("coefficients")) {
    const std::string key = c.at("key").get<std::string>();
    ASSERT_TRUE(groups.contains(c.at("group").get<std::string>())) << key;
    EXPECT_TRUE(key.starts_with(c.at("group").get<std::string>() + ".")) << key;
    EXPECT_FALSE(c.at("title").get<std::string>().empty()) << key;
    EXPECT_TRUE(c.at("optional").is_boolean()) << key;
  }
  const auto at = [&](const std::string& key) {
    for (const json& c : schema.at("coefficients"))
      if (c.at("key") == key) return c;
    return json();
  };
  EXPECT_EQ(at("gyro.bias_dph.x").at("title"), "Gyro bias, x axis");
  EXPECT_EQ(at("gyro.bias_dph.x").at("unit"), "°/h");
  EXPECT_EQ(at("gyro.bias_dph.x").at("optional"), false);
  EXPECT_EQ(at("accel.lever_arm_mm.z.y").at("title"), "Proof-mass offset of accelerometer z, y component");
  EXPECT_EQ(at("accel.lever_arm_mm.z.y").at("stage3_state"), json({"accel_lever_arm_z_m", 1}));
  EXPECT_EQ(at("gyro.misalignment_arcsec.yz").at("stage3_state"), json({"gyro_misalignment_rad", 3}));
  EXPECT_FALSE(at("accel.k2_ug_per_g2.x").contains("stage3_state"));
  // The seed's targets, every one of them, each for a group the document lists.
  std::map<std::string, double> targets;
  for (const json& t : schema.at("seed_targets")) {
    targets[t.at("group").get<std::string>()] = t.at("sigma").get<double>();
    EXPECT_TRUE(groups.contains(t.at("group").get<std::string>())) << t;
  }
  EXPECT_EQ(targets, plan::seed_targets());
}

TEST(Schema, NeedsSigningInLikeEveryOtherRead) {
  LocalDaemon d("schema-auth");
  EXPECT_EQ(d.call("GET", "/api/schema", "", "").status, 401);
  EXPECT_EQ(d.call("POST", "/api/schema", "{}").status, 405);
}

// The browser's unit tests (tests/browser/unit.test.mjs) read the schema from a file: that file
// must be what imucald serves, or they test against names the service no longer has.
TEST(Schema, TheBrowserTestsCopyIsWhatTheServiceServes) {
  LocalDaemon d("schema-copy");
  const json served = json::parse(d.call("GET", "/api/schema", "", kViewerToken).body);
  const std::string path = imucaltest::source_dir() + "/tests/browser/schema.json";
  std::ifstream in(path);
  const json copy = in ? json::parse(in, nullptr, false) : json();
  if (copy != served) {
    const std::string fresh = imucaltest::test_tmp_dir() + "/schema.json";
    std::ofstream(fresh) << served.dump(1) << "\n";
    ADD_FAILURE() << path << " is not what GET /api/schema answers: copy " << fresh << " over it";
  }
}
