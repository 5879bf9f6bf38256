#include "sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Geometry>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"

namespace imucal::sim {

using Eigen::Matrix3d;
using Eigen::Vector3d;

double NormalStream::next() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  // Uniforms in (0, 1] from the top 53 bits, so log() never sees zero.
  const double u1 = (static_cast<double>(engine_() >> 11) + 1.0) * 0x1.0p-53;
  const double u2 = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
  const double r = std::sqrt(-2.0 * std::log(u1));
  const double a = 2.0 * units::kPi * u2;
  spare_ = r * std::sin(a);
  has_spare_ = true;
  return r * std::cos(a);
}

namespace {

// splitmix64: decorrelates the per-source seeds derived from one user seed.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t source) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ULL * (source + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

template <std::size_t N>
std::array<NormalStream, N> make_streams(std::uint64_t seed, std::uint64_t first_source) {
  return [&]<std::size_t... I>(std::index_sequence<I...>) {
    return std::array<NormalStream, N>{NormalStream(mix_seed(seed, first_source + I))...};
  }(std::make_index_sequence<N>{});
}

// Ratio of the Allan-deviation maximum of a first-order Gauss-Markov process to its standard
// deviation (reached near tau = 1.89 Tc), and the IEEE definition of bias instability as the
// Allan floor divided by 0.664: together they set the process sigma that shows a given floor.
constexpr double kGmAllanPeakRatio = 0.6174;
constexpr double kFlickerFloorFactor = 0.664;
// Five unit Gauss-Markov processes with correlation times 1, 10, 100, 1000, 10000 s have an Allan
// deviation flat within +-2 % at 0.77 from 4 s to 4000 s: a flicker floor without 1/f synthesis.
constexpr double kFlickerBankAllanFloor = 0.77;
constexpr std::array<double, 5> kFlickerBankTimes_s = {1.0, 10.0, 100.0, 1000.0, 10000.0};

}  // namespace

// Everything a frame's signal depends on: the motion, the truth's deterministic terms, where the
// table stands and how the IMU sits on it, the table's own errors, the rate and the length.
struct SignalInputs {
  std::string program_json;
  std::string truth_json;  // without the noise
  Site site;
  Mount mount;
  double rate_hz = 0.0;
  std::int64_t n_frames = 0;
  std::optional<table::TableCertificate> table;
};

class MotionSignal {
 public:
  SignalInputs inputs;
  std::vector<Simulator::SignalFrame> frames;
};

namespace {

SignalInputs signal_inputs(const motion::Program& program, ImuModel truth, const SimConfig& config,
                           std::int64_t n_frames) {
  if (config.thermal)
    throw std::invalid_argument("simulate: a motion signal cannot be shared with a thermal source (its coefficients cannot be compared)");
  if (program.source_json.empty())
    throw std::invalid_argument("simulate: a motion signal needs a program with its JSON source (to compare programs)");
  truth.gyro.noise = {};
  truth.accel.noise = {};
  return {program.source_json, imu_model_to_json_text(truth), config.site, config.mount, config.rate_hz, n_frames, config.table};
}

// The first input the two signals differ in, or null when none.
const char* first_difference(const SignalInputs& a, const SignalInputs& b) {
  if (a.program_json != b.program_json) return "program";
  if (a.truth_json != b.truth_json) return "truth";
  const Site &sa = a.site, &sb = b.site;
  if (sa.latitude_deg != sb.latitude_deg || sa.longitude_deg != sb.longitude_deg || sa.height_m != sb.height_m ||
      sa.gravity_mps2 != sb.gravity_mps2 || sa.middle_axis_azimuth_deg != sb.middle_axis_azimuth_deg)
    return "site";
  if (a.mount.C_o_p != b.mount.C_o_p || a.mount.r0_p_m != b.mount.r0_p_m) return "mount";
  if (a.table != b.table) return "table";
  if (a.rate_hz != b.rate_hz) return "rate";
  if (a.n_frames != b.n_frames) return "length";
  return nullptr;
}

}  // namespace

Simulator::Simulator(const motion::Program& program, const ImuModel& truth, const SimConfig& config)
    : program_(program),
      truth_(truth),
      config_(config),
      table_(config.site.middle_axis_azimuth_deg * units::kDegToRad,
             config.table && config.table->geometry ? *config.table->geometry : table::TableGeometry{}),
      white_(make_streams<6>(config.seed, 0)),
      bias_rw_(make_streams<6>(config.seed, 12)) {
  if (!(config.rate_hz > 0.0) || !std::isfinite(config.rate_hz))
    throw std::invalid_argument("simulate: rate must be a positive number of Hz");
  if (truth.frame != "instrument")
    throw std::invalid_argument("simulate: the truth model must be in the instrument frame");
  const double lat = config.site.latitude_deg * units::kDegToRad;
  w_ie_n_ = earth::w_ie_n(lat);
  g_mps2_ = earth::site_gravity_mps2(config.site);
  dt_s_ = 1.0 / config.rate_hz;
  const double duration = config.duration_s > 0 ? config.duration_s : program.duration_s();
  n_frames_ = static_cast<std::int64_t>(std::floor(duration * config.rate_hz + 1e-9));
  breakpoints_ = program.breakpoints_s();
  D_gyro_ = misalignment_matrix(truth.gyro.misalignment_rad);
  D_accel_ = misalignment_matrix(truth.accel.misalignment_rad);
  gyro_lsb_rad_ = kGyroLsbAt1kHz_rad * 1000.0 / config.rate_hz;
  accel_lsb_mps_ = kAccelLsbAt1kHz_mps * 1000.0 / config.rate_hz;

  for (unsigned ch = 0; ch < 6; ++ch) {
    const double d = ch < 3 ? truth.gyro.delay_s[ch] : truth.accel.delay_s[ch - 3];
    auto it = std::find_if(groups_.begin(), groups_.end(), [&](const DelayGroup& g) { return g.delay_s == d; });
    if (it == groups_.end())
      groups_.push_back({d, 1u << ch});
    else
      it->mask |= 1u << ch;
  }

  for (std::size_t ch = 0; ch < 6; ++ch) {
    const bool gyro = ch < 3;
    const double white = gyro ? truth.gyro.noise.arw_rad_rts : truth.accel.noise.vrw_mps_rts;
    const double instab = gyro ? truth.gyro.noise.bias_instability_radps : truth.accel.noise.bias_instability_mps2;
    const double tc = gyro ? truth.gyro.noise.bias_corr_time_s : truth.accel.noise.bias_corr_time_s;
    const double rw = gyro ? truth.gyro.noise.rate_random_walk_radps_rts : truth.accel.noise.accel_random_walk_mps2_rts;
    white_sigma_[ch] = white * std::sqrt(dt_s_);
    rw_drive_[ch] = rw * std::sqrt(dt_s_);
    if (instab > 0) {
      std::vector<double> times;
      double sigma_gm;
      if (tc > 0) {
        times = {tc};
        sigma_gm = instab * kFlickerFloorFactor / kGmAllanPeakRatio;
      } else {
        times.assign(kFlickerBankTimes_s.begin(), kFlickerBankTimes_s.end());
        sigma_gm = instab * kFlickerFloorFactor / kFlickerBankAllanFloor;
      }
      for (std::size_t i = 0; i < times.size(); ++i) {
        GaussMarkov g{std::exp(-dt_s_ / times[i]), 0.0, 0.0, NormalStream(mix_seed(config.seed, 100 + 8 * ch + i))};
        g.drive = sigma_gm * std::sqrt(1.0 - g.phi * g.phi);
        g.state = sigma_gm * g.stream.next();  // start in the stationary distribution
        gm_[ch].push_back(std::move(g));
      }
    }
  }

  if (const auto section = turn_on_of(truth)) {
    turn_on_ = section->value;
    power_on_s_.push_back(0.0);
    for (const SegmentInfo& s : program.segments())
      if (s.kind == "power-cycle") power_on_s_.push_back(s.t0_s);
    std::sort(power_on_s_.begin(), power_on_s_.end());
    NormalStream draws(mix_seed(config.seed, 200));  // a source of its own: the other streams are unchanged
    for (std::size_t k = 0; k < power_on_s_.size(); ++k) {
      Eigen::Matrix<double, 6, 1> offset;
      for (int j = 0; j < 3; ++j) offset[j] = turn_on_->gyro_repeatability_radps[j] * draws.next();
      for (int j = 0; j < 3; ++j) offset[3 + j] = turn_on_->accel_repeatability_mps2[j] * draws.next();
      turn_on_offset_.push_back(offset);
    }
  }
}

TrueKinematics Simulator::kinematics(double t_s) const {
  // The program's angles are the table's true angles (core/table: each gimbal about its own axis).
  const table::AxisState axes = program_.evaluate(t_s, cursor_);
  const table::TableKinematics::Pose pose = table_.pose(axes);
  const table::PlatformRates& pr = pose.rates;
  const Matrix3d& C_p_n = pose.C_p_n;
  const Matrix3d& C_o_p = config_.mount.C_o_p;
  const Vector3d w_ie_p = C_p_n.transpose() * w_ie_n_;
  const Vector3d w_ip_p = pr.w_np_p + w_ie_p;
  // d/dt of the Earth-rate part, seen in the rotating platform: -w_np_p x w_ie_p.
  const Vector3d dw_ip_p = pr.dw_np_p - pr.w_np_p.cross(w_ie_p);
  const Vector3d& r0 = config_.mount.r0_p_m;
  const Vector3d v_p = pr.w_np_p.cross(r0);
  const Vector3d a_p = pr.dw_np_p.cross(r0) + pr.w_np_p.cross(v_p);
  TrueKinematics k;
  k.C_o_n = C_p_n * C_o_p;
  k.w_io_o = C_o_p.transpose() * w_ip_p;
  k.dw_io_o = C_o_p.transpose() * dw_ip_p;
  k.r_origin_n = C_p_n * r0;
  k.v_origin_n = C_p_n * v_p;
  // Specific force at the origin: relative acceleration + Coriolis + gravity (with centrifugal).
  const Vector3d f_n = C_p_n * a_p + 2.0 * w_ie_n_.cross(k.v_origin_n) + Vector3d(0.0, 0.0, g_mps2_);
  k.f_origin_o = k.C_o_n.transpose() * f_n;
  return k;
}

void Simulator::sensor_outputs(double t, unsigned mask, Vector3d& u_gyro, Vector3d& u_accel) const {
  const TrueKinematics k = kinematics(t);
  if (config_.thermal) {
    // Coefficients that move with temperature, taken at each quadrature node.
    GyroErrors g = truth_.gyro;
    AccelErrors a = truth_.accel;
    config_.thermal->coefficients(t, g, a);
    outputs(k, g, a, misalignment_matrix(a.misalignment_rad), mask, u_gyro, u_accel);
    return;
  }
  outputs(k, truth_.gyro, truth_.accel, D_accel_, mask, u_gyro, u_accel);
}

void Simulator::outputs(const TrueKinematics& k, const GyroErrors& gyro, const AccelErrors& accel,
                        const Eigen::Matrix3d& D_accel, unsigned mask, Vector3d& u_gyro, Vector3d& u_accel) {
  // With a delay per channel, most groups hold one triad's channels: the other's outputs would
  // be computed for nothing (a fifth of the simulator's time).
  u_gyro.setZero();
  u_accel.setZero();
  if (mask & 0b000111u) {
    u_gyro = apply_gyro_scale_misalignment(gyro, k.w_io_o);
    // g-sensitivity: a bias that follows the specific force at the origin, so it is integrated (and
    // delayed) with the rate part rather than added per sample with the constant bias.
    if (!gyro.g_sensitivity_radps_per_g.isZero(0.0)) u_gyro += gyro_g_sensitivity_radps(gyro, k.f_origin_o);
  }
  if (!(mask & 0b111000u)) return;
  // Each accelerometer senses the specific force at its own proof mass (seed eq. 3).
  const Vector3d& w = k.w_io_o;
  const Vector3d f_y = k.f_origin_o + w.cross(w.cross(accel.lever_arm_y_m)) + k.dw_io_o.cross(accel.lever_arm_y_m);
  const Vector3d f_z = k.f_origin_o + w.cross(w.cross(accel.lever_arm_z_m)) + k.dw_io_o.cross(accel.lever_arm_z_m);
  // S with each channel's K2, K3 at its own proof mass's force along its axis (CONVENTIONS.md).
  const Vector3d s = accel_scale_errors(accel, Vector3d(k.f_origin_o[0], f_y[1], f_z[2]));
  const Eigen::Matrix3d DS = D_accel * (Vector3d::Ones() + s).asDiagonal();
  u_accel[0] = DS.row(0).dot(k.f_origin_o);
  u_accel[1] = DS.row(1).dot(f_y);
  u_accel[2] = DS.row(2).dot(f_z);
}

void Simulator::integrate(double a, double b, unsigned mask, Vector3d& gyro, Vector3d& accel) const {
  static constexpr double kNode = 0.7745966692414834;  // sqrt(3/5)
  static constexpr std::array<double, 3> kX = {-kNode, 0.0, kNode};
  static constexpr std::array<double, 3> kW = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  gyro.setZero();
  accel.setZero();
  // Split [a, b] where the motion is not smooth, so each part is integrated to machine precision.
  auto it = std::upper_bound(breakpoints_.begin(), breakpoints_.end(), a);
  double lo = a;
  while (lo < b) {
    double hi = b;
    if (it != breakpoints_.end() && *it < b) hi = *it++;
    const double half = 0.5 * (hi - lo), mid = 0.5 * (hi + lo);
    for (std::size_t n = 0; n < 3; ++n) {
      Vector3d ug, ua;
      sensor_outputs(mid + half * kX[n], mask, ug, ua);
      gyro += (kW[n] * half) * ug;
      accel += (kW[n] * half) * ua;
    }
    lo = hi;
  }
  for (int j = 0; j < 3; ++j) {
    if (!(mask & (1u << j))) gyro[j] = 0.0;
    if (!(mask & (1u << (3 + j)))) accel[j] = 0.0;
  }
}

bool Simulator::next(ImuFrame& out) {
  if (k_ >= n_frames_) return false;
  const double t0 = static_cast<double>(k_) * dt_s_;
  const double t1 = static_cast<double>(k_ + 1) * dt_s_;
  while (next_temp_t_s_ <= t1) {
    TempSample ts;
    if (config_.thermal) {
      if (config_.thermal->temperatures(next_temp_t_s_, ts)) {
        ts.t_ns = std::llround(next_temp_t_s_ * units::kNsPerS);
        temps_.push_back(ts);
      }
      next_temp_t_s_ += 1.0 / config_.temp_rate_hz;
      continue;
    }
    ts.t_ns = std::llround(next_temp_t_s_ * units::kNsPerS);
    ts.gyro_C.setConstant(config_.temperature_C);
    ts.accel_C.setConstant(config_.temperature_C);
    ts.chamber_C = config_.temperature_C;
    ts.chamber_setpoint_C = config_.temperature_C;
    temps_.push_back(ts);
    next_temp_t_s_ += 1.0 / config_.temp_rate_hz;
  }
  const SignalFrame signal = signal_ ? signal_->frames[static_cast<std::size_t>(k_)] : signal_of(k_);
  Vector3d dtheta = signal.dtheta_rad, dv = signal.dv_mps;
  if (config_.thermal) {
    // Biases that move with temperature: their value mid-sample (they change over hours).
    GyroErrors g = truth_.gyro;
    AccelErrors a = truth_.accel;
    config_.thermal->coefficients(0.5 * (t0 + t1), g, a);
    dtheta += g.bias_radps * dt_s_;
    dv += a.bias_mps2 * dt_s_;
  } else {
    dtheta += truth_.gyro.bias_radps * dt_s_;
    dv += truth_.accel.bias_mps2 * dt_s_;
  }
  if (turn_on_) {
    // The last power-on's offsets and its warm-up transient, mid-sample (time constants are minutes).
    const double t_mid = 0.5 * (t0 + t1);
    while (power_on_cursor_ + 1 < power_on_s_.size() && power_on_s_[power_on_cursor_ + 1] <= t_mid) ++power_on_cursor_;
    while (power_on_cursor_ > 0 && power_on_s_[power_on_cursor_] > t_mid) --power_on_cursor_;
    const double since_on = t_mid - power_on_s_[power_on_cursor_];
    const Eigen::Matrix<double, 6, 1>& offset = turn_on_offset_[power_on_cursor_];
    dtheta += (offset.head<3>() + turn_on_->gyro_transient_radps(since_on)) * dt_s_;
    dv += (offset.tail<3>() + turn_on_->accel_transient_mps2(since_on)) * dt_s_;
  }
  for (std::size_t ch = 0; ch < 6; ++ch) {
    const auto i = static_cast<Eigen::Index>(ch);
    double noise = 0.0;
    if (white_sigma_[ch] > 0) noise += white_sigma_[ch] * white_[ch].next();
    for (GaussMarkov& g : gm_[ch]) {
      g.state = g.phi * g.state + g.drive * g.stream.next();
      noise += g.state * dt_s_;
    }
    if (rw_drive_[ch] > 0) rw_state_[i] += rw_drive_[ch] * bias_rw_[ch].next();
    noise += rw_state_[i] * dt_s_;  // also a walk continued from an earlier run without new drive
    if (ch < 3)
      dtheta[i] += noise;
    else
      dv[i - 3] += noise;
  }
  // Quantise to integer counts as a real IMU does, carrying the remainder to the next sample.
  for (int j = 0; j < 3; ++j) {
    const double tg = dtheta[j] + gyro_remainder_[j];
    const double cg = std::nearbyint(tg / gyro_lsb_rad_);
    out.dtheta_rad[j] = cg * gyro_lsb_rad_;
    gyro_remainder_[j] = tg - out.dtheta_rad[j];
    const double ta = dv[j] + accel_remainder_[j];
    const double ca = std::nearbyint(ta / accel_lsb_mps_);
    out.dv_mps[j] = ca * accel_lsb_mps_;
    accel_remainder_[j] = ta - out.dv_mps[j];
  }
  out.t_ns = std::llround(static_cast<double>(k_ + 1) * units::kNsPerS / config_.rate_hz);
  out.table_deg = signal.table_deg;
  ++k_;
  return true;
}

Simulator::SignalFrame Simulator::signal_of(std::int64_t k) const {
  const double t0 = static_cast<double>(k) * dt_s_;
  const double t1 = static_cast<double>(k + 1) * dt_s_;
  SignalFrame s{Vector3d::Zero(), Vector3d::Zero(), Vector3d::Zero()};
  for (const DelayGroup& g : groups_) {
    Vector3d ig, ia;
    // Channel output at t reflects its input at t - delay.
    integrate(t0 - g.delay_s, t1 - g.delay_s, g.mask, ig, ia);
    s.dtheta_rad += ig;
    s.dv_mps += ia;
  }
  // What the encoders read at the true angles.
  s.table_deg = table_.encoder_angles_rad(program_.evaluate(t1, cursor_).angle_rad) * units::kRadToDeg;
  return s;
}

std::shared_ptr<const MotionSignal> Simulator::motion_signal() const {
  auto signal = std::make_shared<MotionSignal>();
  signal->inputs = signal_inputs(program_, truth_, config_, n_frames_);
  signal->frames.reserve(static_cast<std::size_t>(n_frames_));
  for (std::int64_t k = 0; k < n_frames_; ++k) signal->frames.push_back(signal_of(k));
  return signal;
}

void Simulator::use_motion_signal(std::shared_ptr<const MotionSignal> signal) {
  if (!signal) throw std::invalid_argument("simulate: no motion signal given");
  if (const char* differs = first_difference(signal->inputs, signal_inputs(program_, truth_, config_, n_frames_)))
    throw std::invalid_argument(std::string("simulate: the motion signal was computed for another ") + differs);
  signal_ = std::move(signal);
}

Eigen::Matrix<double, 6, 1> Simulator::stochastic_bias() const {
  Eigen::Matrix<double, 6, 1> b = rw_state_;
  for (std::size_t ch = 0; ch < 6; ++ch)
    for (const GaussMarkov& g : gm_[ch]) b[static_cast<Eigen::Index>(ch)] += g.state;
  return b;
}

void Simulator::continue_stochastic_bias(const Eigen::Matrix<double, 6, 1>& bias) {
  // The Gauss-Markov parts forget their past within their correlation times; the random walk
  // carries the whole offset.
  rw_state_ = bias;
  for (auto& channel : gm_)
    for (GaussMarkov& g : channel) g.state = 0.0;
}

std::vector<TempSample> Simulator::take_temps() {
  std::vector<TempSample> out;
  out.swap(temps_);
  return out;
}

RecordingMeta Simulator::meta() const {
  RecordingMeta m;
  m.site = config_.site;
  m.imu_serial = "SIM-" + std::to_string(config_.seed);
  m.rate_hz = config_.rate_hz;
  m.mount = config_.mount;
  const double end_s = static_cast<double>(n_frames_) * dt_s_;
  for (SegmentInfo s : program_.segments()) {
    if (s.t0_s >= end_s) break;
    s.t1_s = std::min(s.t1_s, end_s);
    m.segments.push_back(s);
  }
  m.gyro_lsb_rad = gyro_lsb_rad_;
  m.accel_lsb_mps = accel_lsb_mps_;
  m.program_json = program_.source_json;
  m.truth_json = imu_model_to_json_text(truth_);
  m.table = config_.table;
  return m;
}

}  // namespace imucal::sim
