#include "independent_bundle.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace imucal_test::gen {

using Eigen::Matrix3d;
using Eigen::Vector3d;

namespace {
constexpr double kDeg = kPi / 180.0;
constexpr double kArcsec = kDeg / 3600.0;
constexpr double kDph = kDeg / 3600.0;  // deg/h in rad/s
}  // namespace

// ---------------------------------------------------------------------------------------------
// Quaternions
Quat operator*(const Quat& a, const Quat& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

Quat conjugate(const Quat& q) { return {q.w, -q.x, -q.y, -q.z}; }

Quat about_axis(const Vector3d& u, double angle_rad) {
  const double s = std::sin(0.5 * angle_rad);
  return {std::cos(0.5 * angle_rad), u.x() * s, u.y() * s, u.z() * s};
}

Vector3d rotate(const Quat& q, const Vector3d& v) {
  const Quat r = q * Quat{0, v.x(), v.y(), v.z()} * conjugate(q);
  return {r.x, r.y, r.z};
}

// ---------------------------------------------------------------------------------------------
// Earth
double normal_gravity_mps2(double latitude_deg, double height_m) {
  // WGS-84 constants: equatorial gravity, Somigliana's k, first eccentricity squared.
  const double ge = 9.7803253359, k = 0.00193185265241, e2 = 6.69437999013e-3;
  const double a = 6378137.0, f = 1.0 / 298.257223563, GM = 3.986004418e14;
  const double b = a * (1.0 - f);
  const double m = kEarthRate_radps * kEarthRate_radps * a * a * b / GM;
  const double s2 = std::pow(std::sin(latitude_deg * kDeg), 2);
  const double g0 = ge * (1.0 + k * s2) / std::sqrt(1.0 - e2 * s2);
  return g0 * (1.0 - 2.0 * height_m / a * (1.0 + f + m - 2.0 * f * s2) + 3.0 * height_m * height_m / (a * a));
}

// ---------------------------------------------------------------------------------------------
// Sensor axes: a small right-handed rotation by angle e about unit vector b moves a vector v by
// e (b x v), so sensor axis a = e_a + sum over the two other b of angle_ab (e_b x e_a).
Matrix3d sensor_axes(const Angles& ang) {
  const Vector3d e[3] = {Vector3d::UnitX(), Vector3d::UnitY(), Vector3d::UnitZ()};
  const double angle[3][3] = {{0, ang.xy, ang.xz}, {ang.yx, 0, ang.yz}, {ang.zx, ang.zy, 0}};
  Matrix3d D;
  for (int a = 0; a < 3; ++a) {
    Vector3d axis = e[a];
    for (int b = 0; b < 3; ++b)
      if (b != a) axis += angle[a][b] * kArcsec * e[b].cross(e[a]);
    D.row(a) = axis.transpose();
  }
  return D;
}

// ---------------------------------------------------------------------------------------------
// Table program
Program::Program(const Config& cfg) {
  Vector3d at_deg(cfg.start_deg[0], cfg.start_deg[1], cfg.start_deg[2]);
  double t = 0;
  for (const Step& s : cfg.steps) {
    Leg leg{&s, t, t, at_deg, 0.0};
    if (s.axis < 0) {
      leg.t1_s = t + s.duration_s;
    } else {
      // A raised-cosine ramp to the peak rate W covers W * ramp / 2, as does the stop, so the
      // cruise lasts |turn| / W - ramp.
      leg.cruise_s = std::abs(s.turn_deg) / s.peak_rate_dps - s.ramp_s;
      if (leg.cruise_s < 0) throw std::invalid_argument("step " + s.name + ": too short a turn for its ramps");
      leg.t1_s = t + 2 * s.ramp_s + leg.cruise_s;
      at_deg[s.axis] += s.turn_deg;
    }
    t = leg.t1_s;
    legs_.push_back(leg);
  }
}

TableState Program::at(double t_s) const {
  TableState st;
  if (legs_.empty()) return st;
  auto it = std::lower_bound(legs_.begin(), legs_.end(), t_s, [](const Leg& l, double t) { return l.t1_s < t; });
  if (it == legs_.end()) {  // after the program: at rest where the last leg ended
    const Leg& last = legs_.back();
    st.angle_deg = last.start_deg;
    if (last.step->axis >= 0) st.angle_deg[last.step->axis] += last.step->turn_deg;
    return st;
  }
  const Leg& leg = *it;
  st.angle_deg = leg.start_deg;
  const Step& s = *leg.step;
  if (s.axis < 0) return st;
  const double W = s.peak_rate_dps, Tr = s.ramp_s, total = std::abs(s.turn_deg);
  const double sign = s.turn_deg >= 0 ? 1.0 : -1.0;
  // The start ramp: rate W/2 (1 - cos(pi u / Tr)), angle its integral.
  auto ramp_angle = [&](double u) { return 0.5 * W * (u - Tr / kPi * std::sin(kPi * u / Tr)); };
  auto ramp_rate = [&](double u) { return 0.5 * W * (1.0 - std::cos(kPi * u / Tr)); };
  const double tau = std::clamp(t_s - leg.t0_s, 0.0, leg.t1_s - leg.t0_s);
  double angle, rate;
  if (tau < Tr) {
    angle = ramp_angle(tau);
    rate = ramp_rate(tau);
  } else if (tau <= Tr + leg.cruise_s) {
    angle = 0.5 * W * Tr + W * (tau - Tr);
    rate = W;
  } else {  // the stop mirrors the start
    const double u = std::max(0.0, leg.t1_s - leg.t0_s - tau);
    angle = total - ramp_angle(u);
    rate = ramp_rate(u);
  }
  st.angle_deg[s.axis] += sign * angle;
  st.rate_dps[s.axis] = sign * rate;
  return st;
}

// ---------------------------------------------------------------------------------------------
// Kinematics. At all-zero angles the platform's xi (middle axis) points along azimuth A from
// North, i.e. at 90 deg - A counter-clockwise from East: C_p0_n is a turn about Up by 90 - A.
// Then C_p_n = Rz(outer) C_p0_n Rx(middle) Rz(inner).
Quat platform_to_level(const Vector3d& angle_deg, double azimuth_deg) {
  const Vector3d X = Vector3d::UnitX(), Z = Vector3d::UnitZ();
  return about_axis(Z, angle_deg[0] * kDeg) * about_axis(Z, (90.0 - azimuth_deg) * kDeg) *
         about_axis(X, angle_deg[1] * kDeg) * about_axis(Z, angle_deg[2] * kDeg);
}

Vector3d platform_inertial_rate(const TableState& s, const Site& site) {
  const Vector3d X = Vector3d::UnitX(), Z = Vector3d::UnitZ();
  // The rate of a chain of rotations is the sum of each joint's rate about its own axis where
  // that axis points now: outer about Up; middle about xi carried by the outer and the base
  // rotation; inner about zeta carried by all but itself.
  const Quat q_outer = about_axis(Z, s.angle_deg[0] * kDeg) * about_axis(Z, (90.0 - site.middle_axis_azimuth_deg) * kDeg);
  const Quat q_middle = q_outer * about_axis(X, s.angle_deg[1] * kDeg);
  const Vector3d w_np_n = (Z * s.rate_dps[0] + rotate(q_outer, X) * s.rate_dps[1] + rotate(q_middle, Z) * s.rate_dps[2]) * kDeg;
  const double lat = site.latitude_deg * kDeg;
  const Vector3d w_ie_n = kEarthRate_radps * Vector3d(0, std::cos(lat), std::sin(lat));
  const Quat q_p_n = platform_to_level(s.angle_deg, site.middle_axis_azimuth_deg);
  return rotate(conjugate(q_p_n), w_np_n + w_ie_n);
}

// ---------------------------------------------------------------------------------------------
namespace {

nlohmann::ordered_json angles_json(const Angles& a) {
  return {{"xy", a.xy}, {"xz", a.xz}, {"yx", a.yx}, {"yz", a.yz}, {"zx", a.zx}, {"zy", a.zy}};
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text << "\n";
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

double wrap_deg(double a) { return std::remainder(a, 360.0); }  // exact, into [-180, 180]

}  // namespace

void write_bundle(const Config& cfg, const std::string& dir_name) {
  const std::filesystem::path dir(dir_name);
  std::filesystem::create_directories(dir);
  const Program program(cfg);
  const Truth& tr = cfg.truth;

  // ---- meta.json
  nlohmann::ordered_json site = {{"latitude_deg", cfg.site.latitude_deg},
                                 {"longitude_deg", cfg.site.longitude_deg},
                                 {"height_m", cfg.site.height_m}};
  if (cfg.site.gravity_mps2) site["gravity_mps2"] = *cfg.site.gravity_mps2;
  site["middle_axis_azimuth_deg"] = cfg.site.middle_axis_azimuth_deg;
  nlohmann::ordered_json meta = {
      {"format", "imucal-recording/1"},
      {"site", site},
      {"imu", {{"serial", "INDEPENDENT-GEN"}, {"rate_hz", cfg.rate_hz}}},
      {"mount", {{"C_o_p", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}, {"r0_p_mm", {0.0, 0.0, 0.0}}}}};
  if (cfg.write_segments) {
    nlohmann::ordered_json segs = nlohmann::ordered_json::array();
    for (const Program::Leg& l : program.legs())
      segs.push_back({{"name", l.step->name}, {"kind", l.step->kind}, {"t0_s", l.t0_s}, {"t1_s", l.t1_s}});
    meta["segments"] = segs;
  }
  write_text(dir / "meta.json", meta.dump(1));

  // ---- truth.json (imucal-imu-model/1)
  const nlohmann::ordered_json truth = {
      {"format", "imucal-imu-model/1"},
      {"frame", "instrument"},
      {"gyro",
       {{"bias_dph", tr.gyro_bias_dph},
        {"scale_pos_ppm", tr.gyro_scale_pos_ppm},
        {"scale_neg_ppm", tr.gyro_scale_neg_ppm},
        {"misalignment_arcsec", angles_json(tr.gyro_angles_arcsec)},
        {"noise", {{"arw_deg_rth", tr.arw_deg_rth}}}}},
      {"accel",
       {{"bias_mps2", tr.accel_bias_mps2},
        {"scale_ppm", tr.accel_scale_ppm},
        {"misalignment_arcsec", angles_json(tr.accel_angles_arcsec)},
        {"noise", {{"vrw_mps_rth", tr.vrw_mps_rth}}}}}};
  write_text(dir / "truth.json", truth.dump(1));

  // ---- the sensor model u = D S(i) i + bias, in SI
  const Matrix3d D_g = sensor_axes(tr.gyro_angles_arcsec), D_a = sensor_axes(tr.accel_angles_arcsec);
  Vector3d b_g, b_a, s_pos, s_neg, s_a;
  for (int j = 0; j < 3; ++j) {
    b_g[j] = tr.gyro_bias_dph[static_cast<std::size_t>(j)] * kDph;
    s_pos[j] = tr.gyro_scale_pos_ppm[static_cast<std::size_t>(j)] * 1e-6;
    s_neg[j] = tr.gyro_scale_neg_ppm[static_cast<std::size_t>(j)] * 1e-6;
    b_a[j] = tr.accel_bias_mps2[static_cast<std::size_t>(j)];
    s_a[j] = tr.accel_scale_ppm[static_cast<std::size_t>(j)] * 1e-6;
  }
  const double g = cfg.site.gravity_mps2.value_or(normal_gravity_mps2(cfg.site.latitude_deg, cfg.site.height_m));
  // Output rates (rad/s and m/s^2) at time t. The origin sits at the axis intersection, so its
  // specific force is the gravity reaction [0 0 g] of the level frame, resolved in o = p.
  auto outputs = [&](double t, Vector3d& u_g, Vector3d& u_a) {
    const TableState s = program.at(t);
    const Vector3d w_io_o = platform_inertial_rate(s, cfg.site);
    const Vector3d f_o = rotate(conjugate(platform_to_level(s.angle_deg, cfg.site.middle_axis_azimuth_deg)),
                                Vector3d(0, 0, g));
    Vector3d scaled_w, scaled_f;
    for (int j = 0; j < 3; ++j) {
      scaled_w[j] = (1.0 + (w_io_o[j] >= 0 ? s_pos[j] : s_neg[j])) * w_io_o[j];
      scaled_f[j] = (1.0 + s_a[j]) * f_o[j];
    }
    u_g = D_g * scaled_w + b_g;
    u_a = D_a * scaled_f + b_a;
  };

  // ---- frames.csv
  const double dt = 1.0 / cfg.rate_hz;
  const auto n_frames = static_cast<long long>(std::floor(program.duration_s() * cfg.rate_hz + 1e-9));
  std::mt19937_64 rng(cfg.noise_seed);
  std::normal_distribution<double> n01;
  const double arw_rad_rts = tr.arw_deg_rth * kDeg / 60.0, vrw_mps_rts = tr.vrw_mps_rth / 60.0;
  // Three-point Gauss-Legendre on [-1, 1]: exact for polynomials up to degree five.
  const double node[3] = {-std::sqrt(0.6), 0.0, std::sqrt(0.6)}, weight[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};

  const std::string csv_path = (dir / "frames.csv").string();
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv(std::fopen(csv_path.c_str(), "w"), &std::fclose);
  if (!csv) throw std::runtime_error("cannot write " + csv_path);
  std::fputs(
      "t_s,dth_x_rad,dth_y_rad,dth_z_rad,dv_x_mps,dv_y_mps,dv_z_mps,outer_deg,middle_deg,inner_deg,"
      "temp_gx_C,temp_gy_C,temp_gz_C,temp_ax_C,temp_ay_C,temp_az_C,temp_chamber_C\n",
      csv.get());
  for (long long k = 1; k <= n_frames; ++k) {
    const double t0 = static_cast<double>(k - 1) * dt, t1 = static_cast<double>(k) * dt;
    Vector3d dtheta = Vector3d::Zero(), dv = Vector3d::Zero();
    const double h = (t1 - t0) / cfg.substeps;
    for (int p = 0; p < cfg.substeps; ++p) {
      const double mid = t0 + (p + 0.5) * h;
      for (int q = 0; q < 3; ++q) {
        Vector3d u_g, u_a;
        outputs(mid + 0.5 * h * node[q], u_g, u_a);
        dtheta += 0.5 * h * weight[q] * u_g;
        dv += 0.5 * h * weight[q] * u_a;
      }
    }
    for (int j = 0; j < 3; ++j) {
      dtheta[j] += arw_rad_rts * std::sqrt(dt) * n01(rng);
      dv[j] += vrw_mps_rts * std::sqrt(dt) * n01(rng);
    }
    Vector3d enc = program.at(t1).angle_deg;
    if (cfg.wrap_angles) enc = enc.unaryExpr(&wrap_deg);
    std::fprintf(csv.get(), "%.9f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,", t1, dtheta[0], dtheta[1],
                 dtheta[2], dv[0], dv[1], dv[2], enc[0], enc[1], enc[2]);
    std::fputs("25.000,25.000,25.000,25.000,25.000,25.000,25.000\n", csv.get());
  }
  if (std::ferror(csv.get())) throw std::runtime_error("cannot write " + csv_path);
}

}  // namespace imucal_test::gen
