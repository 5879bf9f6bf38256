#include "core/imu_model.hpp"

#include <array>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <set>
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

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw std::runtime_error(where + ": " + what);
}

void check_keys(const json& j, const std::string& where, std::initializer_list<const char*> allowed) {
  if (!j.is_object()) fail(where, "expected an object");
  const std::set<std::string> ok(allowed.begin(), allowed.end());
  for (const auto& [key, value] : j.items())
    if (!ok.count(key)) fail(where, "unknown key '" + key + "' (a typo must not become a silent zero)");
}

double num(const json& j, const std::string& where) {
  if (!j.is_number()) fail(where, "expected a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail(where, "not a finite number");
  return v;
}

Eigen::Vector3d vec3(const json& j, const char* key, const std::string& where, double scale) {
  if (!j.contains(key)) return Eigen::Vector3d::Zero();
  const json& a = j.at(key);
  const std::string w = where + "." + key;
  if (!a.is_array() || a.size() != 3) fail(w, "expected an array of 3 numbers");
  return Eigen::Vector3d(num(a[0], w + "[0]"), num(a[1], w + "[1]"), num(a[2], w + "[2]")) * scale;
}

double scalar(const json& j, const char* key, const std::string& where, double scale) {
  if (!j.contains(key)) return 0.0;
  return num(j.at(key), where + "." + key) * scale;
}

json arr(const Eigen::Vector3d& v, double scale) { return {v[0] * scale, v[1] * scale, v[2] * scale}; }

}  // namespace model_json

namespace {

using namespace model_json;

Misalignment misalignment_from(const json& j, const std::string& where) {
  Misalignment m;
  if (!j.contains("misalignment_arcsec")) return m;
  const json& a = j.at("misalignment_arcsec");
  const std::string w = where + ".misalignment_arcsec";
  check_keys(a, w, {"xy", "xz", "yx", "yz", "zx", "zy"});
  for (const MisalignmentKey& k : kMisalignmentKeys) m.*k.member = scalar(a, k.name, w, kArcsecToRad);
  return m;
}

json misalignment_to(const Misalignment& m) {
  json j = json::object();
  for (const MisalignmentKey& k : kMisalignmentKeys) j[k.name] = m.*k.member * kRadToArcsec;
  return j;
}


// 3x3 as three rows of three numbers (g_sensitivity_dph_per_g).
Eigen::Matrix3d mat3(const json& j, const char* key, const std::string& where, double scale) {
  if (!j.contains(key)) return Eigen::Matrix3d::Zero();
  const json& m = j.at(key);
  const std::string w = where + "." + key;
  if (!m.is_array() || m.size() != 3) fail(w, "expected 3 rows of 3 numbers");
  Eigen::Matrix3d out;
  for (std::size_t r = 0; r < 3; ++r) {
    const std::string wr = w + "[" + std::to_string(r) + "]";
    if (!m[r].is_array() || m[r].size() != 3) fail(wr, "expected a row of 3 numbers");
    for (std::size_t c = 0; c < 3; ++c)
      out(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
          num(m[r][c], wr + "[" + std::to_string(c) + "]") * scale;
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

Eigen::Matrix3d scale_nonlinear_from(const json& j, const std::string& where) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  if (!j.contains("scale_nonlinear_ppm")) return c;
  const json& o = j.at("scale_nonlinear_ppm");
  const std::string w = where + ".scale_nonlinear_ppm";
  check_keys(o, w, {"x", "y", "z"});
  for (int axis = 0; axis < 3; ++axis) {
    const char* key = kAxisKeys[static_cast<std::size_t>(axis)];
    if (!o.contains(key)) continue;
    const json& terms = o.at(key);
    const std::string wa = w + "." + key;
    if (!terms.is_array() || terms.empty() || terms.size() > 3)
      fail(wa, "expected an array of 1 to 3 numbers (c1, c2, c3 in ppm)");
    for (std::size_t k = 0; k < terms.size(); ++k)
      c(axis, static_cast<Eigen::Index>(k)) = num(terms[k], wa + "[" + std::to_string(k) + "]") * kPpm;
  }
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
  check_keys(j, w, {"bias_dph", "scale_pos_ppm", "scale_neg_ppm", "misalignment_arcsec", "delay_us", "noise",
                    "scale_nonlinear_ppm", "g_sensitivity_dph_per_g"});
  GyroErrors g;
  g.bias_radps = vec3(j, "bias_dph", w, kDphToRadps);
  g.scale_pos = vec3(j, "scale_pos_ppm", w, kPpm);
  g.scale_neg = vec3(j, "scale_neg_ppm", w, kPpm);
  g.misalignment_rad = misalignment_from(j, w);
  g.delay_s = vec3(j, "delay_us", w, kUsToS);
  g.scale_nonlinear = scale_nonlinear_from(j, w);
  g.g_sensitivity_radps_per_g = mat3(j, "g_sensitivity_dph_per_g", w, kDphToRadps);
  if (j.contains("noise")) {
    const json& n = j.at("noise");
    const std::string wn = w + ".noise";
    check_keys(n, wn, {"arw_deg_rth", "bias_instability_dph", "bias_corr_time_s", "bias_rw_dph_rth"});
    g.noise.arw_rad_rts = scalar(n, "arw_deg_rth", wn, kDegRthToRadRts);
    g.noise.bias_instability_radps = scalar(n, "bias_instability_dph", wn, kDphToRadps);
    g.noise.bias_corr_time_s = scalar(n, "bias_corr_time_s", wn, 1.0);
    g.noise.rate_random_walk_radps_rts = scalar(n, "bias_rw_dph_rth", wn, kDphRthToRadpsRts);
  }
  return g;
}

AccelErrors accel_from(const json& j, const std::string& w) {
  check_keys(j, w, {"bias_mps2", "scale_ppm", "misalignment_arcsec", "lever_arm_mm", "delay_us", "noise",
                    "k2_ug_per_g2", "k3_ug_per_g3"});
  AccelErrors a;
  a.bias_mps2 = vec3(j, "bias_mps2", w, 1.0);
  a.scale = vec3(j, "scale_ppm", w, kPpm);
  a.misalignment_rad = misalignment_from(j, w);
  a.delay_s = vec3(j, "delay_us", w, kUsToS);
  // ug per g^2 (g^3) is 1e-6 of scale error per g (g^2): see AccelErrors.
  a.k2_per_g = vec3(j, "k2_ug_per_g2", w, kPpm);
  a.k3_per_g2 = vec3(j, "k3_ug_per_g3", w, kPpm);
  if (j.contains("lever_arm_mm")) {
    const json& l = j.at("lever_arm_mm");
    const std::string wl = w + ".lever_arm_mm";
    check_keys(l, wl, {"y", "z"});
    a.lever_arm_y_m = vec3(l, "y", wl, kMmToM);
    a.lever_arm_z_m = vec3(l, "z", wl, kMmToM);
  }
  if (j.contains("noise")) {
    const json& n = j.at("noise");
    const std::string wn = w + ".noise";
    check_keys(n, wn, {"vrw_mps_rth", "bias_instability_mps2", "bias_corr_time_s", "bias_rw_mps2_rth"});
    a.noise.vrw_mps_rts = scalar(n, "vrw_mps_rth", wn, kMpsRthToMpsRts);
    a.noise.bias_instability_mps2 = scalar(n, "bias_instability_mps2", wn, 1.0);
    a.noise.bias_corr_time_s = scalar(n, "bias_corr_time_s", wn, 1.0);
    a.noise.accel_random_walk_mps2_rts = scalar(n, "bias_rw_mps2_rth", wn, kMps2RthToMps2Rts);
  }
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

}  // namespace

ImuModel imu_model_from_json_text(const std::string& text, const std::string& source) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::parse_error& e) {
    fail(source, std::string("not valid JSON: ") + e.what());
  }
  check_keys(j, source, {"format", "frame", "gyro", "accel", "sigma", "thermal", "body_to_instrument_arcsec",
                         "mount", "serial", "status", "stages", "comment", "turn_on"});
  if (!j.contains("format") || j.at("format") != "imucal-imu-model/1")
    fail(source, "\"format\" must be \"imucal-imu-model/1\"");
  ImuModel m;
  if (j.contains("frame")) {
    m.frame = j.at("frame").get<std::string>();
    if (m.frame != "instrument" && m.frame != "body")
      fail(source + ".frame", "must be \"instrument\" or \"body\", not \"" + m.frame + "\"");
  }
  if (j.contains("gyro")) m.gyro = gyro_from(j.at("gyro"), source + ".gyro");
  if (j.contains("accel")) m.accel = accel_from(j.at("accel"), source + ".accel");
  if (j.contains("sigma")) {
    const json& s = j.at("sigma");
    check_keys(s, source + ".sigma", {"gyro", "accel"});
    ImuErrorSet set;
    if (s.contains("gyro")) set.gyro = gyro_from(s.at("gyro"), source + ".sigma.gyro");
    if (s.contains("accel")) set.accel = accel_from(s.at("accel"), source + ".sigma.accel");
    m.sigma = set;
  }
  if (j.contains("body_to_instrument_arcsec"))
    m.body_to_instrument_rad = vec3(j, "body_to_instrument_arcsec", source, kArcsecToRad);
  if (j.contains("mount")) {
    check_keys(j.at("mount"), source + ".mount", {"r0_p_mm"});
    m.mount_r0_p_m = vec3(j.at("mount"), "r0_p_mm", source + ".mount", kMmToM);
  }
  if (j.contains("thermal")) m.thermal_json = j.at("thermal").dump();
  json extra = json::object();
  for (const char* k : {"serial", "status", "stages", "comment", "turn_on"})
    if (j.contains(k)) extra[k] = j.at(k);
  // Checked here, kept as written: the turn-on terms are read where they are used (turn_on.hpp).
  if (j.contains("turn_on")) turn_on_from_json(j.at("turn_on"), source + ".turn_on");
  if (!extra.empty()) m.extra_json = extra.dump();
  return m;
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
  if (m.sigma) j["sigma"] = {{"gyro", gyro_to(m.sigma->gyro, false)}, {"accel", accel_to(m.sigma->accel, false)}};
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
