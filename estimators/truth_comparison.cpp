#include "estimators/truth_comparison.hpp"

#include <stdexcept>

#include "core/coefficients.hpp"
#include "estimators/direct_calibration.hpp"

namespace imucal {

bool zero_by_frame_definition(const std::string& frame, const std::string& key) {
  return frame == "body" && (key == "accel.misalignment_arcsec.xy" || key == "accel.misalignment_arcsec.xz" ||
                             key == "accel.misalignment_arcsec.yx");
}

TruthComparison compare_with_truth(const ImuModel& estimate, const ImuModel& truth) {
  TruthComparison out;
  out.frame = estimate.frame;
  out.truth_frame = truth.frame;
  if (estimate.frame == truth.frame) {
    out.truth = truth;
  } else if (estimate.frame == "body") {
    out.truth = direct::to_body_frame(truth);
    out.converted = true;
  } else {
    throw std::invalid_argument("the truth is in the " + truth.frame + " frame and the estimate in the " +
                                estimate.frame + " frame: no conversion from the " + truth.frame + " frame");
  }
  const std::vector<Coefficient> estimated = model_coefficients(estimate);
  const std::vector<Coefficient> true_values = model_coefficients(out.truth);
  out.rows.reserve(estimated.size());
  for (std::size_t i = 0; i < estimated.size() && i < true_values.size(); ++i) {
    const Coefficient& e = estimated[i];
    TruthComparisonRow row;
    row.key = e.key;
    row.estimate = e.value;
    row.sigma = e.sigma;
    row.truth = true_values[i].value;
    row.error = e.value - row.truth;
    row.optional = e.optional;
    row.by_definition = zero_by_frame_definition(out.frame, e.key);
    if (!row.by_definition && e.sigma > 0.0) row.error_over_sigma = row.error / e.sigma;
    out.rows.push_back(std::move(row));
  }
  return out;
}

}  // namespace imucal
