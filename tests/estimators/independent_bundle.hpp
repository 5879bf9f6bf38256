// A test-only generator of `imucal-recording/1` bundles (meta.json, frames.csv, truth.json),
// written from the spec's CONVENTIONS.md and formats.md alone. It shares no code with the
// project's simulator (sim/), its motion programs (motion_programs/), the table and Earth
// functions (core/table, core/earth) or the sensor model (core/imu_model): its own quaternions,
// its own Earth rate and normal gravity, its own table motion and its own sensor-error model.
// Only Eigen's plain vectors and nlohmann::json are shared, as libraries.
//
// The table really moves: every change of position is a rest-to-rest turn of one axis with a
// raised-cosine rate at its start and stop, and the gyro increments integrate the true inertial
// rate of that motion (Earth rate included) over each sample by Gauss-Legendre quadrature.
// Every proof mass sits at the table's axis intersection (no lever arms), there are no channel
// delays and no quantisation: stage `direct` estimates none of those.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross products only

namespace imucal_test::gen {

// ---- the generator's own rotation math: unit quaternions, q * v * q^-1 rotates v actively.
struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};
Quat operator*(const Quat& a, const Quat& b);
Quat conjugate(const Quat& q);
Quat about_axis(const Eigen::Vector3d& unit_axis, double angle_rad);
Eigen::Vector3d rotate(const Quat& q, const Eigen::Vector3d& v);

// ---- Earth (CONVENTIONS.md, WGS-84)
inline constexpr double kEarthRate_radps = 7.292115e-5;
inline constexpr double kPi = 3.14159265358979323846;
// Somigliana normal gravity at latitude with the free-air correction of CONVENTIONS.md.
double normal_gravity_mps2(double latitude_deg, double height_m);

// ---- the IMU truth, in the units of imucal-imu-model/1
struct Angles {  // "ab": sensor axis a turned right-handedly about instrument axis b, arc seconds
  double xy = 0, xz = 0, yx = 0, yz = 0, zx = 0, zy = 0;
};
struct Truth {
  std::array<double, 3> gyro_bias_dph{}, gyro_scale_pos_ppm{}, gyro_scale_neg_ppm{};
  Angles gyro_angles_arcsec;
  std::array<double, 3> accel_bias_mps2{}, accel_scale_ppm{};
  Angles accel_angles_arcsec;
  double arw_deg_rth = 0, vrw_mps_rth = 0;
};

// Rows are the three sensor axes in the instrument frame, to first order in the angles:
// sensor axis a = e_a + sum_b angle_ab (e_b x e_a).
Eigen::Matrix3d sensor_axes(const Angles& angles_arcsec);

// ---- the table program: a start attitude, then steps
struct Step {
  std::string name;
  std::string kind;              // segment kind: "static" for a hold; "move" or "rate" for a turn
  int axis = -1;                 // 0 outer, 1 middle, 2 inner; -1: hold still
  double duration_s = 0;         // hold only
  double turn_deg = 0;           // turn only: signed angle
  double peak_rate_dps = 10;     // turn only: magnitude of the cruise rate
  double ramp_s = 2;             // turn only: raised-cosine start and stop, each this long
};

struct Site {
  double latitude_deg = 59.94, longitude_deg = 30.31, height_m = 10.0;
  std::optional<double> gravity_mps2;  // absent: the bundle says nothing and normal gravity holds
  double middle_axis_azimuth_deg = 0;
};

struct Config {
  Site site;
  double rate_hz = 20;
  std::array<double, 3> start_deg{0, 0, 0};  // outer, middle, inner
  std::vector<Step> steps;
  Truth truth;
  std::uint64_t noise_seed = 1;
  bool write_segments = true;  // false: the importer must find the statics from the table angles
  bool wrap_angles = true;     // write the encoder angles wrapped to [-180, 180]
  int substeps = 4;            // Gauss-Legendre panels per sample
};

// Table angles (degrees, as the encoders read them, unwrapped) and their rates at time t.
struct TableState {
  Eigen::Vector3d angle_deg = Eigen::Vector3d::Zero(), rate_dps = Eigen::Vector3d::Zero();
};

class Program {
 public:
  explicit Program(const Config& cfg);
  double duration_s() const { return legs_.empty() ? 0.0 : legs_.back().t1_s; }
  TableState at(double t_s) const;
  struct Leg {
    const Step* step;
    double t0_s, t1_s;
    Eigen::Vector3d start_deg;  // angles at t0
    double cruise_s = 0;        // turn: time at the peak rate
  };
  const std::vector<Leg>& legs() const { return legs_; }

 private:
  std::vector<Leg> legs_;
};

// The platform attitude C_p_n (as a quaternion, v_n = q * v_p) for table angles, and the inertial
// rate of the platform resolved in p, w_ip_p = w_np_p + C_n_p w_ie_n.
Quat platform_to_level(const Eigen::Vector3d& angle_deg, double azimuth_deg);
Eigen::Vector3d platform_inertial_rate(const TableState& s, const Site& site);

// The mount is the identity fixture (C_o_p = I, r0_p = 0), so o = p.
// Writes dir/meta.json, dir/frames.csv and dir/truth.json (dir is created).
void write_bundle(const Config& cfg, const std::string& dir);

}  // namespace imucal_test::gen
