// Stage direct (stage 1): the direct calibration from statics and rotations of the table.
// The stage as one unit: what it needs, its runner, its report and its printer (the registry's
// line: pipeline/stages/registry.cpp; the estimator's math stays in estimators/).
#pragma once

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pipeline/pipeline.hpp"

namespace imucal::pipeline::direct_stage {

std::optional<std::string> requirement(const std::vector<SegmentInfo>& segments, const Settings& settings);
std::unique_ptr<StageRun> make_run(const StageContext& context);
void report(const Outcome& outcome, nlohmann::json& report);
void print(const Outcome& outcome, std::FILE* out);

}  // namespace imucal::pipeline::direct_stage
