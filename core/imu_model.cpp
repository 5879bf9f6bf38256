#include "core/imu_model.hpp"

#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <nlohmann/json.hpp>

#include "core/model_json.hpp"
#include "core/turn_on.hpp"
#include "core/units.hpp"

namespace imucal {

using nlohmann::json;
using namespace units;

Eigen::Matrix3d misalignment_matrix(const Misalignment& m) {
  Eigen::Matrix3d D;
  D << 1.0, m.xz, -m.xy,
      -m.yz, 1.0, m.yx,
       m.zy, -m.zx, 1.0;
  return D;
}

bool has_nonlinear_terms(const AccelErrors& a) { return !a.k2_per_g.isZero(0.0) || !a.k3_per_g2.isZero(0.0); }

// Horner form: with the terms zero each adds exactly 0 to the constant scale error, so a model
// without them gives the same numbers, bit for bit, as before they existed.
Eigen::Vector3d gyro_scale_errors(const GyroErrors& g, const Eigen::Vector3d& w) {
  Eigen::Vector3d s;
  if (g.scale_nonlinear.isZero(0.0)) {
    // The polynomial adds exactly 0 then: skipped, for the simulator, which asks at every
    // quadrature node (its divisions were a tenth of the simulation's time).
    for (int j = 0; j < 3; ++j) s[j] = w[j] >= 0 ? g.scale_pos[j] : g.scale_neg[j];
    return s;
  }
  for (int j = 0; j < 3; ++j) {
    const double q = std::abs(w[j]) / kGyroNonlinearityRate_radps;
    const Eigen::RowVector3d c = g.scale_nonlinear.row(j);
    s[j] = (w[j] >= 0 ? g.scale_pos[j] : g.scale_neg[j]) + q * (c[0] + q * (c[1] + q * c[2]));
  }
  return s;
}

Eigen::Vector3d accel_scale_errors(const AccelErrors& a, const Eigen::Vector3d& f_own) {
  Eigen::Vector3d s;
  for (int j = 0; j < 3; ++j) {
    const double a_g = f_own[j] / kStandardGravity_mps2;
    s[j] = a.scale[j] + a_g * (a.k2_per_g[j] + a_g * a.k3_per_g2[j]);
  }
  return s;
}

Eigen::Vector3d gyro_g_sensitivity_radps(const GyroErrors& g, const Eigen::Vector3d& f_origin_o) {
  return g.g_sensitivity_radps_per_g * (f_origin_o / kStandardGravity_mps2);
}

Eigen::Vector3d apply_gyro_scale_misalignment(const GyroErrors& g, const Eigen::Vector3d& w) {
  const Eigen::Vector3d s = gyro_scale_errors(g, w);
  Eigen::Vector3d sw;
  for (int j = 0; j < 3; ++j) sw[j] = (1.0 + s[j]) * w[j];
  return misalignment_matrix(g.misalignment_rad) * sw;
}

Eigen::Vector3d apply_accel_scale_misalignment(const AccelErrors& a, const Eigen::Vector3d& f) {
  return misalignment_matrix(a.misalignment_rad) * (Eigen::Vector3d::Ones() + accel_scale_errors(a, f)).cwiseProduct(f);
}

Eigen::Matrix3d C_b_o_of(const Eigen::Vector3d& r) {
  const double angle = r.norm();
  if (angle == 0.0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
}

Eigen::Matrix3d proof_mass_offsets_m(const ImuModel& model) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Zero();
  r.col(1) = model.accel.lever_arm_y_m;
  r.col(2) = model.accel.lever_arm_z_m;
  if (model.frame == "body" && model.body_to_instrument_rad) {
    // 80" of body-to-instrument rotation moves a 40 mm offset by 16 um: 2e-5 m/s^2 of size
    // effect at 1 rad/s.
    r = C_b_o_of(*model.body_to_instrument_rad).transpose() * r;
  }
  return r;
}

Eigen::Matrix3d size_effect_mps2(const Eigen::Matrix3d& offsets_m, const Eigen::Vector3d& w,
                                 const Eigen::Vector3d& dw) {
  Eigen::Matrix3d e;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d r = offsets_m.col(j);
    e.row(j) = (w.cross(w.cross(r)) + dw.cross(r)).transpose();
  }
  return e;
}

// The inverse of a nonlinear S is the fixed point x = S(x)^-1 y. An error e in x moves S(x) x by
// about x ds/dx e, so each step shrinks the error by the factor |x ds/dx|, small for a sensor's
// ppm-level nonlinearity: 6e-5 for 20 ppm of cubic gyro nonlinearity at 300 deg/s (3 x 20e-6),
// 6e-5 for K2 = 50 ug/g^2 and K3 = 5 ug/g^3 at 1 g (50e-6 + 2 x 5e-6). The first pass, with S at its
// constant part, is off by the nonlinear scale error itself (up to ~2e-5 relative); three steps
// take that to 2e-5 x (6e-5)^3 ~ 4e-18, below double precision, with margin for terms ten times
// larger. Terms with |x ds/dx| near 1 are not a ppm nonlinearity; the model is not meant for them.
// The nonlinear part is taken at the interval's mean input (increment / dt): the mean of s(x) x
// differs by s'' times the input's variance over one sample, ~1e-11 of g at 1 rad/s and 100 Hz.
constexpr int kFixedPointSteps = 3;

Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta, double dt_s,
                                          const Eigen::Vector3d& f_origin_o) {
  // The g-sensitivity is a bias (CONVENTIONS.md); left out when zero so that a model without it
  // gives the same numbers as before, bit for bit.
  const Eigen::Vector3d bias = g.g_sensitivity_radps_per_g.isZero(0.0)
                                   ? g.bias_radps
                                   : Eigen::Vector3d(g.bias_radps + gyro_g_sensitivity_radps(g, f_origin_o));
  const Eigen::Vector3d y = misalignment_matrix(g.misalignment_rad).inverse() * (dtheta - bias * dt_s);
  Eigen::Vector3d out;
  for (int j = 0; j < 3; ++j) out[j] = y[j] / (1.0 + (y[j] >= 0 ? g.scale_pos[j] : g.scale_neg[j]));
  if (g.scale_nonlinear.isZero(0.0)) return out;
  // S at the current estimate of the mean rate (the increment over dt_s); the sign of out is that
  // of y, so the +/- choice never changes.
  for (int step = 0; step < kFixedPointSteps; ++step)
    out = y.cwiseQuotient(Eigen::Vector3d::Ones() + gyro_scale_errors(g, out / dt_s));
  return out;
}

Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta, double dt_s) {
  return compensate_gyro_increment(g, dtheta, dt_s, Eigen::Vector3d::Zero());
}

Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv, double dt_s,
                                           const Eigen::Matrix3d& size_effect) {
  const Eigen::Matrix3d D = misalignment_matrix(a.misalignment_rad);
  const Eigen::Matrix3d D_inv = D.inverse();
  const bool with_size_effect = !size_effect.isZero(0.0);
  // One pass of the inverse for given scale errors s: remove each channel's own size effect
  // through its row of D S, then S^-1 D^-1.
  const auto pass = [&](const Eigen::Vector3d& s) {
    Eigen::Vector3d u = dv;
    if (with_size_effect) {
      const Eigen::Matrix3d DS = D * (Eigen::Vector3d::Ones() + s).asDiagonal();
      u -= DS.cwiseProduct(size_effect).rowwise().sum() * dt_s;
    }
    const Eigen::Vector3d y = D_inv * (u - a.bias_mps2 * dt_s);
    return Eigen::Vector3d(y.cwiseQuotient(Eigen::Vector3d::Ones() + s));
  };
  Eigen::Vector3d out = pass(a.scale);
  if (!has_nonlinear_terms(a)) return out;
  // Channel j's nonlinearity acts at its own proof mass: f_origin[j] + its size effect along j.
  for (int step = 0; step < kFixedPointSteps; ++step)
    out = pass(accel_scale_errors(a, out / dt_s + size_effect.diagonal()));
  return out;
}

Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv, double dt_s) {
  return compensate_accel_increment(a, dv, dt_s, Eigen::Matrix3d::Zero());
}

CompensatedIncrements compensate_imu_increments(const GyroErrors& g, const AccelErrors& a,
                                                const Eigen::Vector3d& dtheta, const Eigen::Vector3d& dv,
                                                double dt_s, const Eigen::Matrix3d& size_effect) {
  CompensatedIncrements c;
  c.dv_mps = compensate_accel_increment(a, dv, dt_s, size_effect);
  c.dtheta_rad = compensate_gyro_increment(g, dtheta, dt_s, c.dv_mps / dt_s);
  return c;
}

namespace model_json {

ObjectReader section(const json& j, const std::string& where) {
  return ObjectReader(j, where, ObjectReader::ThrowAtFirst{});
}

double num(const ObjectReader& r, const json& v, const std::string& path) {
  if (!v.is_number()) r.fail(path, "expected a number");
  const double x = v.get<double>();
  if (!std::isfinite(x)) r.fail(path, "not a finite number");
  return x;
}

Eigen::Vector3d vec3(ObjectReader& r, const char* key, double scale, bool required) {
  const json* a = r.get(key, required);
  if (a == nullptr) return Eigen::Vector3d::Zero();
  const std::string w = r.at(key);
  if (!a->is_array() || a->size() != 3) r.fail(w, "expected an array of 3 numbers");
  return Eigen::Vector3d(num(r, (*a)[0], w + "[0]"), num(r, (*a)[1], w + "[1]"), num(r, (*a)[2], w + "[2]")) * scale;
}

double scalar(ObjectReader& r, const char* key, double scale) {
  const json* v = r.get(key);
  return v == nullptr ? 0.0 : num(r, *v, r.at(key)) * scale;
}

json arr(const Eigen::Vector3d& v, double scale) { return {v[0] * scale, v[1] * scale, v[2] * scale}; }

}  // namespace model_json

namespace {

using namespace model_json;

Misalignment misalignment_from(ObjectReader& parent) {
  Misalignment m;
  const json* a = parent.get("misalignment_arcsec");
  if (a == nullptr) return m;
  ObjectReader r = section(*a, parent.at("misalignment_arcsec"));
  for (const MisalignmentKey& k : kMisalignmentKeys) m.*k.member = scalar(r, k.name, kArcsecToRad);
  r.finish();
  return m;
}

json misalignment_to(const Misalignment& m) {
  json j = json::object();
  for (const MisalignmentKey& k : kMisalignmentKeys) j[k.name] = m.*k.member * kRadToArcsec;
  return j;
}


// 3x3 as three rows of three numbers (g_sensitivity_dph_per_g).
Eigen::Matrix3d mat3(ObjectReader& parent, const char* key, double scale) {
  const json* m = parent.get(key);
  if (m == nullptr) return Eigen::Matrix3d::Zero();
  const std::string w = parent.at(key);
  if (!m->is_array() || m->size() != 3) parent.fail(w, "expected 3 rows of 3 numbers");
  Eigen::Matrix3d out;
  for (std::size_t r = 0; r < 3; ++r) {
    const json& row = (*m)[r];
    const std::string wr = w + "[" + std::to_string(r) + "]";
    if (!row.is_array() || row.size() != 3) parent.fail(wr, "expected a row of 3 numbers");
    for (std::size_t c = 0; c < 3; ++c)
      out(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
          num(parent, row[c], wr + "[" + std::to_string(c) + "]") * scale;
  }
  return out;
}

json mat3_to(const Eigen::Matrix3d& m, double scale) {
  json rows = json::array();
  for (int r = 0; r < 3; ++r) rows.push_back(arr(m.row(r).transpose(), scale));
  return rows;
}

// scale_nonlinear_ppm: {"x": [c1, c2, c3], ...}, one to three terms per axis, missing axes and
// terms zero; rows of the matrix are the axes.
constexpr std::array<const char*, 3> kAxisKeys = {"x", "y", "z"};

Eigen::Matrix3d scale_nonlinear_from(ObjectReader& parent) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  const json* o = parent.get("scale_nonlinear_ppm");
  if (o == nullptr) return c;
  ObjectReader r = section(*o, parent.at("scale_nonlinear_ppm"));
  for (int axis = 0; axis < 3; ++axis) {
    const char* key = kAxisKeys[static_cast<std::size_t>(axis)];
    const json* terms = r.get(key);
    if (terms == nullptr) continue;
    const std::string wa = r.at(key);
    if (!terms->is_array() || terms->empty() || terms->size() > 3)
      r.fail(wa, "expected an array of 1 to 3 numbers (c1, c2, c3 in ppm)");
    for (std::size_t k = 0; k < terms->size(); ++k)
      c(axis, static_cast<Eigen::Index>(k)) = num(r, (*terms)[k], wa + "[" + std::to_string(k) + "]") * kPpm;
  }
  r.finish();
  return c;
}

// As many terms as the highest nonzero one, the same for every axis (a one-term model stays one
// term in the file).
json scale_nonlinear_to(const Eigen::Matrix3d& c) {
  int terms = 1;
  for (int k = 0; k < 3; ++k)
    if (!c.col(k).isZero(0.0)) terms = k + 1;
  json o = json::object();
  for (int axis = 0; axis < 3; ++axis) {
    json row = json::array();
    for (int k = 0; k < terms; ++k) row.push_back(c(axis, k) * (1.0 / kPpm));
    o[kAxisKeys[static_cast<std::size_t>(axis)]] = row;
  }
  return o;
}

// deg/h/sqrt(h) -> rad/s/sqrt(s)
constexpr double kDphRthToRadpsRts = kDphToRadps / 60.0;
constexpr double kMps2RthToMps2Rts = 1.0 / 60.0;

GyroErrors gyro_from(const json& j, const std::string& w) {
  ObjectReader r = section(j, w);
  GyroErrors g;
  g.bias_radps = vec3(r, "bias_dph", kDphToRadps);
  g.scale_pos = vec3(r, "scale_pos_ppm", kPpm);
  g.scale_neg = vec3(r, "scale_neg_ppm", kPpm);
  g.misalignment_rad = misalignment_from(r);
  g.delay_s = vec3(r, "delay_us", kUsToS);
  g.scale_nonlinear = scale_nonlinear_from(r);
  g.g_sensitivity_radps_per_g = mat3(r, "g_sensitivity_dph_per_g", kDphToRadps);
  if (const json* nj = r.get("noise")) {
    ObjectReader n = section(*nj, r.at("noise"));
    g.noise.arw_rad_rts = scalar(n, "arw_deg_rth", kDegRthToRadRts);
    g.noise.bias_instability_radps = scalar(n, "bias_instability_dph", kDphToRadps);
    g.noise.bias_corr_time_s = scalar(n, "bias_corr_time_s", 1.0);
    g.noise.rate_random_walk_radps_rts = scalar(n, "bias_rw_dph_rth", kDphRthToRadpsRts);
    n.finish();
  }
  r.finish();
  return g;
}

AccelErrors accel_from(const json& j, const std::string& w) {
  ObjectReader r = section(j, w);
  AccelErrors a;
  a.bias_mps2 = vec3(r, "bias_mps2", 1.0);
  a.scale = vec3(r, "scale_ppm", kPpm);
  a.misalignment_rad = misalignment_from(r);
  a.delay_s = vec3(r, "delay_us", kUsToS);
  // ug per g^2 (g^3) is 1e-6 of scale error per g (g^2): see AccelErrors.
  a.k2_per_g = vec3(r, "k2_ug_per_g2", kPpm);
  a.k3_per_g2 = vec3(r, "k3_ug_per_g3", kPpm);
  if (const json* lj = r.get("lever_arm_mm")) {
    ObjectReader l = section(*lj, r.at("lever_arm_mm"));
    a.lever_arm_y_m = vec3(l, "y", kMmToM);
    a.lever_arm_z_m = vec3(l, "z", kMmToM);
    l.finish();
  }
  if (const json* nj = r.get("noise")) {
    ObjectReader n = section(*nj, r.at("noise"));
    a.noise.vrw_mps_rts = scalar(n, "vrw_mps_rth", kMpsRthToMpsRts);
    a.noise.bias_instability_mps2 = scalar(n, "bias_instability_mps2", 1.0);
    a.noise.bias_corr_time_s = scalar(n, "bias_corr_time_s", 1.0);
    a.noise.accel_random_walk_mps2_rts = scalar(n, "bias_rw_mps2_rth", kMps2RthToMps2Rts);
    n.finish();
  }
  r.finish();
  return a;
}

json gyro_to(const GyroErrors& g, bool with_noise) {
  json j = {{"bias_dph", arr(g.bias_radps, kRadpsToDph)},
            {"scale_pos_ppm", arr(g.scale_pos, 1.0 / kPpm)},
            {"scale_neg_ppm", arr(g.scale_neg, 1.0 / kPpm)},
            {"misalignment_arcsec", misalignment_to(g.misalignment_rad)},
            {"delay_us", arr(g.delay_s, 1.0 / kUsToS)}};
  // The optional terms only when present, so that a model without them reads and writes as before.
  if (!g.scale_nonlinear.isZero(0.0)) j["scale_nonlinear_ppm"] = scale_nonlinear_to(g.scale_nonlinear);
  if (!g.g_sensitivity_radps_per_g.isZero(0.0))
    j["g_sensitivity_dph_per_g"] = mat3_to(g.g_sensitivity_radps_per_g, kRadpsToDph);
  if (with_noise) {
    json n = {{"arw_deg_rth", g.noise.arw_rad_rts / kDegRthToRadRts},
              {"bias_instability_dph", g.noise.bias_instability_radps * kRadpsToDph}};
    if (g.noise.bias_corr_time_s > 0) n["bias_corr_time_s"] = g.noise.bias_corr_time_s;
    if (g.noise.rate_random_walk_radps_rts > 0)
      n["bias_rw_dph_rth"] = g.noise.rate_random_walk_radps_rts / kDphRthToRadpsRts;
    j["noise"] = n;
  }
  return j;
}

json accel_to(const AccelErrors& a, bool with_noise) {
  json j = {{"bias_mps2", arr(a.bias_mps2, 1.0)},
            {"scale_ppm", arr(a.scale, 1.0 / kPpm)},
            {"misalignment_arcsec", misalignment_to(a.misalignment_rad)},
            {"lever_arm_mm", {{"y", arr(a.lever_arm_y_m, 1.0 / kMmToM)}, {"z", arr(a.lever_arm_z_m, 1.0 / kMmToM)}}},
            {"delay_us", arr(a.delay_s, 1.0 / kUsToS)}};
  if (!a.k2_per_g.isZero(0.0)) j["k2_ug_per_g2"] = arr(a.k2_per_g, 1.0 / kPpm);
  if (!a.k3_per_g2.isZero(0.0)) j["k3_ug_per_g3"] = arr(a.k3_per_g2, 1.0 / kPpm);
  if (with_noise) {
    json n = {{"vrw_mps_rth", a.noise.vrw_mps_rts / kMpsRthToMpsRts},
              {"bias_instability_mps2", a.noise.bias_instability_mps2}};
    if (a.noise.bias_corr_time_s > 0) n["bias_corr_time_s"] = a.noise.bias_corr_time_s;
    if (a.noise.accel_random_walk_mps2_rts > 0)
      n["bias_rw_mps2_rth"] = a.noise.accel_random_walk_mps2_rts / kMps2RthToMps2Rts;
    j["noise"] = n;
  }
  return j;
}

// `sigma` and each source of `budget`: {"gyro": {...}, "accel": {...}}, the coefficients' keys.
ImuErrorSet error_set_from(const json& j, const std::string& w) {
  ObjectReader s = section(j, w);
  ImuErrorSet set;
  if (const json* g = s.get("gyro")) set.gyro = gyro_from(*g, s.at("gyro"));
  if (const json* a = s.get("accel")) set.accel = accel_from(*a, s.at("accel"));
  s.finish();
  return set;
}

json error_set_to(const ImuErrorSet& set) {
  return {{"gyro", gyro_to(set.gyro, false)}, {"accel", accel_to(set.accel, false)}};
}

}  // namespace

namespace {

ImuModel model_from(const json& j, const std::string& source) {
  ObjectReader r = section(j, source);
  if (r.string("format") != std::string("imucal-imu-model/1"))
    r.fail(source, "\"format\" must be \"imucal-imu-model/1\"");
  ImuModel m;
  if (const auto frame = r.string("frame")) {
    m.frame = *frame;
    if (m.frame != "instrument" && m.frame != "body")
      r.fail(r.at("frame"), "must be \"instrument\" or \"body\", not \"" + m.frame + "\"");
  }
  if (const json* g = r.get("gyro")) m.gyro = gyro_from(*g, r.at("gyro"));
  if (const json* a = r.get("accel")) m.accel = accel_from(*a, r.at("accel"));
  if (const json* sj = r.get("sigma")) m.sigma = error_set_from(*sj, r.at("sigma"));
  // An older model has no budget: it reads as none stated.
  if (const json* bj = r.get("budget")) {
    ObjectReader b = section(*bj, r.at("budget"));
    for (const auto& [name, entry] : bj->items()) {
      if (name.empty()) b.fail(r.at("budget"), "a source's name cannot be empty");
      (void)b.get(name.c_str());  // marks it known: every source name is allowed
      m.budget[name] = error_set_from(entry, b.at(name.c_str()));
    }
    b.finish();
  }
  if (r.has("body_to_instrument_arcsec")) m.body_to_instrument_rad = vec3(r, "body_to_instrument_arcsec", kArcsecToRad);
  if (const json* mj = r.get("mount")) {
    ObjectReader mount = section(*mj, r.at("mount"));
    m.mount_r0_p_m = vec3(mount, "r0_p_mm", kMmToM);
    mount.finish();
  }
  if (const json* t = r.get("thermal")) m.thermal_json = t->dump();
  json extra = json::object();
  for (const char* k : {"serial", "status", "stages", "comment", "turn_on"})
    if (const json* v = r.get(k)) extra[k] = *v;
  // Checked here, kept as written: the turn-on terms are read where they are used (turn_on.hpp).
  if (const json* t = r.get("turn_on")) turn_on_from_json(*t, r.at("turn_on"));
  r.finish();
  if (!extra.empty()) m.extra_json = extra.dump();
  return m;
}

}  // namespace

ImuModel imu_model_from_json_text(const std::string& text, const std::string& source) {
  return read_model_text(text, source, [&](const json& j) { return model_from(j, source); });
}

ImuModel read_imu_model_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open IMU model file");
  std::stringstream ss;
  ss << in.rdbuf();
  return imu_model_from_json_text(ss.str(), path);
}

std::string imu_model_to_json_text(const ImuModel& m) {
  json j;
  j["format"] = "imucal-imu-model/1";
  j["frame"] = m.frame;
  j["gyro"] = gyro_to(m.gyro, true);
  j["accel"] = accel_to(m.accel, true);
  if (m.sigma) j["sigma"] = error_set_to(*m.sigma);
  if (!m.budget.empty()) {
    json b = json::object();
    for (const auto& [source, set] : m.budget) b[source] = error_set_to(set);
    j["budget"] = b;
  }
  if (m.body_to_instrument_rad) j["body_to_instrument_arcsec"] = arr(*m.body_to_instrument_rad, kRadToArcsec);
  if (m.mount_r0_p_m) j["mount"] = {{"r0_p_mm", arr(*m.mount_r0_p_m, 1.0 / kMmToM)}};
  if (!m.thermal_json.empty()) j["thermal"] = json::parse(m.thermal_json);
  if (!m.extra_json.empty()) {
    // Keep the parsed object alive: items() of a temporary would dangle in the range-for.
    const json extra = json::parse(m.extra_json);
    for (const auto& [k, v] : extra.items()) j[k] = v;
  }
  return j.dump(1) + "\n";
}

void write_imu_model_file(const ImuModel& model, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write IMU model file");
  out << imu_model_to_json_text(model);
  if (!out) throw std::runtime_error(path + ": write failed");
}

}  // namespace imucal
