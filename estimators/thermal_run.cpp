// Stage 2 over a run: cycles, per-cycle estimates, temperature checks, fits and the report.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <stdexcept>
#include <utility>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "estimators/thermal.hpp"

namespace imucal::thermal {

using nlohmann::json;

namespace {

std::string fmt(const char* f, double a) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, a);
  return buf;
}

std::string span_text(double t0, double t1) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "t=%.0f..%.0f s", t0, t1);
  return buf;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
std::vector<Cycle> find_cycles(const std::vector<SegmentInfo>& segments, int statics_per_cycle) {
  std::vector<SegmentInfo> statics;
  for (const SegmentInfo& s : segments)
    if (s.kind == "static") statics.push_back(s);
  std::sort(statics.begin(), statics.end(), [](const SegmentInfo& a, const SegmentInfo& b) { return a.t0_s < b.t0_s; });
  auto prefix = [](const std::string& name) -> std::string {
    const auto slash = name.find('/');
    if (name.rfind("cycle-", 0) != 0 || slash == std::string::npos) return {};
    return name.substr(0, slash);
  };
  const bool named = std::any_of(statics.begin(), statics.end(), [&](const SegmentInfo& s) { return !prefix(s.name).empty(); });
  std::vector<Cycle> out;
  std::vector<std::pair<std::size_t, std::size_t>> ranges;  // [first, last] static of each cycle
  if (named) {
    for (std::size_t i = 0; i < statics.size();) {
      const std::string p = prefix(statics[i].name);
      std::size_t k = i;
      while (k + 1 < statics.size() && prefix(statics[k + 1].name) == p) ++k;
      if (!p.empty()) ranges.emplace_back(i, k);
      i = k + 1;
    }
  } else if (statics_per_cycle > 0) {
    const auto per = static_cast<std::size_t>(statics_per_cycle);
    for (std::size_t i = 0; i + per <= statics.size(); i += per) ranges.emplace_back(i, i + per - 1);
  } else {
    throw std::runtime_error(
        "stage thermal: the run's statics carry no \"cycle-NNN/\" names; give the number of statics per table cycle "
        "(--statics-per-cycle)");
  }
  for (const auto& [first, last] : ranges) {
    Cycle c;
    const std::string p = prefix(statics[first].name);
    c.name = p.empty() ? "cycle-" + std::to_string(out.size() + 1) : p;
    c.statics.assign(statics.begin() + static_cast<std::ptrdiff_t>(first),
                     statics.begin() + static_cast<std::ptrdiff_t>(last) + 1);
    if (last + 1 < statics.size()) c.statics.push_back(statics[last + 1]);  // the closing rest
    c.t0_s = c.statics.front().t0_s;
    c.t1_s = c.statics.back().t1_s;
    out.push_back(c);
  }
  return out;
}

// ------------------------------------------------------------------------------------------------
CycleEstimator::CycleEstimator(const RecordingMeta& meta, std::vector<Cycle> cycles, const ImuModel& seed)
    : meta_(meta), cycles_(std::move(cycles)), seed_(seed) {
  std::sort(cycles_.begin(), cycles_.end(), [](const Cycle& a, const Cycle& b) { return a.t0_s < b.t0_s; });
  meta_.segments.clear();
  results_.resize(cycles_.size());
}

namespace {

// The coefficient a column of stage 1's design estimates, by its name.
int coefficient_index(const direct::SensorDesign& d, std::size_t column) {
  const std::string key = d.key(column);
  for (const Coefficient& k : coefficients())
    if (full_key(k) == key) return k.index;
  throw std::logic_error("stage thermal: stage 1 estimates " + key + ", which has no thermal coefficient");
}

// Influence of each interval on each coefficient: stage 1's own design at the solution
// (direct::gyro_design, accel_design), so that the temperature an estimate refers to is the same
// weighted mean of the intervals' temperatures that the estimate itself is of the coefficient's
// values (exact for a coefficient linear in T).
void influence(const std::vector<direct::Interval>& ivs, const ImuModel& m, const direct::Options& options,
               CycleEstimate& e) {
  const direct::Selection sel = direct::select_intervals(ivs, options);
  // Every interval stage 1 used, in the gyros' row order (statics, then rotations): the
  // accelerometers' rows are the statics, its first rows.
  std::vector<const direct::Interval*> eqs = sel.statics;
  eqs.insert(eqs.end(), sel.rotations.begin(), sel.rotations.end());
  e.spans.clear();
  for (const auto* iv : eqs) e.spans.push_back({iv->t0_s, iv->t1_s});
  for (auto& w : e.weight) w.assign(eqs.size(), 0.0);
  // Design rows: gyro x y z, accel x y z.
  for (std::size_t row = 0; row < 6; ++row) {
    const int j = static_cast<int>(row % 3);
    const direct::SensorDesign sd = row < 3 ? direct::gyro_design(j, sel, m.gyro) : direct::accel_design(j, sel, m.accel);
    CycleEstimate::Design& d = e.design[row];
    d.coefficient.clear();
    for (std::size_t c = 0; c < sd.columns.size(); ++c) d.coefficient.push_back(coefficient_index(sd, c));
    d.interval.resize(sd.rows.size());
    for (std::size_t i = 0; i < sd.rows.size(); ++i) d.interval[i] = i;
    d.A = sd.A;
    d.K = (sd.A.transpose() * sd.w.asDiagonal() * sd.A).ldlt().solve(sd.A.transpose() * sd.w.asDiagonal());
    for (std::size_t c = 0; c < d.coefficient.size(); ++c)
      for (std::size_t i = 0; i < d.interval.size(); ++i)
        e.weight[static_cast<std::size_t>(d.coefficient[c])][d.interval[i]] =
            d.K(static_cast<Eigen::Index>(c), static_cast<Eigen::Index>(i)) *
            d.A(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(c));
    const Eigen::VectorXd x = d.K * sd.b;
    for (std::size_t c = 0; c < d.coefficient.size(); ++c) {
      const Coefficient& k = coefficients()[static_cast<std::size_t>(d.coefficient[c])];
      e.design_mismatch[static_cast<std::size_t>(k.index)] =
          std::abs(x[static_cast<Eigen::Index>(c)] * k.si_to_json - get(m.gyro, m.accel, k));
    }
  }
}

}  // namespace

void CycleEstimator::close(Active& a) {
  CycleEstimate& e = results_[a.index];
  const Cycle& c = cycles_[a.index];
  e.name = c.name;
  e.t0_s = c.t0_s;
  e.t1_s = c.t1_s;
  try {
    const direct::Result r = a.calibrator->finish(seed_);
    const ImuErrorSet sig = r.model.sigma.value_or(ImuErrorSet{});
    for (const Coefficient& k : coefficients()) {
      e.value[static_cast<std::size_t>(k.index)] = get(r.model.gyro, r.model.accel, k);
      e.sigma[static_cast<std::size_t>(k.index)] = get(sig.gyro, sig.accel, k);
    }
    influence(a.calibrator->intervals(), r.model, direct::Options{}, e);
    e.ok = true;
  } catch (const std::exception& ex) {
    e.ok = false;
    e.note = ex.what();
  }
  a.calibrator.reset();
}

void CycleEstimator::push(const ImuFrame& f) {
  const double t = static_cast<double>(f.t_ns) * 1e-9;
  // A calibrator needs the frame before its first static: open it a little early.
  constexpr double kLead_s = 1.0;
  while (next_open_ < cycles_.size() && cycles_[next_open_].t0_s - kLead_s <= t) {
    RecordingMeta m = meta_;
    m.segments = cycles_[next_open_].statics;
    // Each cycle's own sigma weighs it in the fits: the type B sources are common to every cycle.
    direct::Options cycle_options;
    cycle_options.type_b = false;
    active_.push_back({next_open_, std::make_unique<direct::DirectCalibrator>(m, cycle_options)});
    ++next_open_;
  }
  for (Active& a : active_) {
    if (t <= cycles_[a.index].t1_s + kLead_s) a.calibrator->push(f);
    else close(a);
  }
  active_.erase(std::remove_if(active_.begin(), active_.end(), [](const Active& a) { return !a.calibrator; }),
                active_.end());
}

std::vector<CycleEstimate> CycleEstimator::finish() {
  for (Active& a : active_) close(a);
  active_.clear();
  for (std::size_t i = next_open_; i < cycles_.size(); ++i) {
    results_[i].name = cycles_[i].name;
    results_[i].t0_s = cycles_[i].t0_s;
    results_[i].t1_s = cycles_[i].t1_s;
    results_[i].note = "no frames";
  }
  return results_;
}

// ------------------------------------------------------------------------------------------------
// Temperature series: sample-and-hold values and a centred least-squares rate at every sample.

namespace {

constexpr int kChamber = kChannels;  // the seventh column: chamber air

// Half window of the rates the judge of a simulated run evaluates its truth with (see calibrate).
constexpr double kJudgeHalfWindow_s = 30.0;

class TempSeries {
 public:
  TempSeries(const std::vector<TempSample>& temps, double half_window_s) {
    for (const TempSample& s : temps) {
      std::array<double, kChannels + 1> v{};
      for (int j = 0; j < 3; ++j) {
        v[static_cast<std::size_t>(j)] = s.gyro_C[j];
        v[static_cast<std::size_t>(3 + j)] = s.accel_C[j];
      }
      v[kChamber] = s.chamber_C;
      t_.push_back(static_cast<double>(s.t_ns) * 1e-9);
      v_.push_back(v);
    }
    rate_.assign(t_.size(), {});
    // Running sums over the window [t - h, t + h] (two pointers), per channel.
    for (int ch = 0; ch <= kChamber; ++ch) {
      std::size_t lo = 0, hi = 0;
      double n = 0, st = 0, stt = 0, sy = 0, sty = 0;
      const auto c = static_cast<std::size_t>(ch);
      for (std::size_t i = 0; i < t_.size(); ++i) {
        while (hi < t_.size() && t_[hi] <= t_[i] + half_window_s) {
          const double dt = t_[hi] - t_[0], y = v_[hi][c];
          n += 1;
          st += dt;
          stt += dt * dt;
          sy += y;
          sty += dt * y;
          ++hi;
        }
        while (t_[lo] < t_[i] - half_window_s) {
          const double dt = t_[lo] - t_[0], y = v_[lo][c];
          n -= 1;
          st -= dt;
          stt -= dt * dt;
          sy -= y;
          sty -= dt * y;
          ++lo;
        }
        const double den = n * stt - st * st;
        rate_[i][c] = n >= 2 && den > 1e-9 ? (n * sty - st * sy) / den * 60.0 : 0.0;
      }
    }
  }

  bool empty() const { return t_.empty(); }
  std::size_t index_at(double t) const {
    const auto it = std::upper_bound(t_.begin(), t_.end(), t);
    return it == t_.begin() ? 0 : static_cast<std::size_t>(it - t_.begin()) - 1;
  }
  double value(int ch, double t) const { return v_[index_at(t)][static_cast<std::size_t>(ch)]; }
  double rate(int ch, double t) const { return rate_[index_at(t)][static_cast<std::size_t>(ch)]; }
  // Time average over [t0, t1] of the sample-and-hold value.
  double mean(int ch, double t0, double t1) const {
    if (t1 <= t0) return value(ch, t0);
    std::size_t i = index_at(t0);
    double acc = 0, t = t0;
    while (t < t1) {
      const double next = i + 1 < t_.size() ? std::min(t1, t_[i + 1]) : t1;
      acc += v_[i][static_cast<std::size_t>(ch)] * (next - t);
      t = next;
      ++i;
      if (i >= t_.size()) {
        acc += v_.back()[static_cast<std::size_t>(ch)] * (t1 - t);
        break;
      }
    }
    return acc / (t1 - t0);
  }
  const std::vector<double>& times() const { return t_; }

 private:
  std::vector<double> t_;
  std::vector<std::array<double, kChannels + 1>> v_;
  std::vector<std::array<double, kChannels + 1>> rate_;
};

}  // namespace

// ------------------------------------------------------------------------------------------------
namespace {

// The samples as channels: 0..2 the FOG coil means x y z, 3..5 the accelerometers, kChamber the air.
double time_s(const std::vector<TempSample>& temps, std::size_t i) { return static_cast<double>(temps[i].t_ns) * 1e-9; }
double reading_C(const std::vector<TempSample>& temps, std::size_t i, int ch) {
  if (ch < 3) return temps[i].gyro_C[ch];
  if (ch < 6) return temps[i].accel_C[ch - 3];
  return temps[i].chamber_C;
}
std::string channel_label(int ch) { return ch < kChannels ? std::string(channel_name(ch)) : std::string("temp_chamber_C"); }
// The channel's bit of TempProblem::channel_mask: none for the chamber (no coefficient is on it).
unsigned channel_bit(int ch) { return ch < kChannels ? 1u << ch : 0u; }

// The range (C) of value(m) over samples i..e.
template <class Value>
double range_over(std::size_t i, std::size_t e, const Value& value) {
  double lo = value(i), hi = lo;
  for (std::size_t m = i; m <= e; ++m) {
    lo = std::min(lo, value(m));
    hi = std::max(hi, value(m));
  }
  return hi - lo;
}
double air_range_C(const std::vector<TempSample>& temps, std::size_t i, std::size_t e) {
  return range_over(i, e, [&](std::size_t m) { return reading_C(temps, m, kChamber); });
}
// The median of the witnesses' ranges over samples i..e (the upper one of two), C.
template <class WitnessValue>
double witnesses_moved_C(std::size_t i, std::size_t e, std::size_t witnesses, const WitnessValue& witness_value) {
  std::vector<double> change;
  for (std::size_t w = 0; w < witnesses; ++w)
    change.push_back(range_over(i, e, [&](std::size_t m) { return witness_value(w, m); }));
  std::sort(change.begin(), change.end());
  return change[change.size() / 2];
}

// Where a jump of `step` at sample i comes back: the first later step the other way by more than
// half of it (`value(m)` the reading at m); n when it never does.
template <class Value>
std::size_t jump_back(std::size_t i, std::size_t n, double step, const Value& value) {
  for (std::size_t m = i + 1; m < n; ++m) {
    const double d = value(m) - value(m - 1);
    if (std::isfinite(d) && d * step < 0 && std::abs(d) > 0.5 * std::abs(step)) return m;
  }
  return n;
}
std::string jump_text(const std::vector<TempSample>& temps, std::size_t i, std::size_t back, double step) {
  std::string what = "jumped by " + fmt("%+.3f", step) + " C at t=" + fmt("%.1f", time_s(temps, i)) + " s";
  what += back < temps.size() ? " and back at t=" + fmt("%.1f", time_s(temps, back)) + " s" : " and never came back";
  return what;
}

// Stuck: a reading unchanged for stuck_s while its witnesses moved. The witnesses are sensors of
// like time constant (a channel's own triad: the FOG coils are slow, the accelerometers fast; a
// coil sensor's the coil's other seven), never the chamber alone (a stabilised IMU holds still
// while the air moves). And never while the air held still: a sensor that has settled in a soak
// reads a constant exactly as a stuck one does and cannot be told from it, while slower sensors
// are still moving (the accelerometers settle long before the coils). Found first, so that the
// step when a sensor comes unstuck is not taken for a jump: each channel's stuck runs end at the
// samples `stuck_end` lists.
void find_stuck_channels(const std::vector<TempSample>& temps, const CheckOptions& o, std::vector<TempProblem>& out,
                         std::vector<std::vector<std::size_t>>& stuck_end) {
  const auto n = temps.size();
  auto val = [&](std::size_t i, int ch) { return reading_C(temps, i, ch); };
  for (int ch = 0; ch < kChannels; ++ch) {
    const int triad = ch / 3 * 3;  // the channel's triad: gyros 0..2, accelerometers 3..5
    for (std::size_t i = 0; i < n;) {
      std::size_t k = i;
      while (k + 1 < n && val(k + 1, ch) == val(i, ch)) ++k;
      const double t0 = time_s(temps, i), t1 = time_s(temps, k);
      if (t1 - t0 >= o.stuck_s) {
        const double air = air_range_C(temps, i, k);
        const double others = witnesses_moved_C(i, k, 2, [&](std::size_t w, std::size_t m) {
          const int other = triad + (ch - triad + 1 + static_cast<int>(w)) % 3;
          return val(m, other);
        });
        if (others >= o.stuck_others_change_C && air >= o.air_still_C) {
          out.push_back({channel_label(ch),
                         "stuck at " + fmt("%.3f", val(i, ch)) + " C for " + fmt("%.0f", t1 - t0) +
                             " s while the chamber moved by " + fmt("%.2f", air) + " C and the other " +
                             (ch < 3 ? "coils" : "accelerometers") + " by " + fmt("%.2f", others) + " C",
                         t0, k + 1 < n ? time_s(temps, k + 1) : t1, channel_bit(ch)});
          stuck_end[static_cast<std::size_t>(ch)].push_back(k);
        }
      }
      i = k + 1;
    }
  }
}

// Sensor k of coil c (every sample carries the coil sensors): its stuck runs, the coil's other
// seven the witnesses, then its jumps (not where it comes unstuck) and invalid readings.
void check_coil_sensor(const std::vector<TempSample>& temps, std::size_t c, std::size_t k, const CheckOptions& o,
                       std::vector<TempProblem>& out, std::vector<std::size_t>& coil_stuck_end) {
  const auto n = temps.size();
  auto sensor = [&](std::size_t i, std::size_t which) { return (*temps[i].coil_sensors_C)[c][which]; };
  const std::string nm = std::string("temp_g") + "xyz"[c] + "_" + std::to_string(k + 1) + "_C";
  const unsigned coil_mask = 1u << c;
  std::vector<std::size_t> unstuck;  // ends of long unchanged runs (all eight stuck: the mean says so)
  for (std::size_t i = 0; i < n;) {
    std::size_t e = i;
    while (e + 1 < n && sensor(e + 1, k) == sensor(i, k)) ++e;
    if (time_s(temps, e) - time_s(temps, i) >= o.stuck_s) {
      unstuck.push_back(e);
      const double others = witnesses_moved_C(i, e, 7, [&](std::size_t w, std::size_t m) {
        return sensor(m, w < k ? w : w + 1);  // the coil's other seven
      });
      if (others >= o.stuck_others_change_C && air_range_C(temps, i, e) >= o.air_still_C) {
        out.push_back({nm,
                       "stuck at " + fmt("%.3f", sensor(i, k)) + " C for " + fmt("%.0f", time_s(temps, e) - time_s(temps, i)) +
                           " s while the coil's other sensors moved by " + fmt("%.2f", others) + " C",
                       time_s(temps, i), e + 1 < n ? time_s(temps, e + 1) : time_s(temps, e), coil_mask});
        coil_stuck_end.push_back(e);
      }
    }
    i = e + 1;
  }
  for (std::size_t i = 1; i < n; ++i) {
    const double a = sensor(i - 1, k), b = sensor(i, k);
    if (!std::isfinite(a) || !std::isfinite(b)) {
      out.push_back({nm, "no valid reading", time_s(temps, i - 1), time_s(temps, i), coil_mask});
      continue;
    }
    if (std::find(unstuck.begin(), unstuck.end(), i - 1) != unstuck.end()) continue;  // coming unstuck
    const double allowed = o.jump_C + o.max_rate_C_per_min / 60.0 * (time_s(temps, i) - time_s(temps, i - 1));
    const double step = b - a;
    if (std::abs(step) <= allowed) continue;
    const std::size_t back = jump_back(i, n, step, [&](std::size_t m) { return sensor(m, k); });
    out.push_back({nm, jump_text(temps, i, back, step) + " (one of coil " + "xyz"[c] + "'s eight sensors)",
                   time_s(temps, i - 1), back < n ? time_s(temps, back) : time_s(temps, n - 1), coil_mask});
    i = back < n ? back : n;
  }
}

// Missing or implausible readings of a channel (a broken sensor reads NaN, its maximum or nothing).
void find_invalid_readings(const std::vector<TempSample>& temps, int ch, const CheckOptions& o,
                           std::vector<TempProblem>& out) {
  const auto n = temps.size();
  auto valid = [&](double v) { return std::isfinite(v) && v >= o.plausible_lo_C && v <= o.plausible_hi_C; };
  for (std::size_t i = 0; i < n;) {
    const double v = reading_C(temps, i, ch);
    if (valid(v)) {
      ++i;
      continue;
    }
    std::size_t k = i;
    while (k + 1 < n && !valid(reading_C(temps, k + 1, ch))) ++k;
    out.push_back({channel_label(ch), "no valid reading (" + fmt("%g", v) + " C)", time_s(temps, i),
                   k + 1 < n ? time_s(temps, k + 1) : time_s(temps, n - 1), channel_bit(ch)});
    i = k + 1;
  }
}

// Jumps: a step no physical temperature makes; the channel is suspect until it steps back. A step
// where a stuck run ends (stuck_ends) is the sensor coming unstuck.
void find_jumps(const std::vector<TempSample>& temps, int ch, const std::vector<std::size_t>& stuck_ends,
                const CheckOptions& o, std::vector<TempProblem>& out) {
  const auto n = temps.size();
  for (std::size_t i = 1; i < n; ++i) {
    const double a = reading_C(temps, i - 1, ch), b = reading_C(temps, i, ch);
    if (!std::isfinite(a) || !std::isfinite(b)) continue;
    if (std::find(stuck_ends.begin(), stuck_ends.end(), i - 1) != stuck_ends.end()) continue;  // coming unstuck
    const double allowed = o.jump_C + o.max_rate_C_per_min / 60.0 * (time_s(temps, i) - time_s(temps, i - 1));
    if (std::abs(b - a) <= allowed) continue;
    const double step = b - a;
    const std::size_t back = jump_back(i, n, step, [&](std::size_t m) { return reading_C(temps, m, ch); });
    out.push_back({channel_label(ch), jump_text(temps, i, back, step), time_s(temps, i - 1),
                   back < n ? time_s(temps, back) : time_s(temps, n - 1), channel_bit(ch)});
    i = back < n ? back : n;
  }
}

// Gaps: no samples while the temperatures moved (a run-length store may skip unchanged ones).
void find_gaps(const std::vector<TempSample>& temps, const CheckOptions& o, std::vector<TempProblem>& out) {
  for (std::size_t i = 1; i < temps.size(); ++i) {
    const double dt = time_s(temps, i) - time_s(temps, i - 1);
    if (dt <= o.gap_s) continue;
    double moved = 0;
    for (int ch = 0; ch <= kChamber; ++ch)
      moved = std::max(moved, std::abs(reading_C(temps, i, ch) - reading_C(temps, i - 1, ch)));
    if (moved > 0.05)
      out.push_back({"all", "no temperature samples for " + fmt("%.0f", dt) + " s while they moved by " +
                                fmt("%.2f", moved) + " C",
                     time_s(temps, i - 1), time_s(temps, i), 0x3Fu});
  }
}

// The chamber at the end of each soak long enough to judge: within its tolerance of the set point.
void find_missed_setpoints(const std::vector<TempSample>& temps, const CheckOptions& o, std::vector<TempProblem>& out) {
  const auto n = temps.size();
  for (std::size_t i = 0; i < n;) {
    const std::optional<double>& setpoint_C = temps[i].chamber_setpoint_C;
    if (!setpoint_C) {
      ++i;
      continue;
    }
    const double sp = *setpoint_C;
    std::size_t k = i;
    // The soak: the samples after i with the same set point.
    for (; k + 1 < n; ++k) {
      const std::optional<double>& next_C = temps[k + 1].chamber_setpoint_C;
      if (!next_C || *next_C != sp) break;
    }
    const double t0 = time_s(temps, i), t1 = time_s(temps, k);
    if (t1 - t0 >= o.setpoint_settle_s && std::abs(temps[k].chamber_C - sp) > o.setpoint_tolerance_C)
      out.push_back({"temp_chamber_C",
                     "never reached the set point " + fmt("%.2f", sp) + " C (air " + fmt("%.2f", temps[k].chamber_C) +
                         " C at the end of the soak)",
                     t0, t1, 0x3Fu});
    i = k + 1;
  }
}

}  // namespace

std::vector<TempProblem> check_temperatures(const std::vector<TempSample>& temps, const CheckOptions& o) {
  std::vector<TempProblem> out;
  if (temps.empty()) {
    out.push_back({"all", "no temperature samples at all", 0.0, 0.0, 0x3Fu});
    return out;
  }
  std::vector<std::vector<std::size_t>> stuck_end(kChannels + 1);
  find_stuck_channels(temps, o, out, stuck_end);
  // The eight sensors of each coil, when every sample carries them: the same stuck and jump rules
  // per sensor, the coil's other seven the witnesses that the temperature moved, so that the
  // report names the sensor that broke (a problem of the coil mean below says what it did to the
  // channel the models use). A sensor coming unstuck moves the mean by a step that is no jump.
  const bool with_coil_sensors =
      std::all_of(temps.begin(), temps.end(), [](const TempSample& s) { return s.coil_sensors_C.has_value(); });
  for (std::size_t c = 0; c < 3 && with_coil_sensors; ++c)
    for (std::size_t k = 0; k < 8; ++k) check_coil_sensor(temps, c, k, o, out, stuck_end[c]);
  for (int ch = 0; ch <= kChamber; ++ch) {
    find_invalid_readings(temps, ch, o, out);
    find_jumps(temps, ch, stuck_end[static_cast<std::size_t>(ch)], o, out);
  }
  find_gaps(temps, o, out);
  find_missed_setpoints(temps, o, out);
  std::sort(out.begin(), out.end(), [](const TempProblem& a, const TempProblem& b) { return a.t0_s < b.t0_s; });
  return out;
}

// ------------------------------------------------------------------------------------------------
namespace {

// The temperature and rate each estimate refers to, per cycle and coefficient; who is left out.
struct Row {
  std::size_t cycle;
  std::array<double, kCoefficients> T{}, rate{};
  std::array<bool, kCoefficients> use{};
  std::array<double, kCoefficients> value{};  // the estimate less what other coefficients leaked in
  // Per channel and interval: mean temperature and rate at the middle.
  std::array<std::vector<double>, kChannels> T_iv, rate_iv;
};

// The temperature problems during a cycle: the channels they touch (TempProblem::channel_mask's
// bits, or-ed) and what they were.
struct CycleProblems {
  unsigned channel_mask = 0;
  std::string why;
};
CycleProblems problems_during(const CycleEstimate& e, const std::vector<TempProblem>& problems) {
  CycleProblems out;
  for (const TempProblem& p : problems)
    if (p.channel_mask && p.t0_s <= e.t1_s && p.t1_s >= e.t0_s) {
      out.channel_mask |= p.channel_mask;
      out.why += (out.why.empty() ? "" : "; ") + p.channel + " " + p.what;
    }
  return out;
}

// Cycle c's row: each channel's mean temperature and middle rate over each interval of the cycle,
// and each coefficient's through its estimate's own weighting of the intervals; a coefficient on
// a channel with a problem (bad_channels) is not used. A coefficient stage 1's design, as this
// stage rebuilds it, does not reproduce gets a note: its corrections are approximate.
Row row_of_cycle(std::size_t c, const CycleEstimate& e, const TempSeries& series, unsigned bad_channels,
                 const Options& opt, std::vector<std::string>& notes) {
  Row r;
  r.cycle = c;
  for (int ch = 0; ch < kChannels; ++ch)
    for (const auto& sp : e.spans) {
      r.T_iv[static_cast<std::size_t>(ch)].push_back(series.mean(ch, sp[0], sp[1]));
      r.rate_iv[static_cast<std::size_t>(ch)].push_back(series.rate(ch, 0.5 * (sp[0] + sp[1])));
    }
  for (const Coefficient& k : coefficients()) {
    const auto i = static_cast<std::size_t>(k.index);
    const auto ch = static_cast<std::size_t>(channel_of(k));
    for (std::size_t g = 0; g < groups().size(); ++g)
      if (std::string(groups()[g]) == k.group && e.design_mismatch[i] > 0.1 * opt.resolution[g])
        notes.push_back(e.name + ": " + full_key(k) + " is not reproduced by stage 1's design as this stage " +
                        "rebuilds it (off by " + fmt("%.3g", e.design_mismatch[i]) +
                        "): its temperature and leak corrections are approximate");
    double T = 0, rate = 0;
    for (std::size_t s = 0; s < e.spans.size(); ++s) {
      T += e.weight[i][s] * r.T_iv[ch][s];
      rate += e.weight[i][s] * r.rate_iv[ch][s];
    }
    r.T[i] = T;
    r.rate[i] = rate;
    r.use[i] = !(bad_channels & (1u << ch));
    r.value[i] = e.value[i];
  }
  return r;
}

// The selection: a row per cycle stage 1 estimated, the notes on what was left out and why (a
// failed cycle whole, a cycle with temperature problems for the coefficients on their channels),
// and the same for the report.
struct RowSelection {
  std::vector<Row> rows;
  std::vector<std::string> notes;
  json left_out = json::array();
};
RowSelection select_rows(const std::vector<CycleEstimate>& cycles, const std::vector<TempProblem>& problems,
                         const TempSeries& series, const Options& opt) {
  RowSelection out;
  for (std::size_t c = 0; c < cycles.size(); ++c) {
    const CycleEstimate& e = cycles[c];
    if (!e.ok) {
      std::string first_line = e.note.substr(0, e.note.find('\n'));
      out.notes.push_back(e.name + " (" + span_text(e.t0_s, e.t1_s) + ") left out: " + first_line);
      out.left_out.push_back({{"cycle", e.name}, {"t0_s", e.t0_s}, {"t1_s", e.t1_s}, {"reason", e.note}});
      continue;
    }
    const CycleProblems bad = problems_during(e, problems);
    Row r = row_of_cycle(c, e, series, bad.channel_mask, opt, out.notes);
    if (bad.channel_mask) {
      std::string chans;
      for (int ch = 0; ch < kChannels; ++ch)
        if (bad.channel_mask & (1u << ch)) chans += std::string(chans.empty() ? "" : ", ") + channel_name(ch);
      const bool all = (bad.channel_mask & 0x3Fu) == 0x3Fu;
      out.notes.push_back(e.name + " (" + span_text(e.t0_s, e.t1_s) + ") left out" +
                          (all ? "" : " for the coefficients on " + chans) + ": " + bad.why);
      out.left_out.push_back({{"cycle", e.name}, {"t0_s", e.t0_s}, {"t1_s", e.t1_s}, {"channels", all ? "all" : chans},
                              {"reason", bad.why}});
    }
    out.rows.push_back(std::move(r));
  }
  return out;
}

// What the used estimates cover: the temperature (C) and rate (C/min) over every channel (the
// range the models are fitted over), per channel {T lo, T hi, rate lo, rate hi}, and the cycles
// with an estimate used.
struct Coverage {
  double T_lo_C = 1e300, T_hi_C = -1e300, rate_lo_C_per_min = 1e300, rate_hi_C_per_min = -1e300;
  std::array<std::array<double, 4>, kChannels> per_channel{};
  int used_cycles = 0;
};
Coverage coverage_of(const std::vector<Row>& rows) {
  Coverage out;
  for (auto& c : out.per_channel) c = {1e300, -1e300, 1e300, -1e300};
  for (const Row& r : rows) {
    bool any = false;
    for (const Coefficient& k : coefficients()) {
      const auto i = static_cast<std::size_t>(k.index);
      if (!r.use[i]) continue;
      any = true;
      auto& c = out.per_channel[static_cast<std::size_t>(channel_of(k))];
      c = {std::min(c[0], r.T[i]), std::max(c[1], r.T[i]), std::min(c[2], r.rate[i]), std::max(c[3], r.rate[i])};
      out.T_lo_C = std::min(out.T_lo_C, r.T[i]);
      out.T_hi_C = std::max(out.T_hi_C, r.T[i]);
      out.rate_lo_C_per_min = std::min(out.rate_lo_C_per_min, r.rate[i]);
      out.rate_hi_C_per_min = std::max(out.rate_hi_C_per_min, r.rate[i]);
    }
    out.used_cycles += any;
  }
  return out;
}

// Each channel's coverage for the report; a note for a channel that did not reach the range
// asked (its models extrapolate) or was not both heated and cooled faster than 0.05 C/min.
json coverage_report(const Coverage& cover, const Options& opt, std::vector<std::string>& notes) {
  json coverage = json::object();
  for (int ch = 0; ch < kChannels; ++ch) {
    const auto& c = cover.per_channel[static_cast<std::size_t>(ch)];
    if (c[0] > c[1]) continue;
    coverage[channel_name(ch)] = {{"T_C", {c[0], c[1]}}, {"dTdt_C_per_min", {c[2], c[3]}}};
    if (c[0] > opt.range_lo_C + opt.coverage_tolerance_C || c[1] < opt.range_hi_C - opt.coverage_tolerance_C)
      notes.push_back(std::string("coverage: ") + channel_name(ch) + " reached " + fmt("%.2f", c[0]) + ".." +
                      fmt("%.2f", c[1]) + " C over the used cycles, asked " + fmt("%.1f", opt.range_lo_C) + ".." +
                      fmt("%.1f", opt.range_hi_C) + " C: its models extrapolate outside");
    if (c[3] < 0.05 || c[2] > -0.05) {
      const char* missing = c[3] < 0.05 && c[2] > -0.05 ? "heating or cooling" : c[3] < 0.05 ? "heating" : "cooling";
      notes.push_back(std::string("coverage: ") + channel_name(ch) + " dT/dt " + fmt("%+.3f", c[2]) + ".." +
                      fmt("%+.3f", c[3]) + " C/min: no " + missing + " faster than 0.05 C/min");
    }
  }
  return coverage;
}

// The models' reference temperature: the given models', the one asked, or the middle of the
// fitted range to the nearest half degree.
double reference_temperature_C(const ThermalSection* fixed, const Options& opt, const Coverage& cover) {
  return fixed                        ? fixed->T_ref_C
         : std::isfinite(opt.T_ref_C) ? opt.T_ref_C
                                      : std::round((cover.T_lo_C + cover.T_hi_C)) / 2.0;
}

// Each coefficient's model, none where its fit failed (with why).
struct Models {
  std::array<std::optional<PolyFit>, kCoefficients> fits;
  std::array<std::string, kCoefficients> fit_error;
  // Coefficient i's model at temperature T (C) and rate (C/min), JSON units; `fallback` without one.
  double value_at(std::size_t i, double T, double rate, double T_ref, double fallback) const {
    const std::optional<PolyFit>& f = fits[i];
    return f ? f->constant + f->poly.eval(T - T_ref, rate) : fallback;
  }
};

// A given model (evaluate, refit_constants) as a fit: its shape, and its constant the input
// model's or, refitting the constants, this run's level: the mean of what the shape leaves of the
// used estimates, with its standard error.
PolyFit given_model(const Coefficient& k, const ThermalSection& fixed, const ImuModel& input,
                    const std::vector<Row>& rows, double T_ref, bool refit_constants) {
  const auto i = static_cast<std::size_t>(k.index);
  PolyFit f;
  f.poly = fixed.poly[i];
  f.constant = get(input.gyro, input.accel, k);
  f.T_degree = static_cast<int>(f.poly.T.size());
  f.rate_degree = static_cast<int>(f.poly.dTdt.size());
  if (refit_constants) {
    // The shape of the earlier models, the level of this run: the mean of what is left.
    double sum = 0, sq = 0;
    int n = 0;
    for (const Row& r : rows)
      if (r.use[i]) {
        const double d = r.value[i] - f.poly.eval(r.T[i] - T_ref, r.rate[i]);
        sum += d;
        sq += d * d;
        ++n;
      }
    if (n >= 2) {
      f.constant = sum / n;
      f.constant_sigma = std::sqrt(std::max(0.0, sq / n - f.constant * f.constant) / (n - 1));
      f.samples = n;
    }
  }
  return f;
}

// The models of every coefficient over the used estimates: the given ones (fixed), or fitted,
// each with its degrees chosen at its group's resolution.
Models fit_models(const std::vector<Row>& rows, double T_ref, const ImuModel& input, const Options& opt,
                  const ThermalSection* fixed, bool refit_constants) {
  Models out;
  for (const Coefficient& k : coefficients()) {
    const auto i = static_cast<std::size_t>(k.index);
    if (fixed) {
      out.fits[i] = given_model(k, *fixed, input, rows, T_ref, refit_constants);
      continue;
    }
    std::vector<Sample> samples;
    for (const Row& r : rows)
      if (r.use[i]) samples.push_back({r.T[i], r.rate[i], r.value[i]});
    FitOptions fo = opt.fit;
    for (std::size_t g = 0; g < groups().size(); ++g)
      if (std::string(groups()[g]) == k.group) fo.resolution = opt.resolution[g];
    try {
      out.fits[i] = fit_polynomial(samples, T_ref, fo);
    } catch (const std::exception& ex) {
      out.fits[i].reset();
      out.fit_error[i] = ex.what();
    }
  }
  return out;
}

// A coefficient that changes inside a cycle leaks into the estimates of the others the same
// stage-1 equations determine (a drifting angle into a bias through the rotations, a drifting
// scale factor into a bias through a position held at +-g). With the models fitted, predict
// that leak from the cycle's own design and remove it from the row's values.
void remove_leaks(Row& r, const CycleEstimate& e, const Models& models, double T_ref) {
  for (std::size_t row = 0; row < e.design.size(); ++row) {
    const CycleEstimate::Design& d = e.design[row];
    const auto ch = static_cast<std::size_t>(row);  // gyro x y z, accel x y z: the channel order
    const auto n = static_cast<Eigen::Index>(d.interval.size());
    const auto p = static_cast<Eigen::Index>(d.coefficient.size());
    Eigen::MatrixXd X(n, p);  // SI, each coefficient at each interval, from the models
    for (Eigen::Index q = 0; q < n; ++q)
      for (Eigen::Index c = 0; c < p; ++c) {
        const auto k = static_cast<std::size_t>(d.coefficient[static_cast<std::size_t>(c)]);
        const std::size_t iv = d.interval[static_cast<std::size_t>(q)];
        X(q, c) = models.value_at(k, r.T_iv[ch][iv], r.rate_iv[ch][iv], T_ref, e.value[k]) /
                  coefficients()[k].si_to_json;
      }
    const Eigen::VectorXd readings = (d.A.cwiseProduct(X)).rowwise().sum();
    const Eigen::VectorXd predicted = d.K * readings;
    for (Eigen::Index c = 0; c < p; ++c) {
      const auto k = static_cast<std::size_t>(d.coefficient[static_cast<std::size_t>(c)]);
      double own = 0;
      for (Eigen::Index q = 0; q < n; ++q) own += e.weight[k][d.interval[static_cast<std::size_t>(q)]] * X(q, c);
      r.value[k] = e.value[k] - (predicted[c] - own) * coefficients()[k].si_to_json;
    }
  }
}

// The models into the section, their constants and sigmas into the model and `sigma` (a
// coefficient without a model keeps its value, and a note says why); the degrees chosen and
// their scores, for the report.
json store_models(const Models& models, Result& res, ImuErrorSet& sigma) {
  json degrees = json::object();
  for (const Coefficient& k : coefficients()) {
    const auto i = static_cast<std::size_t>(k.index);
    const std::optional<PolyFit>& fit = models.fits[i];
    if (!fit) {
      res.notes.push_back(full_key(k) + ": no model (" + models.fit_error[i] + "); its value is carried over");
      continue;
    }
    const PolyFit& f = *fit;
    res.section.poly[i] = f.poly;
    set(res.model.gyro, res.model.accel, k, f.constant);
    set(sigma.gyro, sigma.accel, k, f.constant_sigma);
    json table = json::array();
    for (const DegreeScore& sc : f.scores)
      table.push_back({{"T", sc.T_degree}, {"dTdt", sc.rate_degree}, {"fit_rms", sc.fit_rms}, {"cv_rms", sc.cv_rms}});
    degrees[full_key(k)] = {{"T_degree", f.T_degree}, {"dTdt_degree", f.rate_degree}, {"cycles", f.samples},
                            {"fit_rms", f.fit_rms}, {"cv_rms", f.cv_rms}, {"per_degree", table}};
  }
  return degrees;
}

// What the stage returns: given models judged as they are (the input model and its section);
// given shapes with this run's constants (the given section over this run's range); or the
// models fitted. Those of this run carry their sigmas and the section as the model's JSON.
void settle_models(Result& res, const ImuModel& input, const ThermalSection* fixed, bool refit_constants,
                   const ImuErrorSet& sigma, const Coverage& cover) {
  if (fixed && !refit_constants) {
    res.model = input;
    res.section = *fixed;
    return;
  }
  if (fixed) {
    res.section = *fixed;
    res.section.fitted_T_C = std::array<double, 2>{cover.T_lo_C, cover.T_hi_C};
    res.section.fitted_rate_C_per_min = std::array<double, 2>{cover.rate_lo_C_per_min, cover.rate_hi_C_per_min};
  }
  res.model.sigma = sigma;
  res.model.thermal_json = thermal_to_json_text(res.section);
}

// The truth of a simulated run at a time, JSON units: its constant and, with a thermal section,
// its models at the temperatures and rates then (and a stabiliser's oscillation of the gyro
// biases). The judge reads the rates on a window of its own, short enough to follow the fastest
// thermal cycle a simulated run has (a stabiliser's, ~17 min) to a fraction of a percent: with
// the model's own window it would share the model's smoothing and could not see what it costs.
class TruthAt {
 public:
  TruthAt(ImuModel truth, const std::vector<TempSample>& temps)
      : truth_(std::move(truth)), thermal_(thermal_of(truth_)) {
    if (thermal_) series_.emplace(temps, kJudgeHalfWindow_s);
  }
  double operator()(const Coefficient& k, double t) const {
    double v = get(truth_.gyro, truth_.accel, k);
    if (!thermal_ || !series_) return v;  // the two go together
    const ThermalSection& th = *thermal_;
    const int ch = channel_of(k);
    const double rate = series_->rate(ch, t);
    v += th.poly[static_cast<std::size_t>(k.index)].eval(series_->value(ch, t) - th.T_ref_C, rate);
    if (th.sim_oscillation && k.index < 3) v += oscillation_dph(*th.sim_oscillation, k.index, t, rate);
    return v;
  }

 private:
  ImuModel truth_;
  std::optional<ThermalSection> thermal_;
  std::optional<TempSeries> series_;
};

// The truth as cycle e's estimate of coefficient k sees it: each interval's mean of the truth, on
// a grid fine against the thermal time constants, by the estimate's weight of the interval.
double truth_of_estimate(const TruthAt& truth_at, const Coefficient& k, const CycleEstimate& e) {
  const auto i = static_cast<std::size_t>(k.index);
  double tv = 0;
  for (std::size_t s = 0; s < e.spans.size(); ++s) {
    const double a = e.spans[s][0], b = e.spans[s][1];
    const int m = std::max(1, static_cast<int>(std::ceil((b - a) / 2.0)));
    double mean = 0;
    for (int q = 0; q < m; ++q) mean += truth_at(k, a + (b - a) * (q + 0.5) / m) / m;
    tv += e.weight[i][s] * mean;
  }
  return tv;
}

// The truth check, per group of coefficients, JSON units: the largest difference over the used
// estimates of the models (residual) and of the input model (before) from the truth of a
// simulated run, and from the per-cycle estimates (_est); the estimates' own error and the
// truth's peak to peak; and each coefficient's points for the report's plots.
struct Judgement {
  std::map<std::string, double> residual, before, residual_est, before_est, est_error, truth_p2p;
  json plots = json::object();
};
struct JudgeInputs {
  const std::vector<Row>& rows;
  const std::vector<CycleEstimate>& cycles;
  const Models& models;
  const ImuModel& input;  // the model before this stage
  const ImuModel& model;  // the stage's
  double T_ref;
  const TruthAt* truth_at;  // null for a real run
};
void judge_coefficient(const Coefficient& k, const JudgeInputs& in, Judgement& out) {
  const auto i = static_cast<std::size_t>(k.index);
  const std::string g = k.group;
  const double input_value = get(in.input.gyro, in.input.accel, k);
  const double constant = get(in.model.gyro, in.model.accel, k);
  const std::optional<PolyFit>& fit = in.models.fits[i];
  json pts = json::array();
  double lo = 1e300, hi = -1e300;
  for (const Row& r : in.rows) {
    if (!r.use[i]) continue;
    const CycleEstimate& e = in.cycles[r.cycle];
    const double thermal_part = fit ? fit->poly.eval(r.T[i] - in.T_ref, r.rate[i]) : 0.0;
    const double model_value = constant + thermal_part;
    const double est = r.value[i];
    out.residual_est[g] = std::max(out.residual_est[g], std::abs(model_value - est));
    out.before_est[g] = std::max(out.before_est[g], std::abs(input_value - est));
    json truth_value = nullptr;
    if (in.truth_at) {
      const double tv = truth_of_estimate(*in.truth_at, k, e);
      out.residual[g] = std::max(out.residual[g], std::abs(model_value - tv));
      out.before[g] = std::max(out.before[g], std::abs(input_value - tv));
      out.est_error[g] = std::max(out.est_error[g], std::abs(est - tv));
      lo = std::min(lo, tv);
      hi = std::max(hi, tv);
      truth_value = tv;
    }
    pts.push_back({e.name, 0.5 * (e.t0_s + e.t1_s), r.T[i], r.rate[i], est, e.sigma[i], est - thermal_part,
                   model_value, truth_value, e.value[i]});
  }
  if (hi >= lo) out.truth_p2p[g] = std::max(out.truth_p2p[g], hi - lo);
  out.plots[full_key(k)] = pts;
}
Judgement judge_models(const JudgeInputs& in) {
  Judgement out;
  for (const char* g : groups())
    out.residual[g] = out.before[g] = out.residual_est[g] = out.before_est[g] = out.est_error[g] = out.truth_p2p[g] = 0.0;
  for (const Coefficient& k : coefficients()) judge_coefficient(k, in, out);
  return out;
}

json by_group(const std::map<std::string, double>& m) {
  json j = json::object();
  for (const auto& [k, v] : m) j[k] = v;
  return j;
}

// The stage's report (imucal-thermal-report/1): the truth check against the truth when the run
// has one, else against the per-cycle estimates; the cycles used and left out, the coverage, the
// degrees, the notes, the temperature problems and the plots.
struct ReportParts {
  const json& left_out;
  const json& coverage;
  const json& degrees;
  double T_ref;
  bool with_truth;
  const char* models;  // fitted, given, or given shape with constants fitted
};
std::string report_text(const Result& res, const Judgement& j, const ReportParts& parts) {
  const bool truth = parts.with_truth;
  json report = {{"format", "imucal-thermal-report/1"},
                 {"residual_source", truth ? "truth" : "per-cycle estimates"},
                 {"residual", by_group(truth ? j.residual : j.residual_est)},
                 {"before", by_group(truth ? j.before : j.before_est)},
                 {"residual_vs_estimates", by_group(j.residual_est)},
                 {"before_vs_estimates", by_group(j.before_est)},
                 {"T_ref_C", parts.T_ref},
                 {"cycles", {{"total", res.cycles_total}, {"used", res.cycles_used}, {"left_out", parts.left_out}}},
                 {"coverage", parts.coverage},
                 {"degrees", parts.degrees},
                 {"notes", res.notes}};
  if (truth) {
    report["estimate_error"] = by_group(j.est_error);
    report["truth_peak_to_peak"] = by_group(j.truth_p2p);
  }
  json problems = json::array();
  for (const TempProblem& p : res.problems)
    problems.push_back({{"channel", p.channel}, {"what", p.what}, {"t0_s", p.t0_s}, {"t1_s", p.t1_s}});
  report["problems"] = problems;
  report["plots"] = {{"columns", {"cycle", "t_mid_s", "T_C", "dTdt_C_per_min", "estimate", "sigma", "compensated",
                                  "model", "truth", "raw_estimate"}},
                     {"series", j.plots}};
  report["models"] = parts.models;
  return report.dump();
}

// Fits the models (fixed == nullptr) or takes the given ones, and judges them on the run.
Result run_stage(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                 const std::vector<TempSample>& temps, const ImuModel& input, const Options& opt,
                 const ThermalSection* fixed, bool refit_constants) {
  Result res;
  res.cycles_total = static_cast<int>(cycles.size());
  res.problems = check_temperatures(temps, opt.checks);
  for (const TempProblem& p : res.problems)
    res.notes.push_back(p.channel + " " + p.what + " (" + span_text(p.t0_s, p.t1_s) + ")");
  const TempSeries series(temps, opt.rate_half_window_s);
  if (series.empty()) throw std::runtime_error("stage thermal: the run has no temperature samples");

  RowSelection selection = select_rows(cycles, res.problems, series, opt);
  res.notes.insert(res.notes.end(), selection.notes.begin(), selection.notes.end());
  std::vector<Row>& rows = selection.rows;

  // Reference temperature and coverage over the used estimates.
  const Coverage cover = coverage_of(rows);
  res.cycles_used = cover.used_cycles;
  if (cover.used_cycles < 3)
    throw std::runtime_error("stage thermal: " + std::to_string(cover.used_cycles) + " usable cycles of " +
                             std::to_string(cycles.size()) + " (need 3 at least); see the notes above");
  const double T_ref = reference_temperature_C(fixed, opt, cover);
  const json coverage = coverage_report(cover, opt, res.notes);

  // Fits.
  res.model = input;
  ImuErrorSet sigma = input.sigma.value_or(ImuErrorSet{});
  res.section.T_ref_C = T_ref;
  res.section.fitted_T_C = std::array<double, 2>{cover.T_lo_C, cover.T_hi_C};
  res.section.fitted_rate_C_per_min = std::array<double, 2>{cover.rate_lo_C_per_min, cover.rate_hi_C_per_min};
  Models models = fit_models(rows, T_ref, input, opt, fixed, refit_constants);
  // The leaks each model predicts out of the estimates, then the models again (see remove_leaks).
  for (int iter = 0; iter < (fixed && !refit_constants ? 1 : opt.leak_iterations); ++iter) {
    for (Row& r : rows) remove_leaks(r, cycles[r.cycle], models, T_ref);
    if (!fixed || refit_constants) models = fit_models(rows, T_ref, input, opt, fixed, refit_constants);
  }
  const json degrees = store_models(models, res, sigma);
  settle_models(res, input, fixed, refit_constants, sigma, cover);

  // The judge: the truth of a simulated run, seen through each estimate's own weighting, or the
  // per-cycle estimates of a real one.
  std::optional<TruthAt> truth_at;
  if (!meta.truth_json.empty()) truth_at.emplace(imu_model_from_json_text(meta.truth_json, "the run's truth"), temps);
  const Judgement judged = judge_models({rows, cycles, models, input, res.model, T_ref, truth_at ? &*truth_at : nullptr});
  const char* models_kind = !fixed ? "fitted" : refit_constants ? "given shape, constants fitted" : "given";
  res.report_json = report_text(res, judged, {selection.left_out, coverage, degrees, T_ref, truth_at.has_value(), models_kind});
  return res;
}

}  // namespace

Result calibrate(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                 const std::vector<TempSample>& temps, const ImuModel& input, const Options& options) {
  return run_stage(meta, cycles, temps, input, options, nullptr, false);
}

Result evaluate(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                const std::vector<TempSample>& temps, const ImuModel& model, const Options& options) {
  const std::optional<ThermalSection> s = thermal_of(model);
  if (!s) throw std::runtime_error("stage thermal: the model to judge has no thermal section");
  return run_stage(meta, cycles, temps, model, options, &*s, false);
}

Result refit_constants(const RecordingMeta& meta, const std::vector<CycleEstimate>& cycles,
                       const std::vector<TempSample>& temps, const ImuModel& model, const Options& options) {
  const std::optional<ThermalSection> s = thermal_of(model);
  if (!s) throw std::runtime_error("stage thermal: the model whose shape to keep has no thermal section");
  return run_stage(meta, cycles, temps, model, options, &*s, true);
}

}  // namespace imucal::thermal
