// Free-inertial navigation of a recording against the reference the table implies (seed eq. 14):
// frames in (streamed), model compensation (biases, scale factors and their nonlinearity,
// misalignments, lever arms, delays, g-sensitivity), strapdown navigation, and the horizontal
// velocity and position errors of the IMU origin.
#pragma once

#include <cstdint>
#include <deque>
#include <string>
#include <functional>
#include <memory>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/imu_model.hpp"
#include "core/recording.hpp"
#include "core/table.hpp"
#include "estimators/strapdown.hpp"

namespace imucal::nav {

struct NavErrorSample {
  double t_s = 0;
  Eigen::Vector3d dv_n_mps = Eigen::Vector3d::Zero();      // navigation minus reference, ENU
  Eigen::Vector3d dp_n_m = Eigen::Vector3d::Zero();        // ENU metres (Up held: zero)
  Eigen::Vector3d attitude_err_n_rad = Eigen::Vector3d::Zero();
};

struct NavSummary {
  double duration_s = 0;
  std::int64_t frames = 0;
  double max_velocity_error_mps = 0;   // horizontal
  double max_position_error_m = 0;     // horizontal
  double max_attitude_error_rad = 0;
};

// One sample interval reduced to its compensated input, in the model's frame.
struct CompensatedSample {
  Eigen::Vector3d dtheta_rad = Eigen::Vector3d::Zero();  // rotation increment
  Eigen::Vector3d dv_mps = Eigen::Vector3d::Zero();      // specific-force increment at the origin
  Eigen::Vector3d w_radps = Eigen::Vector3d::Zero();     // mean inertial rate over the interval
  Eigen::Vector3d dw_radps2 = Eigen::Vector3d::Zero();   // its derivative (central difference)
  // Row j: f_j - f_origin, the specific force accelerometer j's proof mass adds (seed eq. 3),
  // mean over the interval; the error model of channel j acts on f_origin + this row.
  Eigen::Matrix3d size_effect_mps2 = Eigen::Matrix3d::Zero();
};

// Reduces raw increments to the compensated input over each sample interval. Needs a few frames
// of look-ahead to undo channel delays; the runner feeds it a window of frames.
class Compensator {
 public:
  // The window covers the model's delays, or max_abs_delay_s when larger (for a filter that will
  // update the delays while it runs).
  Compensator(const ImuModel& model, double dt_nominal_s, double max_abs_delay_s = 0.0);
  // Frames on each side of the current one that compensate() reads.
  int lookahead() const { return lookahead_; }
  int lookback() const { return lookback_; }
  // Frames compensate() reads: lookback() + 1 + lookahead().
  std::size_t window_frames() const { return static_cast<std::size_t>(lookback_ + 1 + lookahead_); }
  // window[lookback()] is the frame being compensated; window holds lookback()+1+lookahead() frames.
  // Throws std::logic_error when a delay of the model has left the window (see unfollowed_delay).
  CompensatedSample compensate(const std::deque<ImuFrame>& window) const;
  // The first delay of the model it compensates with that the window cannot follow, in words
  // ("gyro y delay 0.0213 s"), or empty: a filter that moved a delay there has diverged (its
  // frames would be read from outside the window), and says so instead of compensating.
  std::string unfollowed_delay() const;

 private:
  // Frames ahead of and behind the current one that a delay of `delay_s` reads (the cubic's four
  // around the shifted instant, at the rate derivative's offsets -1..1).
  struct Reach {
    int ahead = 0, behind = 0;
  };
  Reach reach(double delay_s) const;
  // Channel outputs over the interval `offset` frames from the current one, moved back by each
  // channel's delay onto the interval of its input.
  Eigen::Vector3d shifted(const std::deque<ImuFrame>& window, bool gyro, int offset) const;
  Eigen::Vector3d rate_radps(const std::deque<ImuFrame>& window, int offset, double dt_s) const;
  const ImuModel& model_;
  int lookahead_ = 1, lookback_ = 1;
  double dt_nominal_s_ = 0;
};

// The reference the table implies for the IMU origin (seed eq. 14), and the conversions between
// the navigation state and metres on the site's local level.
class TableReference {
 public:
  TableReference(const RecordingMeta& meta, const ImuModel& model);
  struct Sample {
    Eigen::Matrix3d C_b_n;
    Eigen::Vector3d v_n, r_n;  // origin velocity and position from the axis intersection, ENU
  };
  // Reference at window[i]; the platform rate by central differences of the encoder angles, both
  // through the recording's table geometry (core/table).
  Sample at(const std::deque<ImuFrame>& window, std::size_t i) const;
  NavState initial_state(const Sample& s) const;
  // How the body frame sits in the instrument frame (formats.md body_to_instrument_arcsec), for a
  // filter that refines it.
  void set_body_to_instrument(const Eigen::Vector3d& rot_rad);
  double h_ref_m(const Sample& s) const { return h0_ + s.r_n.z(); }
  // Position error of a navigation state, ENU metres (Up is zero when the vertical is held).
  Eigen::Vector3d position_error_m(const NavState& nav, const Sample& s) const;
  // Metres east/north to radians of longitude/latitude at the site.
  double RM_m() const { return RM0_; }
  double RN_m() const { return RN0_; }
  double latitude_rad() const { return lat0_; }

 private:
  table::TableKinematics table_;
  Eigen::Matrix3d C_o_p_, C_b_o_;
  Eigen::Vector3d r0_p_m_;
  double lat0_, lon0_, h0_, RM0_, RN0_;
};

class NavigationRun {
 public:
  using Sink = std::function<void(const NavErrorSample&)>;
  NavigationRun(const RecordingMeta& meta, const ImuModel& model, double output_interval_s, Sink sink);

  void push(const ImuFrame& frame);  // throws std::runtime_error on a gap in the frames
  // Temperatures for a model with a "thermal" section (ignored without one): push each sample
  // before the frames after it. Until the first, the coefficients are those at T_ref.
  void push_temp(const TempSample& temp);
  NavSummary finish();

 private:
  void step();  // navigate the frame at window_[lookback]
  struct Thermal;
  std::shared_ptr<Thermal> thermal_;  // stage-2 compensation state, when the model has one

  RecordingMeta meta_;
  ImuModel model_;
  Compensator comp_;
  Sink sink_;
  double output_interval_s_;
  double next_output_s_ = 0;
  TableReference ref_;
  double dt_nominal_s_;
  std::deque<ImuFrame> window_;
  std::int64_t frames_seen_ = 0;
  std::int64_t first_t_ns_ = 0;
  bool started_ = false;
  std::unique_ptr<Strapdown> nav_;
  NavSummary summary_;
};

}  // namespace imucal::nav
