// The registry: every built-in stage, one line each, in pipeline order (each starts from the model
// of the stages before it). A stage is its folder (pipeline/stages/<stage>/) and its line here.
// The row's index is its id: the Stage enum names the built-in rows in this order.
#include <stdexcept>
#include <string>
#include <utility>

#include "pipeline/pipeline.hpp"
#include "pipeline/stages/direct/direct_stage.hpp"
#include "pipeline/stages/lever_arm/lever_arm_stage.hpp"
#include "pipeline/stages/navigation/navigation_stage.hpp"
#include "pipeline/stages/noise/noise_stage.hpp"
#include "pipeline/stages/rate_steps/rate_steps_stage.hpp"
#include "pipeline/stages/repeatability/repeatability_stage.hpp"
#include "pipeline/stages/thermal/thermal_stage.hpp"
#include "pipeline/stages/tumble/tumble_stage.hpp"
#include "pipeline/stages/warm_up/warm_up_stage.hpp"

namespace imucal::pipeline {

namespace {

// clang-format off
std::deque<StageDescriptor>& table() {
  namespace d = direct_stage;
  namespace rs = rate_steps_stage;
  namespace tu = tumble_stage;
  namespace la = lever_arm_stage;
  namespace th = thermal_stage;
  namespace nv = navigation_stage;
  namespace no = noise_stage;
  namespace wu = warm_up_stage;
  namespace re = repeatability_stage;
  //  id                    name             estimator        program          short program          any frame
  static std::deque<StageDescriptor> stages = {
      {Stage::Direct,        "direct",        "direct",        "direct",        "direct-short",        false, d::requirement,  d::make_run,  d::report,  d::print,  nullptr},
      {Stage::RateSteps,     "rate-steps",    "rate-steps",    "rate-steps",    "rate-steps-short",    false, rs::requirement, rs::make_run, rs::report, rs::print, rs::report_file},
      {Stage::Tumble,        "tumble",        "tumble",        "tumble",        "tumble-short",        false, tu::requirement, tu::make_run, tu::report, tu::print, nullptr},
      {Stage::LeverArm,      "lever-arm",     "lever-arm",     "lever-arm",     nullptr,               false, la::requirement, la::make_run, la::report, la::print, nullptr},
      {Stage::Thermal,       "thermal",       "thermal",       "thermal",       "thermal-short",       false, th::requirement, th::make_run, th::report, th::print, th::report_file},
      {Stage::Navigation,    "navigation",    "stage3",        "navigation",    nullptr,               true,  nv::requirement, nv::make_run, nv::report, nv::print, nullptr},
      {Stage::Noise,         "noise",         "noise",         "noise",         nullptr,               true,  no::requirement, no::make_run, no::report, no::print, nullptr},
      {Stage::WarmUp,        "warm-up",       "warm-up",       "warm-up",       "warm-up-short",       true,  wu::requirement, wu::make_run, wu::report, wu::print, wu::report_file},
      {Stage::Repeatability, "repeatability", "repeatability", "repeatability", "repeatability-short", true,  re::requirement, re::make_run, re::report, re::print, re::report_file},
  };
  return stages;
}
// clang-format on

}  // namespace

const std::deque<StageDescriptor>& stage_registry() { return table(); }

Stage register_stage(StageDescriptor descriptor) {
  std::deque<StageDescriptor>& stages = table();
  for (const StageDescriptor& s : stages)
    if (std::string(s.name) == descriptor.name || std::string(s.estimator) == descriptor.estimator)
      throw std::invalid_argument(std::string("a stage named '") + descriptor.name + "' is registered already");
  descriptor.stage = static_cast<Stage>(stages.size());
  stages.push_back(descriptor);
  return descriptor.stage;
}

const StageDescriptor& names_of(Stage stage) {
  const std::deque<StageDescriptor>& stages = table();
  const auto index = static_cast<std::size_t>(stage);
  if (index >= stages.size()) throw std::logic_error("pipeline: a stage without a name");
  return stages[index];
}

std::optional<Stage> stage_named(std::string_view name) {
  for (const StageDescriptor& s : table())
    if (name == s.name) return s.stage;
  return std::nullopt;
}

std::optional<Stage> stage_of_estimator(std::string_view estimator) {
  for (const StageDescriptor& s : table())
    if (estimator == s.estimator) return s.stage;
  return std::nullopt;
}

}  // namespace imucal::pipeline
