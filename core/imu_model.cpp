#include "core/imu_model.hpp"

#include <cmath>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <stdexcept>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <nlohmann/json.hpp>

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

Eigen::Vector3d apply_gyro_scale_misalignment(const GyroErrors& g, const Eigen::Vector3d& w) {
  Eigen::Vector3d sw;
  for (int j = 0; j < 3; ++j) sw[j] = (1.0 + (w[j] >= 0 ? g.scale_pos[j] : g.scale_neg[j])) * w[j];
  return misalignment_matrix(g.misalignment_rad) * sw;
}

Eigen::Vector3d apply_accel_scale_misalignment(const AccelErrors& a, const Eigen::Vector3d& f) {
  return misalignment_matrix(a.misalignment_rad) * (Eigen::Vector3d::Ones() + a.scale).cwiseProduct(f);
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

Eigen::Vector3d accel_size_effect_output(const AccelErrors& a, const Eigen::Matrix3d& e) {
  const Eigen::Matrix3d DS = misalignment_matrix(a.misalignment_rad) * (Eigen::Vector3d::Ones() + a.scale).asDiagonal();
  return DS.cwiseProduct(e).rowwise().sum();
}

Eigen::Vector3d compensate_gyro_increment(const GyroErrors& g, const Eigen::Vector3d& dtheta,
                                          double dt_s) {
  const Eigen::Vector3d y = misalignment_matrix(g.misalignment_rad).inverse() * (dtheta - g.bias_radps * dt_s);
  Eigen::Vector3d out;
  for (int j = 0; j < 3; ++j) out[j] = y[j] / (1.0 + (y[j] >= 0 ? g.scale_pos[j] : g.scale_neg[j]));
  return out;
}

Eigen::Vector3d compensate_accel_increment(const AccelErrors& a, const Eigen::Vector3d& dv,
                                           double dt_s) {
  const Eigen::Vector3d y = misalignment_matrix(a.misalignment_rad).inverse() * (dv - a.bias_mps2 * dt_s);
  return y.cwiseQuotient(Eigen::Vector3d::Ones() + a.scale);
}

namespace {

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

json arr(const Eigen::Vector3d& v, double scale) { return {v[0] * scale, v[1] * scale, v[2] * scale}; }

// deg/h/sqrt(h) -> rad/s/sqrt(s)
constexpr double kDphRthToRadpsRts = kDphToRadps / 60.0;
constexpr double kMps2RthToMps2Rts = 1.0 / 60.0;

GyroErrors gyro_from(const json& j, const std::string& w) {
  check_keys(j, w, {"bias_dph", "scale_pos_ppm", "scale_neg_ppm", "misalignment_arcsec", "delay_us", "noise"});
  GyroErrors g;
  g.bias_radps = vec3(j, "bias_dph", w, kDphToRadps);
  g.scale_pos = vec3(j, "scale_pos_ppm", w, kPpm);
  g.scale_neg = vec3(j, "scale_neg_ppm", w, kPpm);
  g.misalignment_rad = misalignment_from(j, w);
  g.delay_s = vec3(j, "delay_us", w, kUsToS);
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
  check_keys(j, w, {"bias_mps2", "scale_ppm", "misalignment_arcsec", "lever_arm_mm", "delay_us", "noise"});
  AccelErrors a;
  a.bias_mps2 = vec3(j, "bias_mps2", w, 1.0);
  a.scale = vec3(j, "scale_ppm", w, kPpm);
  a.misalignment_rad = misalignment_from(j, w);
  a.delay_s = vec3(j, "delay_us", w, kUsToS);
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
                         "mount", "serial", "status", "stages", "comment"});
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
  for (const char* k : {"serial", "status", "stages", "comment"})
    if (j.contains(k)) extra[k] = j.at(k);
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
