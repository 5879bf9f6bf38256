// The one document a browser names, groups and judges coefficients by (GET /api/schema,
// docs/api.md), made at run time from the tables that own each part, so that the web holds no
// copy of them (issue 37).
#pragma once

#include <nlohmann/json.hpp>

namespace imucal::plan {

// core's coefficient_schema() (every coefficient key in order with its group, title, unit and
// whether it is optional; the groups with titles), each coefficient that is a state of stage 3
// with "stage3_state": [block, index], and "seed_targets": the seed's 1-sigma targets
// (seed_targets()) as [{group, sigma}] in the groups' order.
nlohmann::json schema_json();

}  // namespace imucal::plan
