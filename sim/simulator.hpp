// The physics simulation of a table + Earth + IMU, with no I/O: true motion from the program's
// analytic angle functions, Earth rate and gravity, specific force at each proof mass (seed eq. 3),
// the sensor model of a truth imucal-imu-model/1, delays of any length, noise from one seeded
// stream per source, quantisation to integer counts with the remainder carried. Bit-for-bit
// reproducible for a seed. `imucal simulate` and the wire-level simulated devices both use it.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "core/table.hpp"
#include "core/turn_on.hpp"
#include "motion_programs/program.hpp"

namespace imucal::sim {

// Temperatures and truth coefficients that change over the run (sim/thermal_model.hpp).
// Without one the simulator logs the constant temperature_C and uses the truth's constants, bit
// for bit as it always has.
class ThermalSource {
 public:
  virtual ~ThermalSource() = default;
  // The logged temperatures at t; false when the logger delivers no sample then.
  virtual bool temperatures(double t_s, TempSample& out) const = 0;
  // The biases, scale factors and misalignments at t, starting from the truth's constants.
  virtual void coefficients(double t_s, GyroErrors& gyro, AccelErrors& accel) const = 0;
};

struct SimConfig {
  Site site;
  Mount mount;
  double rate_hz = 1000.0;
  std::uint64_t seed = 1;
  double duration_s = 0.0;  // 0: the program's duration
  double temperature_C = 25.0;
  double temp_rate_hz = 1.0;  // temperature samples per second
  const ThermalSource* thermal = nullptr;  // not owned; outlives the simulator
  // The table's own errors (formats.md `table`): the table moves by the program's angles as true
  // angles about its erroneous axes and the encoders read them with their periodic errors; the
  // run's meta carries the certificate. Absent, or without a geometry: the ideal table.
  std::optional<table::TableCertificate> table;
};

// Normal deviates from a 64-bit Mersenne Twister by Box-Muller, written out so the stream is the
// same on every standard library (std::normal_distribution is implementation-defined).
class NormalStream {
 public:
  explicit NormalStream(std::uint64_t seed) : engine_(seed) {}
  double next();

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

// The true kinematics of the IMU at one instant (what an ideal IMU would sense).
struct TrueKinematics {
  Eigen::Matrix3d C_o_n;          // instrument frame to ENU
  Eigen::Vector3d w_io_o;         // inertial rate of o, in o
  Eigen::Vector3d dw_io_o;        // its time derivative
  Eigen::Vector3d f_origin_o;     // specific force at the origin (x proof mass), in o
  Eigen::Vector3d r_origin_n;     // origin position from the axis intersection, ENU, metres
  Eigen::Vector3d v_origin_n;     // origin velocity relative to Earth, ENU
};

// The part of every frame that no seed changes: the increments the motion makes the sensors
// sense through the truth's deterministic terms (before biases, noise and quantisation) and the
// encoders' angles. Most of a simulation's time goes into it; runs of many seeds of one program,
// truth and bench (the suite's tests of how errors spread) compute it once and share it.
class MotionSignal;

class Simulator {
 public:
  Simulator(const motion::Program& program, const ImuModel& truth, const SimConfig& config);

  // The next frame; false when the run is over. Temperatures are produced at their own rate and
  // collected with take_temps().
  bool next(ImuFrame& out);
  std::vector<TempSample> take_temps();

  RecordingMeta meta() const;
  std::int64_t frame_count() const { return n_frames_; }
  double dt_s() const { return dt_s_; }
  TrueKinematics kinematics(double t_s) const;
  // The random part of the biases now (Gauss-Markov plus random walk): gyro x y z (rad/s), then
  // accelerometer x y z (m/s^2). Tests compare estimates of drifting biases against it.
  Eigen::Matrix<double, 6, 1> stochastic_bias() const;
  // Continue the same IMU from another run: its random-walk biases start where that run ended.
  void continue_stochastic_bias(const Eigen::Matrix<double, 6, 1>& bias);

  // The signal of every frame of this run, computed now (as long as simulating the run without its
  // noise), for simulators of other seeds to share. Not with a thermal source: its coefficients
  // cannot be compared, so no other simulator could be shown to share them.
  std::shared_ptr<const MotionSignal> motion_signal() const;
  // Each frame's signal read from `signal` instead of computed: the frames are bit for bit those
  // this simulator would compute. Throws std::invalid_argument, naming what differs, when the
  // signal is of another program, truth (its noise aside), site, mount, table, rate or length.
  void use_motion_signal(std::shared_ptr<const MotionSignal> signal);

  static constexpr double kGyroLsbAt1kHz_rad = 1e-11;
  static constexpr double kAccelLsbAt1kHz_mps = 1e-10;

 private:
  // Integral over [a, b] of the sensor outputs of the channels in `mask` (bit j: gyro j,
  // bit 3+j: accel j), split at the program's breakpoints, Gauss-Legendre inside each part.
  void integrate(double a, double b, unsigned mask, Eigen::Vector3d& gyro, Eigen::Vector3d& accel) const;
  // The outputs at t of the gyros and the accelerometers of `mask`'s triads (a triad outside it
  // is left zero: the channels of another delay group, which integrate() drops anyway).
  void sensor_outputs(double t, unsigned mask, Eigen::Vector3d& u_gyro, Eigen::Vector3d& u_accel) const;
  friend class MotionSignal;
  // Frame k's signal: the delay groups' integrals summed, and the encoders at its end.
  struct SignalFrame {
    Eigen::Vector3d dtheta_rad, dv_mps, table_deg;
  };
  SignalFrame signal_of(std::int64_t k) const;
  static void outputs(const TrueKinematics& k, const GyroErrors& gyro, const AccelErrors& accel,
                      const Eigen::Matrix3d& D_accel, unsigned mask, Eigen::Vector3d& u_gyro,
                      Eigen::Vector3d& u_accel);

  const motion::Program& program_;
  ImuModel truth_;
  SimConfig config_;
  table::TableKinematics table_;
  Eigen::Vector3d w_ie_n_;
  double g_mps2_;
  double dt_s_;
  std::int64_t n_frames_;
  std::int64_t k_ = 0;  // frames produced
  std::vector<double> breakpoints_;
  mutable std::size_t cursor_ = 0;
  Eigen::Matrix3d D_gyro_, D_accel_;

  // Channels grouped by equal delay so that each group needs one set of kinematic evaluations.
  struct DelayGroup {
    double delay_s;
    unsigned mask;
  };
  std::vector<DelayGroup> groups_;
  std::shared_ptr<const MotionSignal> signal_;  // null: computed frame by frame

  double gyro_lsb_rad_, accel_lsb_mps_;
  Eigen::Vector3d gyro_remainder_ = Eigen::Vector3d::Zero(), accel_remainder_ = Eigen::Vector3d::Zero();

  // One stream per noise source: white and correlated bias, per channel.
  std::array<NormalStream, 6> white_;
  // Correlated bias per channel: one Gauss-Markov process with the configured correlation time, or
  // five with correlation times a decade apart whose Allan curves add to a flat flicker floor.
  struct GaussMarkov {
    double phi, drive, state;
    NormalStream stream;
  };
  std::array<std::vector<GaussMarkov>, 6> gm_;
  std::array<NormalStream, 6> bias_rw_;
  Eigen::Matrix<double, 6, 1> rw_state_ = Eigen::Matrix<double, 6, 1>::Zero();
  std::array<double, 6> white_sigma_{}, rw_drive_{};

  std::vector<TempSample> temps_;
  double next_temp_t_s_ = 0.0;

  // The truth's turn-on terms (core/turn_on.hpp): the IMU is powered on at t = 0 and at the start
  // of each power-cycle segment of the program; each power-on's bias offsets, gyro x y z then
  // accelerometer x y z, drawn from a stream of their own.
  std::optional<TurnOnTerms> turn_on_;
  std::vector<double> power_on_s_;
  std::vector<Eigen::Matrix<double, 6, 1>> turn_on_offset_;
  std::size_t power_on_cursor_ = 0;
};

}  // namespace imucal::sim
