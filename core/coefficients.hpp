// Every coefficient of an IMU model by its one name ("gyro.bias_dph.x", "accel.k2_ug_per_g2.y",
// "gyro.scale_nonlinear_ppm.z.c3"), in its JSON unit, with its 1-sigma: the one list every table
// of coefficients is made from (a run's estimates, `imucal compare`), so that a key the model gains
// shows everywhere at once.
#pragma once

#include <string>
#include <vector>

#include "core/imu_model.hpp"

namespace imucal {

struct Coefficient {
  std::string key;     // "gyro.misalignment_arcsec.xy"
  double value = 0.0;  // in the unit the key names
  double sigma = 0.0;  // the same unit; 0 when the model carries no sigma for it
  // A term not every estimate has: the nonlinear terms, delays and proof-mass offsets (the
  // biases, scale factors and misalignments of both triads are always there).
  bool optional = false;
  // What is estimated together: a triad's vector (its three axes) or, for the matrices (the gyro
  // scale nonlinearity's terms, the g-sensitivity), the one coefficient itself.
  std::string group;
};

// All coefficients of `model` in one fixed order (the linear ones first), the same keys for every
// model, whatever it holds.
std::vector<Coefficient> model_coefficients(const ImuModel& model);

}  // namespace imucal
