#include "pipeline/stages/lever_arm/lever_arm_stage.hpp"

#include <utility>

#include "estimators/lever_arm.hpp"
#include "pipeline/stage.hpp"

namespace imucal::pipeline::lever_arm_stage {

using nlohmann::json;
using namespace stage_util;

namespace {

class LeverArmRun final : public StageRun {
 public:
  LeverArmRun(const RecordingMeta& meta, const ImuModel& start) : filter_(meta, start) {}
  void push(const ImuFrame& f) override { filter_.push(f); }
  void finish(const FrameSource&, const Feed&, Outcome& out) override {
    lever::Result r = filter_.finish();
    add_notes(out, r.notes);
    out.model = r.model;
    out.result = std::move(r);
  }

 private:
  lever::LeverArmFilter filter_;
};


}  // namespace

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings&) {
  if (count_kind(segments, "sine") > 0) return std::nullopt;
  return std::string("stage lever-arm needs oscillation (sine) segments; there are none (program 'lever-arm' gives them)");
}

std::unique_ptr<StageRun> make_run(const StageContext& c) { return std::make_unique<LeverArmRun>(c.meta, c.start); }

// The proof masses' positions in mm, with their sigmas.
void report(const Outcome& o, json& j) {
  const auto* r = o.result_as<lever::Result>();
  if (!r) return;
  j["updates"] = r->updates;
  json mm = json::array(), sg = json::array();
  for (int i = 0; i < 9; ++i) {
    mm.push_back(r->state_m[i] * 1e3);
    sg.push_back(r->sigma_m[i] * 1e3);
  }
  j["proof_masses_mm"] = mm;
  j["proof_masses_sigma_mm"] = sg;
}

void print(const Outcome&, std::FILE*) {}  // its notes say it all

}  // namespace imucal::pipeline::lever_arm_stage
