// Every coefficient of an IMU model by its one name ("gyro.bias_dph.x", "accel.k2_ug_per_g2.y",
// "gyro.scale_nonlinear_ppm.z.c3"), in its JSON unit, with its 1-sigma: the one list every table
// of coefficients is made from (a run's estimates, `imucal compare`), so that a key the model gains
// shows everywhere at once.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

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

// How the part of a key after its quantity reads: what a coefficient's title is made of.
enum class KeyShape {
  axis,         // ".x": one per sensor axis
  angle,        // ".xy": sensor x about y
  proof_mass,   // ".y.x": the proof mass of accelerometer y, its x component
  coupling,     // ".x.y": gyro x to specific force along y
  terms,        // ".x.c2": a polynomial's term on axis x
};

// A quantity of the model as people read it, the heading its coefficients are listed under (one
// per name without its axis, and one for both proof-mass offsets), in the order the tables show
// them (gyro first). Not Coefficient::group, which is what is estimated together.
struct CoefficientQuantity {
  const char* key;    // "gyro.bias_dph": every coefficient whose key starts "gyro.bias_dph."
  const char* title;  // "Gyro bias"
  const char* unit;   // "°/h": the unit the key names, as printed
  KeyShape shape;
};
const std::vector<CoefficientQuantity>& coefficient_quantities();

// The quantity a coefficient's key belongs to; throws std::logic_error for a key none covers (a
// quantity model_coefficients gained without its row in the table).
const CoefficientQuantity& quantity_of(const std::string& key);

// A coefficient's name for people, without its unit: "Gyro bias, x axis".
std::string coefficient_title(const std::string& key);

// What a browser needs to name and group the coefficients without a copy of these tables
// (GET /api/schema, docs/api.md): {"groups": [{key, title, unit}], "coefficients": [{key, group,
// title, unit, optional}]}, both in order.
nlohmann::json coefficient_schema();

}  // namespace imucal
