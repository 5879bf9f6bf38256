// Stage 1's uncertainty budget as `imucal plan` and the builder read it (issue 34): each
// coefficient's contributions by source and the one that dominates (so a lab sees when its table,
// not its program, limits a coefficient), and the bench's requirements: the largest 1-sigma of
// each of the bench's type B sources (the table's error classes, the site's g) at which every
// coefficient's combined standard uncertainty still meets its limit. Pure arithmetic on a model's
// `budget` section: the budget itself is direct::uncertainty_budget's, computed once.
#pragma once

#include <limits>
#include <map>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/nav_filter.hpp"

namespace imucal::plan {

// Limits (or targets) by coefficient group, the model's key without the axis ("gyro.bias_dph").
using Targets = std::map<std::string, double>;

// Stage 1's accuracy limits (direct::Limits) by group.
Targets stage1_limits(const direct::Limits& limits = {});
// Stage 3's (navfilter::Limits), delays included.
Targets stage3_limits(const navfilter::Limits& limits = {});

struct CoefficientBudget {
  std::string key;    // "gyro.bias_dph.x"
  std::string group;  // "gyro.bias_dph"
  double combined = 0.0;  // the model's sigma: the combined standard uncertainty, in the key's unit
  std::map<std::string, double> contributions;  // source -> its standard uncertainty, the key's unit
  std::string dominant;                         // the source with the largest contribution
};
// Every coefficient the model's budget states (a contribution above zero), in model_coefficients'
// order; none for a model without a budget.
std::vector<CoefficientBudget> coefficient_budgets(const ImuModel& model);

// How far bench sources may grow. A source's contributions scale linearly with its 1-sigma (the
// budget's sensitivities times the sigma), so with the sources in `scaled` multiplied by a common
// factor f, those in `dropped` taken out and the rest as they are, coefficient c meets its limit L
// while f^2 S_c + (u_c^2 - S_c - D_c) <= L^2: S_c and D_c the sums of the scaled and the dropped
// sources' squared contributions, u_c the combined uncertainty.
struct SourceRequirement {
  // The largest f at which every limited coefficient meets its limit: infinity when none depends
  // on the scaled sources; 0 when a coefficient exceeds its limit whatever they are (the program
  // or a source not scaled limits it).
  double max_factor = std::numeric_limits<double>::infinity();
  std::string limiting;  // the coefficient that sets max_factor ("" when infinite)
};
SourceRequirement source_requirement(const std::vector<CoefficientBudget>& budgets, const Targets& limits,
                                     const std::vector<std::string>& scaled, const std::vector<std::string>& dropped = {});

}  // namespace imucal::plan
