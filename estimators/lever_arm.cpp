#include "estimators/lever_arm.hpp"

#include <cmath>
#include <cstdio>

#include <Eigen/Geometry>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"

namespace imucal::lever {

using Eigen::Matrix3d;
using Eigen::Vector3d;

LeverArmFilter::LeverArmFilter(const RecordingMeta& meta, const ImuModel& model, const Options& options)
    : meta_(meta), model_(model), options_(options), table_(table_kinematics(meta)) {
  w_ie_n_ = earth::w_ie_n(meta.site.latitude_deg * units::kDegToRad);
  g_mps2_ = earth::site_gravity_mps2(meta.site);
  dt_nominal_s_ = 1.0 / meta.rate_hz;
  P_ = Eigen::Matrix<double, 9, 9>::Identity() * options.initial_sigma_m * options.initial_sigma_m;
}

void LeverArmFilter::push(const ImuFrame& frame) {
  if (!window_.empty()) {
    const double dt = static_cast<double>(frame.t_ns - window_.back().t_ns) * 1e-9;
    if (dt > 1.5 * dt_nominal_s_ || dt <= 0) {
      // Never difference or integrate across a gap: restart the window and drop the block.
      window_.clear();
      block_z_.setZero();
      block_H_.setZero();
      block_T_ = block_excitation_ = block_horizontal_rate_radps_ = 0;
      ++gaps_;
    }
  }
  window_.push_back(frame);
  if (window_.size() < 4) return;
  process_middle();
  window_.pop_front();
}

void LeverArmFilter::process_middle() {
  // Interval (t_{k-1}, t_k] with k = window_[2]; angles at k-2 .. k+1 give the rate and the
  // angular acceleration at its midpoint by central differences.
  const ImuFrame &f0 = window_[0], &f1 = window_[1], &f2 = window_[2], &f3 = window_[3];
  const double dt = static_cast<double>(f2.t_ns - f1.t_ns) * 1e-9;
  const Vector3d a0 = f0.table_deg * units::kDegToRad, a1 = f1.table_deg * units::kDegToRad;
  const Vector3d a2 = f2.table_deg * units::kDegToRad, a3 = f3.table_deg * units::kDegToRad;
  table::AxisState encoder;
  encoder.angle_rad = 0.5 * (a1 + a2);
  encoder.rate_radps = (a2 - a1) / dt;
  encoder.accel_radps2 = ((a3 - a2) - (a1 - a0)) / (2.0 * dt * dt);
  // The recording's table geometry (core/table): true angles, rates and accelerations, each gimbal
  // about its own axis.
  const table::AxisState mid = table_.true_axes(encoder);
  const table::PlatformRates pr = table_.platform_rates(mid);
  const Matrix3d C_p_n = table_.C_p_n(mid.angle_rad);
  const Matrix3d& C_o_p = meta_.mount.C_o_p;
  const Vector3d w_ie_p = C_p_n.transpose() * w_ie_n_;
  const Vector3d w_o = C_o_p.transpose() * (pr.w_np_p + w_ie_p);
  const Vector3d dw_o = C_o_p.transpose() * (pr.dw_np_p - pr.w_np_p.cross(w_ie_p));
  const Matrix3d K = table::skew(w_o) * table::skew(w_o) + table::skew(dw_o);
  const Matrix3d C_o_n = C_p_n * C_o_p;
  const Vector3d g_o = C_o_n.transpose() * Vector3d(0, 0, g_mps2_);
  // Accelerometer j reports the specific force of tau_j ago: gravity as it stood then, to first
  // order g_o(t - tau) = g_o + tau (w_o x g_o) (gravity is fixed in n and turns by -w in o).
  const Vector3d g_rate_o = w_o.cross(g_o);
  const Vector3d w_n = C_o_n * w_o;
  block_horizontal_rate_radps_ = std::max(block_horizontal_rate_radps_, std::hypot(w_n.x(), w_n.y()));
  // In sensor space, exactly (CONVENTIONS.md): channel j's output less its bias is row j of the
  // stage-1 D S applied to the force at its own proof mass, g + K rho_j. Inverting D S first would
  // mix the other channels' size effect into this one (1e-4 of it).
  // S with the model's K2, K3 at gravity along each axis: the size effect changes a channel's
  // nonlinear scale error by ppm of itself.
  const Matrix3d DS = misalignment_matrix(model_.accel.misalignment_rad) *
                      (Vector3d::Ones() + accel_scale_errors(model_.accel, g_o)).asDiagonal();
  const Vector3d u = f2.dv_mps - model_.accel.bias_mps2 * dt;
  for (int j = 0; j < 3; ++j) {
    block_z_[j] += u[j] - DS.row(j).dot(g_o + model_.accel.delay_s[j] * g_rate_o) * dt;
    block_H_.row(j) += DS.row(j) * K * dt;
  }
  block_T_ += dt;
  block_excitation_ = std::max(block_excitation_, std::max(dw_o.norm(), w_o.squaredNorm()));
  if (block_T_ >= options_.block_s - 1e-12) update_block();
}

void LeverArmFilter::update_block() {
  const bool gravity_turning = block_horizontal_rate_radps_ > options_.max_horizontal_rate_radps;
  if (gravity_turning && block_excitation_ >= options_.min_excitation_radps2) ++skipped_turning_gravity_;
  if (!gravity_turning && block_excitation_ >= options_.min_excitation_radps2) {
    // Channel j depends on rho_j only: three scalar updates per block, each on its 3-state block.
    const double R = std::pow(model_.accel.noise.vrw_mps_rts > 0 ? model_.accel.noise.vrw_mps_rts : 0.002 / 60.0, 2) *
                     block_T_;
    for (int j = 0; j < 3; ++j) {
      Eigen::Matrix<double, 1, 9> H = Eigen::Matrix<double, 1, 9>::Zero();
      H.segment<3>(3 * j) = block_H_.row(j);
      const double innovation = block_z_[j] - H.dot(x_);
      const Eigen::Matrix<double, 9, 1> PHt = P_ * H.transpose();
      const double S = H.dot(PHt) + R;
      const Eigen::Matrix<double, 9, 1> Kg = PHt / S;
      x_ += Kg * innovation;
      // Joseph form keeps P symmetric and positive over hundreds of thousands of updates.
      const Eigen::Matrix<double, 9, 9> I_KH = Eigen::Matrix<double, 9, 9>::Identity() - Kg * H;
      P_ = I_KH * P_ * I_KH.transpose() + Kg * R * Kg.transpose();
    }
    ++updates_;
  }
  block_z_.setZero();
  block_H_.setZero();
  block_T_ = block_excitation_ = block_horizontal_rate_radps_ = 0;
}

Result LeverArmFilter::finish() const {
  Result r;
  r.model = model_;
  r.state_m = x_;
  r.sigma_m = P_.diagonal().cwiseSqrt();
  r.updates = updates_;
  // Coordinates the motion never excited keep their prior: refuse rather than return a guess.
  std::string weak;
  const char* names[9] = {"r0.x", "r0.y", "r0.z", "rho_y.x", "rho_y.y", "rho_y.z", "rho_z.x", "rho_z.y", "rho_z.z"};
  for (int i = 0; i < 9; ++i)
    if (r.sigma_m[i] > 0.1 * options_.initial_sigma_m) weak += std::string(weak.empty() ? "" : ", ") + names[i];
  if (!weak.empty())
    throw std::runtime_error("stage lever-arm: the recording does not determine " + weak +
                             " (run the lever-arm program: oscillations with variable angular acceleration about each "
                             "accelerometer axis pointing up)");
  const Vector3d r0 = x_.segment<3>(0);
  r.model.accel.lever_arm_y_m = x_.segment<3>(3) - r0;
  r.model.accel.lever_arm_z_m = x_.segment<3>(6) - r0;
  r.model.mount_r0_p_m = meta_.mount.C_o_p * r0;
  ImuErrorSet sigma = r.model.sigma.value_or(ImuErrorSet{});
  const Eigen::Matrix<double, 9, 9>& P = P_;
  for (int i = 0; i < 3; ++i) {
    sigma.accel.lever_arm_y_m[i] = std::sqrt(P(3 + i, 3 + i) + P(i, i) - 2 * P(i, 3 + i));
    sigma.accel.lever_arm_z_m[i] = std::sqrt(P(6 + i, 6 + i) + P(i, i) - 2 * P(i, 6 + i));
  }
  r.model.sigma = sigma;
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "stage lever-arm: %lld updates, %lld gaps, %lld blocks left out (gravity turning); r0 sigma %.3f %.3f %.3f mm",
                updates_, gaps_, skipped_turning_gravity_, r.sigma_m[0] * 1e3, r.sigma_m[1] * 1e3, r.sigma_m[2] * 1e3);
  r.notes.push_back(buf);
  return r;
}

}  // namespace imucal::lever
