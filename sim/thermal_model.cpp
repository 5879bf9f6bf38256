#include "sim/thermal_model.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "core/hermite.hpp"
#include "core/units.hpp"

namespace imucal::sim {

namespace {

// Relative lag of coil sensor s (0..7) around the coil's own: spread evenly over +-1.
double sensor_factor(int s) { return -1.0 + 2.0 * s / 7.0; }

int channel_index(const std::string& name, int& sensor) {
  sensor = -1;
  static const char* const names[6] = {"gx", "gy", "gz", "ax", "ay", "az"};
  for (int ch = 0; ch < 6; ++ch) {
    if (name == names[ch]) return ch;
    if (ch < 3 && name.size() == 3 && name.compare(0, 2, names[ch]) == 0 && name[2] >= '1' && name[2] <= '8') {
      sensor = name[2] - '1';
      return ch;
    }
  }
  if (name == "chamber") return 6;
  return -1;
}

}  // namespace

ThermalModel::ThermalModel(const motion::ChamberProfile& profile, const ImuModel& truth, const ThermalConfig& config,
                           double duration_s)
    : ThermalModel([profile](double t_s) { return profile.setpoint_C(t_s); }, truth, config, duration_s) {}

ThermalModel::ThermalModel(Setpoint setpoint_C, const ImuModel& truth, const ThermalConfig& config, double duration_s)
    : setpoint_C_(std::move(setpoint_C)), config_(config) {
  if (auto s = thermal::thermal_of(truth)) {
    section_ = *s;
    has_section_ = true;
  }
  for (const SensorFault& f : config_.faults) {
    int sensor;
    if (channel_index(f.channel, sensor) < 0 && !(f.kind == "missing" && f.channel == "all"))
      throw std::invalid_argument("thermal fault: unknown channel '" + f.channel +
                                  "' (gx gy gz, gx1..gz8, ax ay az, chamber; all for missing)");
    if (f.kind != "stuck" && f.kind != "jump" && f.kind != "missing")
      throw std::invalid_argument("thermal fault: unknown kind '" + f.kind + "' (stuck, jump, missing)");
  }
  const double h = config_.step_s;
  if (!(h > 0)) throw std::invalid_argument("thermal model: step_s must be positive");
  const auto n = static_cast<std::size_t>(std::ceil(std::max(duration_s, 0.0) / h)) + 2;
  grid_.resize(n);
  slope_.resize(n);
  value6_.resize(n);
  const Stabilisation& stab = config_.stabilisation;
  if (stab.enabled && !(stab.hysteresis_C >= 0 && stab.excess_C > 0 && stab.heater_tau_s > 0 && stab.plate_tau_s > 0 &&
                        stab.loss_tau_s > 0 && stab.warm_up_s >= 0))
    throw std::invalid_argument(
        "thermal model: stabilisation needs hysteresis_C >= 0, warm_up_s >= 0 and positive excess and time constants");
  const double max_step = config_.lags.chamber_max_rate_C_per_min / 60.0 * h;
  bool heater_on = true;
  // One step of h from y (at t0) to x (at t1 = t0 + h): chamber air, case, stabiliser, sensors.
  auto step = [&](const std::array<double, kColumns>& y, std::array<double, kColumns>& x, double t0, double t1) {
    x[kSet] = setpoint_C_(t1);
    const double air = motion::first_order_lag_step(y[kAir], setpoint_C_(t0), x[kSet], h,
                                                    config_.lags.chamber_tau_s);
    x[kAir] = std::clamp(std::clamp(air, y[kAir] - max_step, y[kAir] + max_step), config_.chamber_min_C,
                         config_.chamber_max_C);
    x[kCase] = motion::first_order_lag_step(y[kCase], y[kAir], x[kAir], h, config_.lags.case_tau_s);
    if (stab.enabled) {
      // The relay decides on the plate as it was; the heater block and the plate then advance by
      // explicit Euler on quarter-second sub-steps (the time constants are minutes).
      if (y[kPlate] < stab.setpoint_C - stab.hysteresis_C) heater_on = true;
      if (y[kPlate] > stab.setpoint_C + stab.hysteresis_C) heater_on = false;
      double heater = y[kHeater], plate = y[kPlate];
      constexpr int kSub = 4;
      for (int q = 0; q < kSub; ++q) {
        const double u = (q + 0.5) / kSub;
        const double case_C = (1 - u) * y[kCase] + u * x[kCase];
        const double d_heater = ((heater_on ? plate + stab.excess_C : plate) - heater) / stab.heater_tau_s;
        const double d_plate = (heater - plate) / stab.plate_tau_s + (case_C - plate) / stab.loss_tau_s;
        heater += d_heater * h / kSub;
        plate += d_plate * h / kSub;
      }
      x[kHeater] = heater;
      x[kPlate] = plate;
    } else {
      x[kHeater] = x[kPlate] = x[kCase];
    }
    // The sensors follow the plate (the case itself without stabilisation).
    const double src0 = y[kPlate], src1 = x[kPlate];
    for (int j = 0; j < 3; ++j) {
      const std::size_t a = kAccel + static_cast<std::size_t>(j);
      x[a] = motion::first_order_lag_step(y[a], src0, src1, h, config_.accel_tau_s[j]);
      for (int s = 0; s < 8; ++s) {
        const std::size_t c = kCoil + static_cast<std::size_t>(8 * j + s);
        const double tau = config_.coil_tau_s[j] * (1.0 + config_.coil_sensor_spread * sensor_factor(s));
        x[c] = motion::first_order_lag_step(y[c], src0, src1, h, tau);
      }
    }
  };
  // Start in equilibrium at the first set point, as after a night in the chamber; a stabilised
  // IMU switched on warm_up_s before, at the plate's set point with the heater holding it.
  std::array<double, kColumns> x{};
  x[kSet] = x[kAir] = x[kCase] = setpoint_C_(0.0);
  x[kPlate] = stab.enabled ? stab.setpoint_C : x[kCase];
  x[kHeater] = stab.enabled ? x[kPlate] + (x[kPlate] - x[kCase]) * stab.plate_tau_s / stab.loss_tau_s : x[kCase];
  for (std::size_t c = kAccel; c < kColumns; ++c) x[c] = x[kPlate];
  if (stab.enabled)
    for (double t = 0; t < stab.warm_up_s; t += h) {
      const std::array<double, kColumns> y = x;
      step(y, x, 0.0, 0.0);  // the chamber holds the first set point
    }
  auto derivatives = [&](const std::array<double, kColumns>& y, std::size_t k) {
    const double source = y[kPlate];
    for (int j = 0; j < 3; ++j) {
      value6_[k][static_cast<std::size_t>(3 + j)] = y[kAccel + static_cast<std::size_t>(j)];
      slope_[k][static_cast<std::size_t>(3 + j)] = (source - y[kAccel + static_cast<std::size_t>(j)]) / config_.accel_tau_s[j];
      double mean = 0, dmean = 0;
      for (int s = 0; s < 8; ++s) {
        const double tau = config_.coil_tau_s[j] * (1.0 + config_.coil_sensor_spread * sensor_factor(s));
        const double v = y[kCoil + static_cast<std::size_t>(8 * j + s)];
        mean += v / 8.0;
        dmean += (source - v) / tau / 8.0;
      }
      value6_[k][static_cast<std::size_t>(j)] = mean;
      slope_[k][static_cast<std::size_t>(j)] = dmean;
    }
  };
  grid_[0] = x;
  derivatives(x, 0);
  for (std::size_t k = 1; k < n; ++k) {
    step(grid_[k - 1], grid_[k], static_cast<double>(k - 1) * h, static_cast<double>(k) * h);
    derivatives(grid_[k], k);
  }
}

thermal::ChannelTemps ThermalModel::channels(double t) const {
  // Cubic Hermite between grid points from the values and the ODE's own derivatives.
  const double h = config_.step_s;
  const double u = std::clamp(t / h, 0.0, static_cast<double>(grid_.size() - 2));
  const auto k = std::min(static_cast<std::size_t>(u), grid_.size() - 2);
  const double s = u - static_cast<double>(k);
  thermal::ChannelTemps out;
  for (std::size_t c = 0; c < thermal::kChannels; ++c) {
    const double y0 = value6_[k][c], y1 = value6_[k + 1][c], m0 = slope_[k][c], m1 = slope_[k + 1][c];
    const auto i = static_cast<Eigen::Index>(c);
    out.T_C[i] = cubic_hermite(y0, m0, y1, m1, h, s);
    out.rate_C_per_min[i] = cubic_hermite_rate(y0, m0, y1, m1, h, s) * 60.0;
  }
  return out;
}

double ThermalModel::grid_value(std::size_t column, double t) const {
  const double h = config_.step_s;
  const double u = std::clamp(t / h, 0.0, static_cast<double>(grid_.size() - 2));
  const auto k = std::min(static_cast<std::size_t>(u), grid_.size() - 2);
  const double s = u - static_cast<double>(k);
  return (1 - s) * grid_[k][column] + s * grid_[k + 1][column];
}

ThermalModel::State ThermalModel::state(double t) const {
  State st;
  st.setpoint_C = setpoint_C_(t);
  st.air_C = grid_value(kAir, t);
  st.case_C = grid_value(kCase, t);
  st.plate_C = grid_value(kPlate, t);
  st.heater_C = grid_value(kHeater, t);
  st.sensors = channels(t);
  for (std::size_t j = 0; j < 3; ++j)
    for (std::size_t s = 0; s < 8; ++s) st.coil_sensors_C[j][s] = grid_value(kCoil + 8 * j + s, t);
  return st;
}

bool ThermalModel::temperatures(double t, TempSample& out) const {
  for (const SensorFault& f : config_.faults)
    if (f.kind == "missing" && t >= f.t0_s && t <= f.t1_s) return false;
  // Faults act on what the logger reads, at the reading's own instant (stuck: the value at t0).
  auto read = [&](int ch, int sensor, double at) {
    double v;
    if (ch == 6) v = grid_value(kAir, at);
    else if (ch >= 3) v = grid_value(kAccel + static_cast<std::size_t>(ch - 3), at);
    else v = grid_value(kCoil + static_cast<std::size_t>(8 * ch + sensor), at);
    return v;
  };
  auto faulty = [&](int ch, int sensor) {
    double at = t, offset = 0;
    for (const SensorFault& f : config_.faults) {
      int fs;
      const int fc = channel_index(f.channel, fs);
      const bool hits = fc == ch && (fs < 0 || fs == sensor);
      if (!hits || t < f.t0_s || t > f.t1_s) continue;
      if (f.kind == "stuck") at = f.t0_s;
      if (f.kind == "jump") offset += f.jump_C;
    }
    return read(ch, sensor, at) + offset;
  };
  auto quantise = [&](double v) { return config_.lsb_C > 0 ? std::round(v / config_.lsb_C) * config_.lsb_C : v; };
  auto& coils = out.coil_sensors_C.emplace();
  for (int j = 0; j < 3; ++j) {
    // The coil channel is the mean of its eight logged sensors (finer than one sensor's step).
    double mean = 0;
    for (int s = 0; s < 8; ++s) {
      const double sensor_C = quantise(faulty(j, s));
      coils[static_cast<std::size_t>(j)][static_cast<std::size_t>(s)] = sensor_C;
      mean += sensor_C / 8.0;
    }
    out.gyro_C[j] = mean;
    out.accel_C[j] = quantise(faulty(3 + j, -1));
  }
  out.chamber_C = quantise(faulty(6, -1));
  out.chamber_setpoint_C = setpoint_C_(t);
  return true;
}

void ThermalModel::coefficients(double t, GyroErrors& g, AccelErrors& a) const {
  if (!has_section_) return;
  const thermal::ChannelTemps c = channels(t);
  thermal::apply_thermal(section_, c, g, a);
  if (section_.sim_oscillation)
    for (int j = 0; j < 3; ++j)
      g.bias_radps[j] += thermal::oscillation_dph(*section_.sim_oscillation, j, t, c.rate_C_per_min[j]) *
                         units::kDphToRadps;
}

}  // namespace imucal::sim
