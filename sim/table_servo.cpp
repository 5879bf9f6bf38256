#include "sim/table_servo.hpp"

#include <algorithm>
#include <cmath>

#include "core/units.hpp"

namespace imucal::sim {

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

using motion::AxisFunc;
using units::kDegToRad;
using units::kPi;
using units::kRadToDeg;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kFarFuture_s = 1e9;  // "forever" for open-ended pieces
// Old pieces are kept this long for program_from() (the IMU restarts its physics a little in the
// past), then pruned.
constexpr double kHistory_s = 30.0;

double sgn(double x) { return x > 0 ? 1.0 : (x < 0 ? -1.0 : 0.0); }

}  // namespace

TableServo::TableServo(const ServoConfig& config) : config_(config) {
  for (int a = 0; a < 3; ++a) {
    Axis& ax = axes_[static_cast<std::size_t>(a)];
    ax.segs.push_back({0.0, AxisFunc::constant(config.start_deg[static_cast<std::size_t>(a)] * kDegToRad)});
  }
}

AxisLimitSetting& TableServo::lim(int axis, TableMode mode) {
  return config_.limits[static_cast<std::size_t>(axis)][static_cast<std::size_t>(mode)];
}

const AxisLimitSetting& TableServo::limits(int axis, TableMode mode) const {
  return config_.limits[static_cast<std::size_t>(axis)][static_cast<std::size_t>(mode)];
}

const TableServo::Seg& TableServo::active(const Axis& a, double t) const {
  auto it = std::upper_bound(a.segs.begin(), a.segs.end(), t, [](double x, const Seg& s) { return x < s.t0; });
  if (it == a.segs.begin()) return a.segs.front();
  return *(it - 1);
}

void TableServo::eval(const Axis& a, double t, double& angle, double& rate, double& accel) const {
  const Seg& s = active(a, t);
  s.f.eval(std::max(0.0, t - s.t0), angle, rate, accel);
}

void TableServo::replace_from(int axis, double t, std::vector<Seg> segs) {
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  while (a.segs.size() > 1 && a.segs.back().t0 >= t) a.segs.pop_back();
  if (a.segs.size() == 1 && a.segs.back().t0 >= t) a.segs.clear();
  for (Seg& s : segs)
    if (a.segs.empty() || s.t0 > a.segs.back().t0) a.segs.push_back(s);
    else a.segs.back() = s;  // same start time: the later piece wins
  // Prune history no physics restart will ask for.
  while (a.segs.size() > 2 && a.segs[1].t0 < now_ - kHistory_s) a.segs.erase(a.segs.begin());
  ++version_;
  update_limit_event(axis, t);
}

std::pair<double, double> TableServo::graceful_stop(int axis, double t, double accel) {
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  const Seg& s = active(a, t);
  if (s.f.kind == AxisFunc::Kind::Sine) {
    // Next turning point (zero rate): psi = pi/2 + k pi.
    const double psi = s.f.omega * (t - s.t0) + s.f.phase;
    const double k = std::ceil((psi - kPi / 2) / kPi);
    const double t_z = s.t0 + (kPi / 2 + k * kPi - s.f.phase) / s.f.omega;
    double angle, rate, acc;
    s.f.eval(t_z - s.t0, angle, rate, acc);
    replace_from(axis, t_z, {{t_z, AxisFunc::constant(angle)}});
    return {t_z, angle};
  }
  double angle, rate, acc;
  eval(a, t, angle, rate, acc);
  if (std::fabs(rate) * kRadToDeg < config_.moving_threshold_dps) {
    replace_from(axis, t, {{t, AxisFunc::constant(angle)}});
    return {t, angle};
  }
  const double T = std::fabs(rate) / accel;
  const double alpha = -sgn(rate) * accel;
  const double rest = angle + rate * T + 0.5 * alpha * T * T;
  replace_from(axis, t, {{t, AxisFunc::quadratic(angle, rate, alpha)}, {t + T, AxisFunc::constant(rest)}});
  return {t + T, rest};
}

void TableServo::emergency_stop(int axis, double t) {
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  double angle, rate, acc;
  eval(a, t, angle, rate, acc);
  const double accel = limits(axis, TableMode::off).accel_dps2 * kDegToRad;
  if (std::fabs(rate) * kRadToDeg < config_.moving_threshold_dps) {
    replace_from(axis, t, {{t, AxisFunc::constant(angle)}});
  } else {
    const double T = std::fabs(rate) / accel;
    const double alpha = -sgn(rate) * accel;
    replace_from(axis, t, {{t, AxisFunc::quadratic(angle, rate, alpha)}, {t + T, AxisFunc::constant(angle + rate * T + 0.5 * alpha * T * T)}});
  }
  a.mode = TableMode::off;
  update_limit_event(axis, t);
}

void TableServo::update_limit_event(int axis, double t) {
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  a.limit_event_s = kInf;
  if (a.at_limit) return;  // latched: the braking overshoot is expected beyond the limit
  const AxisLimitSetting& L = limits(axis, a.mode);
  const double lo = L.min_deg * kDegToRad, hi = L.max_deg * kDegToRad;
  auto first = std::upper_bound(a.segs.begin(), a.segs.end(), t, [](double x, const Seg& s) { return x < s.t0; });
  if (first != a.segs.begin()) --first;
  for (auto it = first; it != a.segs.end(); ++it) {
    const double seg_end = (it + 1 == a.segs.end()) ? kInf : (it + 1)->t0;
    const double ta = std::max(t, it->t0);
    if (ta >= seg_end) continue;
    const AxisFunc& f = it->f;
    if (f.kind != AxisFunc::Kind::Quadratic) continue;  // constants do not move; sines are checked on demand
    const double tau_a = ta - it->t0, tau_b = seg_end - it->t0;
    double best = kInf;
    for (const double L_rad : {hi, lo}) {
      const double out = L_rad == hi ? 1.0 : -1.0;  // outward direction
      double angle, rate, acc;
      f.eval(tau_a, angle, rate, acc);
      if (out * (angle - L_rad) >= 0.0 && (out * rate > 0.0 || (rate == 0.0 && out * f.alpha > 0.0))) {
        best = std::min(best, tau_a);
        continue;
      }
      // Roots of theta0 + w0 tau + alpha tau^2 / 2 = L crossing outward.
      std::vector<double> roots;
      if (f.alpha == 0.0) {
        if (f.omega0 != 0.0) roots.push_back((L_rad - f.theta0) / f.omega0);
      } else {
        const double disc = f.omega0 * f.omega0 - 2.0 * f.alpha * (f.theta0 - L_rad);
        if (disc >= 0.0) {
          const double sq = std::sqrt(disc);
          roots.push_back((-f.omega0 - sq) / f.alpha);
          roots.push_back((-f.omega0 + sq) / f.alpha);
        }
      }
      for (double r : roots) {
        if (!(r >= tau_a && r < tau_b)) continue;
        const double rate_r = f.omega0 + f.alpha * r;
        if (out * rate_r > 0.0) best = std::min(best, r);
      }
    }
    if (best < kInf) {
      a.limit_event_s = it->t0 + best;
      return;
    }
  }
}

void TableServo::advance(double t_s) {
  if (t_s < now_) t_s = now_;
  for (;;) {
    double te = kInf;
    int which = -1;
    bool is_limit = false;
    for (int i = 0; i < 3; ++i) {
      const Axis& a = axes_[static_cast<std::size_t>(i)];
      if (a.limit_event_s < te) {
        te = a.limit_event_s;
        which = i;
        is_limit = true;
      }
      if (watchdog_period_s_ > 0.0 && a.mode != TableMode::off) {
        const double w = a.last_feed_s + watchdog_period_s_;
        if (w < te) {
          te = w;
          which = i;
          is_limit = false;
        }
      }
    }
    if (which < 0 || te > t_s) break;
    now_ = std::max(now_, te);
    Axis& a = axes_[static_cast<std::size_t>(which)];
    if (is_limit) a.at_limit = true;
    else a.watchdog = true;
    emergency_stop(which, te);
  }
  now_ = t_s;
}

ServoResult TableServo::bad_axis(int axis) const {
  if (axis < 0 || axis > 2) return {dialect::Refusal::argument, "axis must be 1, 2 or 3"};
  return {};
}

ServoResult TableServo::check_motion_allowed(int axis, TableMode needed) const {
  if (auto r = bad_axis(axis); !r.ok()) return r;
  const Axis& a = axes_[static_cast<std::size_t>(axis)];
  if (interlock_ != InterlockState::closed) return {dialect::Refusal::interlock_open, "interlock open"};
  if (a.at_limit) return {dialect::Refusal::axis_fault, "axis " + std::to_string(axis + 1) + " hit a position limit: reset required"};
  if (a.watchdog) return {dialect::Refusal::watchdog_expired, "axis " + std::to_string(axis + 1) + " dropped to off by the watchdog: set its mode"};
  if (a.mode != needed)
    return {dialect::Refusal::wrong_mode, "axis " + std::to_string(axis + 1) + " is in " + to_string(a.mode) + " mode, not " + to_string(needed)};
  return {};
}

ServoResult TableServo::interlock_close(double t_s) {
  advance(t_s);
  interlock_ = InterlockState::closed;
  return {};
}

ServoResult TableServo::interlock_open(double t_s) {
  advance(t_s);
  interlock_ = InterlockState::open;
  for (int i = 0; i < 3; ++i) emergency_stop(i, now_);
  return {};
}

ServoResult TableServo::interlock_reset(double t_s) {
  advance(t_s);
  for (int i = 0; i < 3; ++i) {
    Axis& a = axes_[static_cast<std::size_t>(i)];
    a.at_limit = false;
    a.watchdog = false;
    update_limit_event(i, now_);
  }
  return {};
}

ServoResult TableServo::set_mode(double t_s, int axis, TableMode mode) {
  advance(t_s);
  if (auto r = bad_axis(axis); !r.ok()) return r;
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  if (mode != TableMode::off) {
    if (interlock_ != InterlockState::closed) return {dialect::Refusal::interlock_open, "interlock open"};
    if (a.at_limit) return {dialect::Refusal::axis_fault, "axis " + std::to_string(axis + 1) + " hit a position limit: reset required"};
  }
  a.watchdog = false;
  a.last_feed_s = now_;
  if (mode == a.mode) return {};
  const auto [t_rest, angle] = graceful_stop(axis, now_, limits(axis, a.mode).accel_dps2 * kDegToRad);
  (void)t_rest;
  a.mode = mode;
  a.centre_rad = angle;
  update_limit_event(axis, now_);
  return {};
}

ServoResult TableServo::demand_position(double t_s, int axis, double angle_deg) {
  advance(t_s);
  if (auto r = check_motion_allowed(axis, TableMode::position); !r.ok()) return r;
  const AxisLimitSetting& L = limits(axis, TableMode::position);
  if (!std::isfinite(angle_deg) || angle_deg < L.min_deg || angle_deg > L.max_deg)
    return {dialect::Refusal::limit_exceeded, "position outside [" + std::to_string(L.min_deg) + ", " + std::to_string(L.max_deg) + "] deg"};
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  a.last_feed_s = now_;
  const double v = L.rate_dps * kDegToRad, acc = L.accel_dps2 * kDegToRad;
  // A demand equal to where the axis already rests only feeds the watchdog.
  const double target = angle_deg * kDegToRad;
  // Nor does the demand of the move already under way (track-mode keep-alive): its trajectory
  // ends at rest on the target.
  if (a.segs.back().f.kind == AxisFunc::Kind::Const && std::fabs(a.segs.back().f.theta0 - target) < 1e-12) return {};
  const auto [t1, th1] = graceful_stop(axis, now_, acc);
  const double d = target - th1, s = sgn(d), D = std::fabs(d);
  std::vector<Seg> segs;
  if (D > 0.0) {
    double ta, tc, vpk;
    if (D <= v * v / acc) {
      ta = std::sqrt(D / acc);
      tc = 0.0;
      vpk = acc * ta;
    } else {
      ta = v / acc;
      tc = (D - v * v / acc) / v;
      vpk = v;
    }
    const double th_a = th1 + s * 0.5 * acc * ta * ta;
    segs.push_back({t1, AxisFunc::quadratic(th1, 0.0, s * acc)});
    if (tc > 0.0) segs.push_back({t1 + ta, AxisFunc::quadratic(th_a, s * vpk, 0.0)});
    segs.push_back({t1 + ta + tc, AxisFunc::quadratic(th_a + s * vpk * tc, s * vpk, -s * acc)});
    segs.push_back({t1 + 2.0 * ta + tc, AxisFunc::constant(target)});
  } else {
    segs.push_back({t1, AxisFunc::constant(target)});
  }
  replace_from(axis, t1, std::move(segs));
  return {};
}

ServoResult TableServo::demand_rate(double t_s, int axis, double rate_dps) {
  advance(t_s);
  if (auto r = check_motion_allowed(axis, TableMode::rate); !r.ok()) return r;
  const AxisLimitSetting& L = limits(axis, TableMode::rate);
  if (!std::isfinite(rate_dps) || std::fabs(rate_dps) > L.rate_dps)
    return {dialect::Refusal::limit_exceeded, "rate beyond the rate-mode limit of " + std::to_string(L.rate_dps) + " deg/s"};
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  a.last_feed_s = now_;
  double angle, rate, accel;
  eval(a, now_, angle, rate, accel);
  const double target = rate_dps * kDegToRad, acc = L.accel_dps2 * kDegToRad;
  const Seg& s = active(a, now_);
  // Repeating the demand in force (track mode keep-alive) leaves the motion as it is.
  if (s.f.kind == AxisFunc::Kind::Quadratic && s.f.alpha == 0.0 && s.f.omega0 == target) return {};
  if (s.f.kind == AxisFunc::Kind::Const && target == 0.0) return {};
  if (s.f.kind == AxisFunc::Kind::Quadratic && s.f.alpha != 0.0) {
    const auto& last = a.segs.back();
    if (last.f.kind == AxisFunc::Kind::Quadratic && last.f.alpha == 0.0 && last.f.omega0 == target) return {};
  }
  const double dw = target - rate, T = std::fabs(dw) / acc;
  std::vector<Seg> segs;
  if (T > 0.0) {
    const double alpha = sgn(dw) * acc;
    segs.push_back({now_, AxisFunc::quadratic(angle, rate, alpha)});
    segs.push_back({now_ + T, AxisFunc::quadratic(angle + rate * T + 0.5 * alpha * T * T, target, 0.0)});
  } else {
    segs.push_back({now_, target == 0.0 ? AxisFunc::constant(angle) : AxisFunc::quadratic(angle, target, 0.0)});
  }
  replace_from(axis, now_, std::move(segs));
  return {};
}

ServoResult TableServo::demand_oscillation(double t_s, int axis, const OscillationDemand& d) {
  advance(t_s);
  if (auto r = check_motion_allowed(axis, TableMode::synthesis); !r.ok()) return r;
  const AxisLimitSetting& L = limits(axis, TableMode::synthesis);
  Axis& a = axes_[static_cast<std::size_t>(axis)];
  const double A = d.amplitude_deg * kDegToRad, w = 2.0 * kPi * d.frequency_hz, phi = d.phase_deg * kDegToRad;
  if (!std::isfinite(A) || !std::isfinite(w) || !std::isfinite(phi) || A < 0.0 || (A > 0.0 && !(w > 0.0)))
    return {dialect::Refusal::argument, "amplitude must be >= 0 and frequency > 0"};
  const double c = a.centre_rad;
  if ((c - A) * kRadToDeg < L.min_deg || (c + A) * kRadToDeg > L.max_deg)
    return {dialect::Refusal::limit_exceeded, "oscillation leaves the position range"};
  if (A * w * kRadToDeg > L.rate_dps) return {dialect::Refusal::limit_exceeded, "oscillation rate amplitude beyond the rate limit"};
  if (A * w * w * kRadToDeg > L.accel_dps2) return {dialect::Refusal::limit_exceeded, "oscillation acceleration beyond the limit"};
  a.last_feed_s = now_;
  // The oscillation in force demanded again (track-mode keep-alive): nothing changes.
  const Seg& last = a.segs.back();
  if (A > 0.0 && last.f.kind == AxisFunc::Kind::Sine && last.f.amp == A && last.f.omega == w &&
      std::fabs(std::remainder(w * last.t0 + phi - last.f.phase, 2.0 * kPi)) < 1e-9 &&
      std::fabs(last.f.theta0 - A * std::sin(last.f.phase) - c) < 1e-12)
    return {};
  const double v = L.rate_dps * kDegToRad, acc = L.accel_dps2 * kDegToRad;
  const auto [t1, th1] = graceful_stop(axis, now_, acc);
  // Rest-to-rest move helper: segments and duration.
  auto move = [&](double from, double to, double t0, std::vector<Seg>& segs) {
    const double dd = to - from, s = sgn(dd), D = std::fabs(dd);
    if (D == 0.0) {
      segs.push_back({t0, AxisFunc::constant(to)});
      return 0.0;
    }
    double ta, tc, vpk;
    if (D <= v * v / acc) {
      ta = std::sqrt(D / acc);
      tc = 0.0;
      vpk = acc * ta;
    } else {
      ta = v / acc;
      tc = (D - v * v / acc) / v;
      vpk = v;
    }
    const double th_a = from + s * 0.5 * acc * ta * ta;
    segs.push_back({t0, AxisFunc::quadratic(from, 0.0, s * acc)});
    if (tc > 0.0) segs.push_back({t0 + ta, AxisFunc::quadratic(th_a, s * vpk, 0.0)});
    segs.push_back({t0 + ta + tc, AxisFunc::quadratic(th_a + s * vpk * tc, s * vpk, -s * acc)});
    segs.push_back({t0 + 2.0 * ta + tc, AxisFunc::constant(to)});
    return 2.0 * ta + tc;
  };
  std::vector<Seg> segs;
  if (A == 0.0) {
    move(th1, c, t1, segs);
    replace_from(axis, t1, std::move(segs));
    return {};
  }
  // Start at the turning point (c + A at psi = pi/2, c - A at psi = 3 pi/2, mod 2 pi) reached
  // first, psi = w t + phi on world time.
  double best_t = kInf;
  double best_sign = 1.0;
  for (const double s : {1.0, -1.0}) {
    std::vector<Seg> tmp;
    const double ready = t1 + move(th1, c + s * A, t1, tmp);
    const double psi_target = s > 0 ? kPi / 2 : 3 * kPi / 2;
    const double k = std::ceil((w * ready + phi - psi_target) / (2.0 * kPi));
    const double t_z = (psi_target + 2.0 * kPi * k - phi) / w;
    if (t_z < best_t) {
      best_t = t_z;
      best_sign = s;
    }
  }
  const double start = c + best_sign * A;
  move(th1, start, t1, segs);
  AxisFunc sine;
  sine.kind = AxisFunc::Kind::Sine;
  sine.theta0 = start;
  sine.amp = A;
  sine.omega = w;
  sine.phase = std::remainder(w * best_t + phi, 2.0 * kPi);
  sine.duration = kFarFuture_s;
  sine.ramp = 0.0;
  segs.push_back({best_t, sine});
  replace_from(axis, t1, std::move(segs));
  return {};
}

ServoResult TableServo::set_limit_position(double t_s, int axis, TableMode mode, double min_deg, double max_deg) {
  advance(t_s);
  if (auto r = bad_axis(axis); !r.ok()) return r;
  if (!(min_deg < max_deg) || !std::isfinite(min_deg) || !std::isfinite(max_deg))
    return {dialect::Refusal::argument, "position limits need min < max"};
  lim(axis, mode).min_deg = min_deg;
  lim(axis, mode).max_deg = max_deg;
  update_limit_event(axis, now_);
  return {};
}

ServoResult TableServo::set_limit_rate(double t_s, int axis, TableMode mode, double rate_dps) {
  advance(t_s);
  if (auto r = bad_axis(axis); !r.ok()) return r;
  if (!(rate_dps > 0.0) || !std::isfinite(rate_dps)) return {dialect::Refusal::argument, "rate limit must be positive"};
  lim(axis, mode).rate_dps = rate_dps;
  return {};
}

ServoResult TableServo::set_limit_accel(double t_s, int axis, TableMode mode, double accel_dps2) {
  advance(t_s);
  if (auto r = bad_axis(axis); !r.ok()) return r;
  if (!(accel_dps2 > 0.0) || !std::isfinite(accel_dps2)) return {dialect::Refusal::argument, "acceleration limit must be positive"};
  lim(axis, mode).accel_dps2 = accel_dps2;
  return {};
}

ServoResult TableServo::set_watchdog(double t_s, double period_s) {
  advance(t_s);
  if (!(period_s >= 0.0) || !std::isfinite(period_s)) return {dialect::Refusal::argument, "watchdog period must be >= 0"};
  watchdog_period_s_ = period_s;
  for (Axis& a : axes_) a.last_feed_s = now_;
  return {};
}

std::array<AxisSample, 3> TableServo::sample(double t_s) const {
  std::array<AxisSample, 3> out{};
  for (std::size_t i = 0; i < 3; ++i) {
    double angle, rate, accel;
    eval(axes_[i], t_s, angle, rate, accel);
    out[i] = {angle * kRadToDeg, rate * kRadToDeg, accel * kRadToDeg};
  }
  return out;
}

TableStatus TableServo::status(double t_s) const {
  TableStatus st;
  st.interlock = interlock_;
  const auto s = sample(t_s);
  for (std::size_t i = 0; i < 3; ++i) {
    const Axis& a = axes_[i];
    st.axes[i].mode = a.mode;
    st.axes[i].at_limit = a.at_limit;
    st.axes[i].fault = a.at_limit;
    st.axes[i].watchdog_expired = a.watchdog;
    st.axes[i].moving = std::fabs(s[i].rate_dps) > config_.moving_threshold_dps;
  }
  return st;
}

motion::Program TableServo::program_from(double t_from) const {
  motion::Program p;
  p.name = "simulated-table";
  std::vector<double> bounds{t_from};
  for (const Axis& a : axes_)
    for (const Seg& s : a.segs)
      if (s.t0 > t_from) bounds.push_back(s.t0);
  std::sort(bounds.begin(), bounds.end());
  bounds.erase(std::unique(bounds.begin(), bounds.end()), bounds.end());
  for (std::size_t i = 0; i < bounds.size(); ++i) {
    motion::Piece piece;
    piece.t0_s = bounds[i] - t_from;
    piece.t1_s = i + 1 < bounds.size() ? bounds[i + 1] - t_from : piece.t0_s + kFarFuture_s;
    piece.segment = "table";
    piece.kind = "sim";
    for (std::size_t k = 0; k < 3; ++k) {
      const Seg& s = active(axes_[k], bounds[i]);
      piece.axis[k] = s.f.rebased(std::max(0.0, bounds[i] - s.t0));
    }
    p.pieces.push_back(piece);
  }
  return p;
}

}  // namespace imucal::sim
