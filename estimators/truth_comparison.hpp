// A calibrated model against the truth of a simulated run, coefficient by coefficient, in ONE
// frame: the truth (written in the instrument frame) is turned into the estimate's frame first
// (direct::to_body_frame for a body-frame estimate, e.g. stage 3's), so that a body-frame
// estimate is never read against instrument-frame angles. The one comparison `imucal compare`
// and imucald's GET /api/campaigns/{id}/truth (the results page) both make.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"

namespace imucal {

struct TruthComparisonRow {
  std::string key;        // core/coefficients.hpp's name, "gyro.misalignment_arcsec.xy"
  double estimate = 0.0;  // in the unit the key names
  double sigma = 0.0;     // the estimate's 1-sigma; 0 when it carries none
  double truth = 0.0;     // the truth in the estimate's frame
  double error = 0.0;     // estimate - truth
  std::optional<double> error_over_sigma;  // when sigma > 0 and the row is not zero by definition
  bool optional = false;  // a term not every estimate has (core/coefficients.hpp)
  // Zero by the frame's definition, not by measurement (body frame: accelerometer xy, xz, yx):
  // no sigma to compare against, nothing to judge.
  bool by_definition = false;
};

struct TruthComparison {
  std::string frame;        // the estimate's frame, which every row is in
  std::string truth_frame;  // the truth's frame as written
  bool converted = false;   // the truth was turned into `frame`
  ImuModel truth;           // the truth in `frame`
  std::vector<TruthComparisonRow> rows;  // every coefficient of core/coefficients.hpp, in its order
};

// Whether a coefficient is zero by the definition of the frame: the body frame is built on the
// accelerometers (x along accelerometer x, y in the plane of accelerometers x and y), so the
// accelerometer misalignments xy, xz and yx are 0 there by construction.
bool zero_by_frame_definition(const std::string& frame, const std::string& key);

// `estimate` against `truth`, the truth in the estimate's frame. Throws std::invalid_argument for
// an instrument-frame estimate against a body-frame truth (no conversion back is defined).
TruthComparison compare_with_truth(const ImuModel& estimate, const ImuModel& truth);

}  // namespace imucal
