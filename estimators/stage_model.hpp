// The model a calibration stage writes its estimates into, decided once for every stage that
// refines a prior (tumble, rate steps).
#pragma once

#include "core/imu_model.hpp"

namespace imucal {

// The prior's coefficients carried over, in the instrument frame.
inline ImuModel stage_model_from(const ImuModel& prior) {
  ImuModel model = prior;
  model.frame = "instrument";
  return model;
}

// The sigma a stage fills in: the prior's, or a new one when it had none.
inline ImuErrorSet& sigma_to_fill(ImuModel& model) {
  if (!model.sigma) model.sigma = ImuErrorSet{};
  return *model.sigma;
}

}  // namespace imucal
