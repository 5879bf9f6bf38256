// The simulated temperatures of a chamber run and the truth coefficients they drive.
//  - Chamber air follows the profile's set point (first-order lag, limited heating/cooling rate
//    and reach), the IMU case follows the air, each accelerometer and each of the eight sensors on
//    every FOG coil follows the case with its own lag; a coil's temperature is the mean of its
//    eight sensors (seed ch. 3). With the IMU's own thermal stabilisation the sensors sit on a
//    plate held by an on/off heater (below): the chamber's 20 C swing reaches them only as a
//    0.4 C range, but the heater's control cycle keeps them heating and cooling at a few
//    hundredths of a degree per minute, and the FOG bias follows dT/dt.
//  - Truth coefficients: the truth model's constants plus its "thermal" section evaluated at the
//    true sensor temperatures and rates, plus the FOG bias oscillation of sim_oscillation.
//  - Logged temperatures: quantised, with injected faults (stuck, jump, missing) that leave the
//    truth alone, so the checks of stage 2 can be tested.
// Temperatures are integrated once on a 1 s grid (exact first-order lag steps) and interpolated
// by cubic Hermite, so the state is a pure, smooth function of time for the simulator's quadrature.
#pragma once

#include <array>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/imu_model.hpp"
#include "sim/simulator.hpp"
#include "estimators/thermal.hpp"
#include "motion_programs/chamber.hpp"

namespace imucal::sim {

// The IMU's thermal stabilisation: a plate carrying the sensors, heated through a heater block
// switched on and off by a relay with hysteresis on the plate's control sensor.
//   heater block: dTh/dt = ((on ? Tp + excess_C : Tp) - Th) / heater_tau_s
//   plate:        dTp/dt = (Th - Tp) / plate_tau_s + (Tcase - Tp) / loss_tau_s
// The heater's lag makes the relay overshoot, so the plate cycles around the set point with a
// period of about 16..30 min that lengthens as the case warms (the plate then cools more slowly);
// the sensors, lagging the plate, stay within about 0.4 C over a 15..35 C chamber run yet heat
// and cool at up to 0.03..0.04 C/min. The set point is above the warmest case, as a heater needs.
// The IMU is switched on warm_up_s before the run, so the run starts inside the control cycle.
struct Stabilisation {
  bool enabled = false;
  double setpoint_C = 55.0;
  double hysteresis_C = 0.05;  // the relay switches at setpoint -+ hysteresis
  double excess_C = 30.0;      // the heater block's rise over the plate at full power
  double heater_tau_s = 600.0;
  double plate_tau_s = 300.0;  // heater block to plate
  double loss_tau_s = 8000.0;  // plate to case
  double warm_up_s = 4 * 3600.0;
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
  // The chamber's set point over time, in seconds from the run's start.
  using Setpoint = std::function<double(double t_s)>;
  // The truth's "thermal" section (if any) gives the coefficients' dependence.
  ThermalModel(const motion::ChamberProfile& profile, const ImuModel& truth, const ThermalConfig& config,
               double duration_s);
  // The same for a set point given as a function.
  ThermalModel(Setpoint setpoint_C, const ImuModel& truth, const ThermalConfig& config, double duration_s);

  bool temperatures(double t_s, TempSample& out) const override;
  void coefficients(double t_s, GyroErrors& gyro, AccelErrors& accel) const override;

  struct State {
    double setpoint_C = 0, air_C = 0, case_C = 0, plate_C = 0, heater_C = 0;
    thermal::ChannelTemps sensors;  // coil means x y z, accelerometers x y z; rates in C/min
    std::array<std::array<double, 8>, 3> coil_sensors_C{};
  };
  State state(double t_s) const;  // the true state (no faults, no quantisation)

 private:
  thermal::ChannelTemps channels(double t_s) const;
  double grid_value(std::size_t column, double t_s) const;

  thermal::ThermalSection section_;
  bool has_section_ = false;
  Setpoint setpoint_C_;
  ThermalConfig config_;
  // Grid columns: set point, air, case, plate, heater block, 3 accel, 24 coil sensors; then the
  // six channels' derivatives (C/s) for the Hermite interpolation.
  static constexpr std::size_t kSet = 0, kAir = 1, kCase = 2, kPlate = 3, kHeater = 4, kAccel = 5, kCoil = 8,
                               kColumns = 32;
  std::vector<std::array<double, kColumns>> grid_;
  std::vector<std::array<double, thermal::kChannels>> slope_;
  std::vector<std::array<double, thermal::kChannels>> value6_;
};

}  // namespace imucal::sim
