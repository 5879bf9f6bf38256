// A test's own stage, to show what adding a stage takes: this folder (its runner, its report, its
// printer) and one line, the register_stage call of test_stage_registry.cpp. It measures the mean
// specific force over its window in the instrument frame and carries its start model over.
#pragma once

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "pipeline/pipeline.hpp"

namespace imucaltest::mean_force_stage {

// The stage's own result (Outcome::result holds it).
struct Result {
  Eigen::Vector3d mean_specific_force_mps2 = Eigen::Vector3d::Zero();  // instrument frame
  long long frames = 0;
};

std::optional<std::string> requirement(const std::vector<imucal::SegmentInfo>& segments,
                                       const imucal::pipeline::Settings& settings);
std::unique_ptr<imucal::pipeline::StageRun> make_run(const imucal::pipeline::StageContext& context);
void report(const imucal::pipeline::Outcome& outcome, nlohmann::json& report);
void print(const imucal::pipeline::Outcome& outcome, std::FILE* out);

}  // namespace imucaltest::mean_force_stage
