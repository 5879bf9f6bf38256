#include "estimators/navigation_run.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>

#include <Eigen/LU>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"
#include "estimators/thermal.hpp"

namespace imucal::nav {

using Eigen::Matrix3d;
using Eigen::Vector3d;

Compensator::Reach Compensator::reach(double delay_s) const {
  const double s = delay_s / dt_nominal_s_;
  const double n = std::floor(s);
  const bool fractional = s != n;
  return {static_cast<int>(n) + (fractional ? 3 : 1), (fractional ? 2 : 1) - static_cast<int>(n)};
}

Compensator::Compensator(const ImuModel& model, double dt_nominal_s, double max_abs_delay_s)
    : model_(model), dt_nominal_s_(dt_nominal_s) {
  // The frames shifted() reads for a delay of s samples: one frame beyond the shift on each side,
  // and with a fractional delay one more on each side for the cubic. Whole-sample delays (zero
  // among them) need no more than before.
  const auto cover = [&](double delay_s) {
    if (!std::isfinite(delay_s)) return;  // unfollowed_delay() says so before anything is read
    const Reach r = reach(delay_s);
    lookahead_ = std::max(lookahead_, r.ahead);
    lookback_ = std::max(lookback_, r.behind);
  };
  for (int j = 0; j < 3; ++j) {
    cover(model.gyro.delay_s[j]);
    cover(model.accel.delay_s[j]);
  }
  if (max_abs_delay_s > 0) {
    // A filter moves the delays anywhere within +-max_abs_delay_s: any fractional delay up to it.
    const int m = static_cast<int>(std::ceil(max_abs_delay_s / dt_nominal_s_));
    lookahead_ = std::max(lookahead_, m + 2);
    lookback_ = std::max(lookback_, m + 2);
  }
}

std::string Compensator::unfollowed_delay() const {
  // Within a hundred times the window first, so that the casts in reach() stay in range.
  const double bound_s = 100.0 * (lookahead_ + lookback_) * dt_nominal_s_;
  for (const bool gyro : {true, false}) {
    const Vector3d& delay = gyro ? model_.gyro.delay_s : model_.accel.delay_s;
    for (int j = 0; j < 3; ++j) {
      bool out = !(std::abs(delay[j]) <= bound_s);
      if (!out) {
        const Reach r = reach(delay[j]);
        out = r.ahead > lookahead_ || r.behind > lookback_;
      }
      if (out) {
        char text[96];
        std::snprintf(text, sizeof text, "%s %c delay %.6g s", gyro ? "gyro" : "accelerometer", "xyz"[j], delay[j]);
        return text;
      }
    }
  }
  return {};
}

// Channel j's output lags its input by tau_j, so the input over (t_{k-1}, t_k] is the output over
// (t_{k-1}+tau, t_k+tau]: the cumulative output interpolated at those instants, by the cubic
// through the four grid instants around each (Lagrange). The difference of the two interpolants
// is a weighted sum of four increments whose weights are the cubic's own: with tau = (n + f) dt,
// L(-1) u[k+n-1] + L(0) u[k+n] + L(1) u[k+n+1] + L(2) u[k+n+2].
// Linear interpolation (two increments, weights 1-f and f) is off by f(1-f) dt^2 / 2 times the
// output's rate of change in the cumulative output: at 100 Hz with 2 ms of accelerometer delay
// (f = 0.2) up to 8e-5 m/s of velocity on a 180 deg, 20 s oscillation, a systematic error the
// filter's delay model does not have (on noise-free data it left the y accelerometer's delay and
// the proof-mass offsets y.z, z.y 2.4, 1.9 and 4.4 sigma from the truth, issue 16); the cubic's
// error is f(1-f)(1+f)(2-f) dt^4 / 24 times the third derivative, below 1e-8 m/s there.
Vector3d Compensator::shifted(const std::deque<ImuFrame>& window, bool gyro, int offset) const {
  const Vector3d& delay = gyro ? model_.gyro.delay_s : model_.accel.delay_s;
  Vector3d out;
  for (int j = 0; j < 3; ++j) {
    const double s = delay[j] / dt_nominal_s_;
    const double n = std::floor(s);
    const double f = s - n;
    const auto at = [&](double d) {
      const auto idx = static_cast<std::size_t>(lookback_ + offset + static_cast<int>(d));
      const ImuFrame& fr = window[idx];
      return gyro ? fr.dtheta_rad[j] : fr.dv_mps[j];
    };
    if (f == 0.0) {
      out[j] = at(n);
      continue;
    }
    const double w_m1 = -f * (f - 1.0) * (f - 2.0) / 6.0;
    const double w_0 = (f + 1.0) * (f - 1.0) * (f - 2.0) / 2.0;
    const double w_1 = -(f + 1.0) * f * (f - 2.0) / 2.0;
    const double w_2 = (f + 1.0) * f * (f - 1.0) / 6.0;
    out[j] = w_m1 * at(n - 1) + w_0 * at(n) + w_1 * at(n + 1) + w_2 * at(n + 2);
  }
  return out;
}

Vector3d Compensator::rate_radps(const std::deque<ImuFrame>& window, int offset, double dt_s) const {
  return compensate_gyro_increment(model_.gyro, shifted(window, true, offset), dt_s) / dt_s;
}

CompensatedSample Compensator::compensate(const std::deque<ImuFrame>& window) const {
  // Never read outside the window (a delay run away, or a window too short): an error, not
  // memory past the deque's end.
  if (window.size() < window_frames())
    throw std::logic_error("nav::Compensator: a window of " + std::to_string(window.size()) + " frames, " +
                           std::to_string(window_frames()) + " needed");
  if (const std::string delay = unfollowed_delay(); !delay.empty())
    throw std::logic_error("nav::Compensator: the " + delay + " is beyond the frames its window holds");
  CompensatedSample c;
  const auto k = static_cast<std::size_t>(lookback_);
  const double dt = static_cast<double>(window[k].t_ns - window[k - 1].t_ns) * 1e-9;
  // The rates the size effect needs, without the gyros' g-sensitivity (it needs the specific force,
  // which needs the size effect): at 0.01 deg/h/g that is 5e-8 rad/s, which moves the size effect
  // of a 50 mm offset by 5e-9 m/s^2 at 1 rad/s.
  c.w_radps = rate_radps(window, 0, dt);
  // The rate's derivative at mid-interval from the neighbours' compensated mean rates, a sample
  // interval apart (gaps never reach the window): second order in the interval, 3e-7 rad/s^2 at
  // 100 Hz on a 180 deg, 20 s oscillation.
  c.dw_radps2 = (rate_radps(window, 1, dt_nominal_s_) - rate_radps(window, -1, dt_nominal_s_)) / (2.0 * dt_nominal_s_);
  const Eigen::Matrix3d offsets = proof_mass_offsets_m(model_);
  // Exact removal in sensor space: each channel's own term through its own row of D S (the raw
  // output is D S f_j row by row), then the inverse model. See docs/calibration.md.
  if (!offsets.isZero()) c.size_effect_mps2 = size_effect_mps2(offsets, c.w_radps, c.dw_radps2);
  // The one rule of core/imu_model: accelerometers, then the gyros with their g-sensitivity.
  const CompensatedIncrements inc = compensate_imu_increments(model_.gyro, model_.accel, shifted(window, true, 0),
                                                              shifted(window, false, 0), dt, c.size_effect_mps2);
  c.w_radps = inc.dtheta_rad / dt;
  c.dtheta_rad = c.w_radps * dt;
  c.dv_mps = inc.dv_mps;
  return c;
}

TableReference::TableReference(const RecordingMeta& meta, const ImuModel& model) : table_(table_kinematics(meta)) {
  C_o_p_ = meta.mount.C_o_p;
  C_b_o_ = Matrix3d::Identity();
  if (model.frame == "body" && model.body_to_instrument_rad) C_b_o_ = C_b_o_of(*model.body_to_instrument_rad);
  r0_p_m_ = model.mount_r0_p_m ? *model.mount_r0_p_m : meta.mount.r0_p_m;
  lat0_ = meta.site.latitude_deg * units::kDegToRad;
  lon0_ = meta.site.longitude_deg * units::kDegToRad;
  h0_ = meta.site.height_m;
  RM0_ = earth::meridian_radius_m(lat0_) + h0_;
  RN0_ = earth::prime_vertical_radius_m(lat0_) + h0_;
}

void TableReference::set_body_to_instrument(const Vector3d& rot_rad) {
  C_b_o_ = C_b_o_of(rot_rad);
}

TableReference::Sample TableReference::at(const std::deque<ImuFrame>& window, std::size_t i) const {
  // The stand moves the origin only by rotation about the axis intersection (eq. 14).
  const ImuFrame& f = window[i];
  const std::size_t lo = i > 0 ? i - 1 : i, hi = i + 1 < window.size() ? i + 1 : i;
  table::AxisState encoder;
  encoder.angle_rad = f.table_deg * units::kDegToRad;
  if (hi > lo)
    encoder.rate_radps = (window[hi].table_deg - window[lo].table_deg) * units::kDegToRad /
                         (static_cast<double>(window[hi].t_ns - window[lo].t_ns) * 1e-9);
  const table::AxisState axes = table_.true_axes(encoder);
  const Matrix3d C_p_n = table_.C_p_n(axes.angle_rad);
  Sample r;
  r.C_b_n = C_p_n * C_o_p_ * C_b_o_;
  r.r_n = C_p_n * r0_p_m_;
  r.v_n = C_p_n * table_.platform_rates(axes).w_np_p.cross(r0_p_m_);
  return r;
}

NavState TableReference::initial_state(const Sample& r) const {
  NavState s;
  s.q_b_n = Eigen::Quaterniond(r.C_b_n);
  s.v_n = r.v_n;
  s.lat_rad = lat0_ + r.r_n.y() / RM0_;
  s.lon_rad = lon0_ + r.r_n.x() / (RN0_ * std::cos(lat0_));
  s.h_m = h0_ + r.r_n.z();
  return s;
}

Vector3d TableReference::position_error_m(const NavState& s, const Sample& r) const {
  return {(s.lon_rad - lon0_) * RN0_ * std::cos(lat0_) - r.r_n.x(), (s.lat_rad - lat0_) * RM0_ - r.r_n.y(),
          s.h_m - h_ref_m(r)};
}

// The model's coefficients at T_ref, and the temperatures and rates that move them (stage 2).
struct NavigationRun::Thermal {
  thermal::ThermalSection section;
  GyroErrors gyro_at_ref;
  AccelErrors accel_at_ref;
  thermal::ChannelRate rate;
};

NavigationRun::NavigationRun(const RecordingMeta& meta, const ImuModel& model, double output_interval_s, Sink sink)
    : meta_(meta),
      model_(model),
      comp_(model_, 1.0 / meta.rate_hz),
      sink_(std::move(sink)),
      output_interval_s_(output_interval_s),
      ref_(meta, model) {
  dt_nominal_s_ = 1.0 / meta.rate_hz;
  if (auto s = thermal::thermal_of(model); s && s->has_models())
    thermal_ = std::make_shared<Thermal>(Thermal{*s, model.gyro, model.accel, thermal::ChannelRate{}});
}

void NavigationRun::push_temp(const TempSample& temp) {
  if (!thermal_) return;
  thermal_->rate.push(temp);
  // The compensator reads model_: move its coefficients to this temperature and rate.
  model_.gyro = thermal_->gyro_at_ref;
  model_.accel = thermal_->accel_at_ref;
  thermal::apply_thermal(thermal_->section, thermal_->rate.current(), model_.gyro, model_.accel);
}

void NavigationRun::push(const ImuFrame& frame) {
  if (!window_.empty()) {
    const double gap_s = static_cast<double>(frame.t_ns - window_.back().t_ns) * 1e-9;
    if (gap_s > 1.5 * dt_nominal_s_ || gap_s <= 0) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "navigate: gap in the IMU frames at t=%.6f s (%.6f s without data); navigation does not "
                    "integrate across gaps",
                    static_cast<double>(window_.back().t_ns) * 1e-9, gap_s);
      throw std::runtime_error(buf);
    }
  }
  window_.push_back(frame);
  ++frames_seen_;
  const std::size_t needed = comp_.window_frames();
  if (window_.size() < needed) return;
  step();
  window_.pop_front();
}

void NavigationRun::step() {
  const auto k = static_cast<std::size_t>(comp_.lookback());
  if (!started_) {
    // Initialise at the previous frame's instant from the table: attitude, velocity, position.
    nav_ = std::make_unique<Strapdown>(ref_.initial_state(ref_.at(window_, k - 1)), earth::site_gravity_mps2(meta_.site));
    first_t_ns_ = window_[k - 1].t_ns;
    started_ = true;
  }
  const double dt = static_cast<double>(window_[k].t_ns - window_[k - 1].t_ns) * 1e-9;
  const CompensatedSample c = comp_.compensate(window_);
  const TableReference::Sample r = ref_.at(window_, k);
  nav_->update(c.dtheta_rad, c.dv_mps, dt, r.v_n.z(), ref_.h_ref_m(r));
  const NavState& s = nav_->state();
  NavErrorSample e;
  e.t_s = static_cast<double>(window_[k].t_ns) * 1e-9;
  e.dv_n_mps = s.v_n - r.v_n;
  e.dp_n_m = ref_.position_error_m(s, r);
  const Eigen::Quaterniond q_err = s.q_b_n * Eigen::Quaterniond(r.C_b_n).conjugate();
  const Eigen::AngleAxisd aa(q_err);
  e.attitude_err_n_rad = aa.angle() * aa.axis();
  ++summary_.frames;
  summary_.duration_s = static_cast<double>(window_[k].t_ns - first_t_ns_) * 1e-9;
  summary_.max_velocity_error_mps = std::max(summary_.max_velocity_error_mps, e.dv_n_mps.head<2>().norm());
  summary_.max_position_error_m = std::max(summary_.max_position_error_m, e.dp_n_m.head<2>().norm());
  summary_.max_attitude_error_rad = std::max(summary_.max_attitude_error_rad, e.attitude_err_n_rad.norm());
  if (sink_ && e.t_s + 1e-9 >= next_output_s_) {
    sink_(e);
    next_output_s_ = e.t_s + output_interval_s_;
  }
}

NavSummary NavigationRun::finish() {
  if (!started_)
    throw std::runtime_error("navigate: too few frames to navigate (" + std::to_string(frames_seen_) + ")");
  return summary_;
}

}  // namespace imucal::nav
