// The simulated temperatures of a chamber run and the truth coefficients they drive.
//  - Chamber air follows the profile's set point (first-order lag, limited heating/cooling rate
//    and reach), the IMU case follows the air, each accelerometer and each of the eight sensors on
//    every FOG coil follows the case with its own lag; a coil's temperature is the mean of its
//    eight sensors (seed ch. 3). With the IMU's own thermal stabilisation the sensors follow a
//    heated plate that lets through only a small fraction of the case's swing (0.4 C over 20 C).
//  - Truth coefficients: the truth model's constants plus its "thermal" section evaluated at the
//    true sensor temperatures and rates, plus the FOG bias oscillation of sim_oscillation.
//  - Logged temperatures: quantised, with injected faults (stuck, jump, missing) that leave the
//    truth alone, so the checks of stage 2 can be tested.
// Temperatures are integrated once on a 1 s grid (exact first-order lag steps) and interpolated
// by cubic Hermite, so the state is a pure, smooth function of time for the simulator's quadrature.
#pragma once

#include <array>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "drivers/sim/simulator.hpp"
#include "estimators/thermal.hpp"
#include "motion_programs/chamber.hpp"

namespace imucal::sim {

struct Stabilisation {
  bool enabled = false;
  double setpoint_C = 35.0;  // a heater holds the plate at the warm end of the working range
  double leak = 0.02;        // share of the case's deviation from the set point reaching the plate
  double tau_s = 600.0;      // the plate's response
};

// A fault of one logged channel: gx gy gz (coil means), gx1 .. gz8 (one coil sensor), ax ay az,
// chamber; kind stuck (frozen at its value at t0), jump (offset by jump_C), missing (no samples
// at all from the logger: channel "all").
struct SensorFault {
  std::string channel;
  std::string kind;
  double t0_s = 0.0;
  double t1_s = std::numeric_limits<double>::infinity();
  double jump_C = 0.0;
};

struct ThermalConfig {
  motion::ThermalLags lags;
  Eigen::Vector3d accel_tau_s = Eigen::Vector3d(480.0, 540.0, 600.0);  // behind the case (or plate)
  Eigen::Vector3d coil_tau_s = Eigen::Vector3d(510.0, 570.0, 630.0);
  double coil_sensor_spread = 0.3;  // the eight sensors' lags: the coil's +-30 %
  double chamber_min_C = -70.0, chamber_max_C = 180.0;  // what the chamber can reach
  double step_s = 1.0;
  double lsb_C = 0.001;  // resolution of one logged sensor (a 24-bit ADC on a platinum sensor)
  Stabilisation stabilisation;
  std::vector<SensorFault> faults;
};

class ThermalModel final : public ThermalSource {
 public:
  // The truth's "thermal" section (if any) gives the coefficients' dependence.
  ThermalModel(const motion::ChamberProfile& profile, const ImuModel& truth, const ThermalConfig& config,
               double duration_s);

  bool temperatures(double t_s, TempSample& out) const override;
  void coefficients(double t_s, GyroErrors& gyro, AccelErrors& accel) const override;

  struct State {
    double setpoint_C = 0, air_C = 0, case_C = 0, plate_C = 0;
    thermal::ChannelTemps sensors;  // coil means x y z, accelerometers x y z; rates in C/min
    std::array<std::array<double, 8>, 3> coil_sensors_C{};
  };
  State state(double t_s) const;  // the true state (no faults, no quantisation)

 private:
  thermal::ChannelTemps channels(double t_s) const;
  double grid_value(std::size_t column, double t_s) const;

  thermal::ThermalSection section_;
  bool has_section_ = false;
  motion::ChamberProfile profile_;
  ThermalConfig config_;
  // Grid columns: set point, air, case, plate, 3 accel, 24 coil sensors; then the six channels'
  // derivatives (C/s) for the Hermite interpolation.
  static constexpr std::size_t kSet = 0, kAir = 1, kCase = 2, kPlate = 3, kAccel = 4, kCoil = 7, kColumns = 31;
  std::vector<std::array<double, kColumns>> grid_;
  std::vector<std::array<double, thermal::kChannels>> slope_;
  std::vector<std::array<double, thermal::kChannels>> value6_;
};

}  // namespace imucal::sim
