#include "plan/budget.hpp"

#include <algorithm>
#include <cmath>

#include "core/coefficients.hpp"

namespace imucal::plan {

Targets stage1_limits(const direct::Limits& l) {
  return {{"gyro.bias_dph", l.gyro_bias_dph},           {"gyro.scale_pos_ppm", l.gyro_scale_ppm},
          {"gyro.scale_neg_ppm", l.gyro_scale_ppm},      {"gyro.misalignment_arcsec", l.gyro_angle_arcsec},
          {"accel.bias_mps2", l.accel_bias_mps2},        {"accel.scale_ppm", l.accel_scale_ppm},
          {"accel.misalignment_arcsec", l.accel_angle_arcsec}};
}

Targets stage3_limits(const navfilter::Limits& l) {
  return {{"gyro.bias_dph", l.gyro_bias_dph},           {"gyro.scale_pos_ppm", l.gyro_scale_ppm},
          {"gyro.scale_neg_ppm", l.gyro_scale_ppm},      {"gyro.misalignment_arcsec", l.gyro_angle_arcsec},
          {"gyro.delay_us", l.gyro_delay_us},            {"accel.bias_mps2", l.accel_bias_mps2},
          {"accel.scale_ppm", l.accel_scale_ppm},        {"accel.misalignment_arcsec", l.accel_angle_arcsec},
          {"accel.delay_us", l.accel_delay_us}};
}

std::vector<CoefficientBudget> coefficient_budgets(const ImuModel& model) {
  // Each source's entries named and in their units as the sigma's are (model_coefficients).
  const auto named = [](const ImuErrorSet& set) {
    ImuModel m;
    m.sigma = set;
    return model_coefficients(m);
  };
  std::vector<CoefficientBudget> out;
  for (const Coefficient& c : model_coefficients(model)) out.push_back({c.key, c.group, c.sigma, {}, ""});
  for (const auto& [source, set] : model.budget) {
    const std::vector<Coefficient> entries = named(set);
    for (std::size_t i = 0; i < entries.size(); ++i)
      if (entries[i].sigma > 0) out[i].contributions[source] = entries[i].sigma;
  }
  std::erase_if(out, [](const CoefficientBudget& b) { return b.contributions.empty(); });
  for (CoefficientBudget& b : out)
    b.dominant = std::max_element(b.contributions.begin(), b.contributions.end(), [](const auto& x, const auto& y) {
                   return x.second < y.second;
                 })->first;
  return out;
}

SourceRequirement source_requirement(const std::vector<CoefficientBudget>& budgets, const Targets& limits,
                                     const std::vector<std::string>& scaled, const std::vector<std::string>& dropped) {
  const auto sum_sq = [](const CoefficientBudget& b, const std::vector<std::string>& sources) {
    double sum = 0.0;
    for (const std::string& s : sources)
      if (const auto x = b.contributions.find(s); x != b.contributions.end()) sum += x->second * x->second;
    return sum;
  };
  SourceRequirement r;
  for (const CoefficientBudget& b : budgets) {
    const auto limit = limits.find(b.group);
    const double scaled_sq = sum_sq(b, scaled);
    if (limit == limits.end() || !(scaled_sq > 0)) continue;
    const double rest_sq = std::max(0.0, b.combined * b.combined - scaled_sq - sum_sq(b, dropped));
    const double room_sq = limit->second * limit->second - rest_sq;
    const double factor = room_sq > 0 ? std::sqrt(room_sq / scaled_sq) : 0.0;
    if (factor < r.max_factor) {
      r.max_factor = factor;
      r.limiting = b.key;
    }
  }
  return r;
}

}  // namespace imucal::plan
