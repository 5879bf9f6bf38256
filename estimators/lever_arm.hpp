// Accelerometer proof-mass positions (seed eq. 5, 6): a 9-state Kalman filter, state
// [rho_x, rho_y, rho_z] where rho_j is accelerometer j's proof mass from the table's axis
// intersection (o frame, metres); rho_x = r0 (the origin), r_y = rho_y - rho_x, r_z = rho_z - rho_x.
// Each accelerometer senses w x (w x rho_j) + dw/dt x rho_j plus gravity along its own axis; the
// measurement is its stage-1-compensated output minus the known gravity term. The rates come from
// the table angles. Pure: frames in, estimate out.
#pragma once

#include <deque>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "core/recording.hpp"

namespace imucal::lever {

struct Options {
  double block_s = 0.02;            // frames summed into one measurement update
  double initial_sigma_m = 0.2;     // prior 1-sigma of each coordinate
  double min_excitation_radps2 = 0.5;  // blocks with less |dw/dt| or |w|^2 carry no information
  // Blocks in which gravity turns in the sensor frame (a rate about a horizontal axis above this)
  // are left out: there the unknown accelerometer delays (~2 ms, found only by stage 3) turn the
  // changing gravity into errors of tau |w x g| that would pass for lever-arm signal.
  double max_horizontal_rate_radps = 0.01;
};

struct Result {
  ImuModel model;  // the given model with lever_arm_mm, mount.r0_p_mm and their sigmas
  Eigen::Matrix<double, 9, 1> state_m;
  Eigen::Matrix<double, 9, 1> sigma_m;
  long long updates = 0;
  std::vector<std::string> notes;
};

class LeverArmFilter {
 public:
  LeverArmFilter(const RecordingMeta& meta, const ImuModel& stage1_model, const Options& options = {});
  void push(const ImuFrame& frame);
  Result finish() const;

 private:
  void process_middle();
  void update_block();
  RecordingMeta meta_;
  ImuModel model_;
  Options options_;
  table::TableKinematics table_;
  Eigen::Vector3d w_ie_n_;
  double g_mps2_, dt_nominal_s_;
  std::deque<ImuFrame> window_;  // four frames: k-2, k-1, k, k+1 around the interval (k-1, k]
  // Current block: sum of (dv - gravity dt) and of K dt, per channel.
  Eigen::Vector3d block_z_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d block_H_ = Eigen::Matrix3d::Zero();  // row j: sum of (row j of D S) K dt
  double block_T_ = 0, block_excitation_ = 0, block_horizontal_rate_radps_ = 0;
  Eigen::Matrix<double, 9, 1> x_ = Eigen::Matrix<double, 9, 1>::Zero();
  Eigen::Matrix<double, 9, 9> P_;
  long long updates_ = 0;
  long long gaps_ = 0;
  long long skipped_turning_gravity_ = 0;
};

}  // namespace imucal::lever
