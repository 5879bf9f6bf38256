#include "plan/schema.hpp"

#include "core/coefficients.hpp"
#include "plan/optimize.hpp"
#include "plan/plan.hpp"

namespace imucal::plan {

nlohmann::json schema_json() {
  nlohmann::json out = coefficient_schema();
  const nlohmann::json states = stage3_states_json();
  for (nlohmann::json& c : out.at("coefficients")) {
    const std::string key = c.at("key").get<std::string>();
    if (states.contains(key)) c["stage3_state"] = states.at(key);
  }
  // In the groups' order, as the builder lists them (a JSON object would be alphabetical).
  Targets seed = seed_targets();
  nlohmann::json targets = nlohmann::json::array();
  for (const CoefficientQuantity& q : coefficient_quantities()) {
    const auto it = seed.find(q.key);
    if (it == seed.end()) continue;
    targets.push_back({{"group", it->first}, {"sigma", it->second}});
    seed.erase(it);
  }
  for (const auto& [group, sigma] : seed) targets.push_back({{"group", group}, {"sigma", sigma}});
  out["seed_targets"] = targets;
  return out;
}

}  // namespace imucal::plan
