#include "motion_programs/program.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

#include "core/units.hpp"

namespace imucal::motion {

using nlohmann::json;
using units::kDegToRad;
using units::kPi;
using units::kRadToDeg;

namespace {

// Quintic smoothstep: 0 -> 1 with zero first and second derivatives at both ends.
void smoothstep(double x, double& s, double& ds, double& dds) {
  s = x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
  ds = 30.0 * x * x * (1.0 - x) * (1.0 - x);
  dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x);
}

}  // namespace

void AxisFunc::eval(double tau, double& angle, double& rate, double& accel) const {
  switch (kind) {
    case Kind::Const:
      angle = theta0;
      rate = 0.0;
      accel = 0.0;
      return;
    case Kind::Cycloid: {
      // Cycloidal move: rate 0 and acceleration 0 at both ends, peak rate 2*delta/T.
      const double u = tau / duration, w = 2.0 * kPi;
      angle = theta0 + delta * (u - std::sin(w * u) / w);
      rate = delta / duration * (1.0 - std::cos(w * u));
      accel = delta / (duration * duration) * w * std::sin(w * u);
      return;
    }
    case Kind::Quadratic:
      angle = theta0 + omega0 * tau + 0.5 * alpha * tau * tau;
      rate = omega0 + alpha * tau;
      accel = alpha;
      return;
    case Kind::Sine: {
      // theta0 + A e(tau) (sin(w tau + phi) - sin phi): starts at theta0, returns after whole cycles.
      double e = 1.0, de = 0.0, dde = 0.0;
      if (ramp > 0.0) {
        if (tau < ramp) {
          smoothstep(tau / ramp, e, de, dde);
          de /= ramp;
          dde /= ramp * ramp;
        } else if (tau > duration - ramp) {
          smoothstep((duration - tau) / ramp, e, de, dde);
          de = -de / ramp;
          dde /= ramp * ramp;
        }
      }
      const double s = std::sin(omega * tau + phase) - std::sin(phase);
      const double ds = omega * std::cos(omega * tau + phase);
      const double dds = -omega * omega * std::sin(omega * tau + phase);
      angle = theta0 + amp * e * s;
      rate = amp * (de * s + e * ds);
      accel = amp * (dde * s + 2.0 * de * ds + e * dds);
      return;
    }
  }
}

std::vector<SegmentInfo> Program::segments() const {
  std::vector<SegmentInfo> out;
  for (const Piece& p : pieces) {
    if (!out.empty() && out.back().name == p.segment && out.back().kind == p.kind) {
      out.back().t1_s = p.t1_s;
    } else {
      out.push_back({p.segment, p.kind, p.t0_s, p.t1_s});
    }
  }
  return out;
}

table::AxisState Program::evaluate(double t_s) const {
  std::size_t cursor = 0;
  return evaluate(t_s, cursor);
}

table::AxisState Program::evaluate(double t_s, std::size_t& cursor) const {
  table::AxisState st;
  if (pieces.empty()) return st;
  bool at_rest = false;
  if (t_s <= pieces.front().t0_s) {
    cursor = 0;
    t_s = pieces.front().t0_s;
    at_rest = true;
  } else if (t_s >= pieces.back().t1_s) {
    cursor = pieces.size() - 1;
    t_s = pieces.back().t1_s;
    at_rest = true;
  } else {
    if (cursor >= pieces.size()) cursor = 0;
    if (pieces[cursor].t0_s > t_s || pieces[cursor].t1_s <= t_s) {
      // Try the next piece first (sequential use), else binary search.
      if (cursor + 1 < pieces.size() && pieces[cursor + 1].t0_s <= t_s && t_s < pieces[cursor + 1].t1_s) {
        ++cursor;
      } else {
        auto it = std::upper_bound(pieces.begin(), pieces.end(), t_s,
                                   [](double t, const Piece& p) { return t < p.t1_s; });
        cursor = static_cast<std::size_t>(it - pieces.begin());
        if (cursor >= pieces.size()) cursor = pieces.size() - 1;
      }
    }
  }
  const Piece& p = pieces[cursor];
  const double tau = t_s - p.t0_s;
  for (int a = 0; a < 3; ++a) {
    double angle, rate, accel;
    p.axis[static_cast<std::size_t>(a)].eval(tau, angle, rate, accel);
    st.angle_rad[a] = angle;
    st.rate_radps[a] = at_rest ? 0.0 : rate;
    st.accel_radps2[a] = at_rest ? 0.0 : accel;
  }
  return st;
}

std::vector<double> Program::breakpoints_s() const {
  std::vector<double> out;
  for (const Piece& p : pieces) {
    out.push_back(p.t0_s);
    for (const AxisFunc& f : p.axis)
      if (f.kind == AxisFunc::Kind::Sine && f.ramp > 0.0) {
        out.push_back(p.t0_s + f.ramp);
        out.push_back(p.t1_s - f.ramp);
      }
  }
  if (!pieces.empty()) out.push_back(pieces.back().t1_s);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

AxisFunc AxisFunc::constant(double theta0_rad) {
  AxisFunc f;
  f.kind = Kind::Const;
  f.theta0 = theta0_rad;
  return f;
}

AxisFunc AxisFunc::quadratic(double theta0_rad, double omega0_rps, double alpha_rps2) {
  AxisFunc f;
  f.kind = Kind::Quadratic;
  f.theta0 = theta0_rad;
  f.omega0 = omega0_rps;
  f.alpha = alpha_rps2;
  return f;
}

AxisFunc AxisFunc::rebased(double dt_s) const {
  AxisFunc g = *this;
  switch (kind) {
    case Kind::Const: break;
    case Kind::Quadratic: {
      double angle, rate, accel;
      eval(dt_s, angle, rate, accel);
      g.theta0 = angle;
      g.omega0 = rate;
      break;
    }
    case Kind::Sine: {
      // theta0 + A (sin(w (tau + dt) + phi) - sin phi) = theta0' + A (sin(w tau + phi') - sin phi')
      const double phi2 = std::remainder(phase + omega * dt_s, 2.0 * kPi);
      g.theta0 = theta0 + amp * (std::sin(phi2) - std::sin(phase));
      g.phase = phi2;
      break;
    }
    case Kind::Cycloid: break;
  }
  return g;
}

// ---------------------------------------------------------------------------------------------
// Compilation from JSON

namespace {

struct Builder {
  const TableLimits& limits;
  Program program;
  Eigen::Vector3d pose_rad = Eigen::Vector3d::Zero();
  double t_s = 0.0;

  [[noreturn]] static void fail(const std::string& where, const std::string& what) {
    throw std::invalid_argument("program " + where + ": " + what);
  }

  // The segment's keys are read through the one strict reader (core/json_reader.hpp): every key
  // read is known, any other is refused by finish() in compile_program().
  static Eigen::Vector3d angles3(const json& a, const std::string& where) {
    if (!a.is_array() || a.size() != 3) fail(where, "expected [outer, middle, inner] in degrees");
    Eigen::Vector3d v;
    for (std::size_t k = 0; k < 3; ++k) {
      if (!a[k].is_number()) fail(where, "angles must be numbers");
      v[static_cast<Eigen::Index>(k)] = a[k].get<double>() * kDegToRad;
    }
    return v;
  }
  static int axis_named(const json* v, const char* key, const std::string& where) {
    if (v == nullptr || !v->is_string()) fail(where, std::string("missing \"") + key + "\" (outer, middle or inner)");
    const std::string name = v->get<std::string>();
    for (int a = 0; a < 3; ++a)
      if (name == kAxisNames[static_cast<std::size_t>(a)]) return a;
    fail(where, "unknown axis \"" + name + "\" (outer, middle or inner)");
  }
  static int axis_index(ObjectReader& seg, const char* key, const std::string& where) {
    return axis_named(seg.get(key), key, where);
  }

  Piece make_piece(double duration_s, const std::string& segment, const std::string& kind) const {
    Piece p;
    p.t0_s = t_s;
    p.t1_s = t_s + duration_s;
    p.segment = segment;
    p.kind = kind;
    for (int a = 0; a < 3; ++a) p.axis[static_cast<std::size_t>(a)] = AxisFunc::constant(pose_rad[a]);
    return p;
  }

  void push(Piece p) {
    // The pose after the piece is where its angle functions end.
    for (int a = 0; a < 3; ++a) {
      double angle, rate, accel;
      p.axis[static_cast<std::size_t>(a)].eval(p.t1_s - p.t0_s, angle, rate, accel);
      pose_rad[a] = angle;
    }
    t_s = p.t1_s;
    program.pieces.push_back(std::move(p));
  }

  void hold(double duration_s, const std::string& name, const std::string& kind, const std::string& where) {
    if (duration_s <= 0) fail(where, "duration_s must be positive");
    push(make_piece(duration_s, name, kind));
  }

  // Shortest cycloidal move within 80 % of the rate and acceleration limits, at least 1 s.
  double auto_move_duration(const Eigen::Vector3d& delta_rad) const {
    double T = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double d = std::abs(delta_rad[a]);
      if (d == 0) continue;
      const AxisLimits& lim = limits.axis[static_cast<std::size_t>(a)];
      T = std::max(T, 2.0 * d / (0.8 * lim.rate_dps * kDegToRad));
      T = std::max(T, std::sqrt(2.0 * kPi * d / (0.8 * lim.accel_dps2 * kDegToRad)));
    }
    return std::ceil(T * 10.0) / 10.0;
  }

  void move(const Eigen::Vector3d& target_rad, double duration_s, const std::string& name) {
    const Eigen::Vector3d delta = target_rad - pose_rad;
    if (delta.cwiseAbs().maxCoeff() < 1e-12) return;
    const double T = duration_s > 0 ? duration_s : auto_move_duration(delta);
    Piece p = make_piece(T, name, "move");
    for (int a = 0; a < 3; ++a) {
      AxisFunc& f = p.axis[static_cast<std::size_t>(a)];
      if (delta[a] == 0) continue;
      f.kind = AxisFunc::Kind::Cycloid;
      f.delta = delta[a];
      f.duration = T;
    }
    push(std::move(p));
  }

  void positions(ObjectReader& seg, const std::string& name, const std::string& kind, const std::string& where) {
    const json* list = seg.get("positions_deg");
    if (list == nullptr || !list->is_array() || list->empty())
      fail(where, "\"positions_deg\" must be a non-empty list of [outer, middle, inner]");
    const double dwell = seg.required_number("dwell_s");
    const double move_s = seg.number("move_s").value_or(0.0);
    int k = 0;
    for (const json& pos : *list) {
      ++k;
      char label[32];
      std::snprintf(label, sizeof label, "-%02d", k);
      const std::string pname = name + label;
      move(angles3(pos, where + " position " + std::to_string(k)), move_s, "to-" + pname);
      hold(dwell, pname, kind, where);
    }
  }

  void rate(ObjectReader& seg, const std::string& name, const std::string& where) {
    const int a = axis_index(seg, "axis", where);
    const double w = seg.required_number("rate_dps") * kDegToRad;
    if (w == 0) fail(where, "rate_dps must not be zero");
    const double acc = seg.number("accel_dps2").value_or(0.5 * limits.axis[static_cast<std::size_t>(a)].accel_dps2) * kDegToRad;
    if (acc <= 0) fail(where, "accel_dps2 must be positive");
    // Beyond the table's limits the ramps are not judged: validate_program names the rate or the
    // acceleration, which is the problem to fix (not the revolutions its ramps would need).
    const AxisLimits& lim = limits.axis[static_cast<std::size_t>(a)];
    const bool beyond_limits = std::abs(w) * kRadToDeg > lim.rate_dps * (1 + 1e-9) || acc * kRadToDeg > lim.accel_dps2 * (1 + 1e-9);
    const double t_ramp = std::abs(w) / acc;
    double t_cruise;
    if (seg.has("revolutions")) {
      const double revs = seg.required_number("revolutions");
      const double ramp_angle = w * w / acc;  // both ramps together
      t_cruise = (revs * 2.0 * kPi - ramp_angle) / std::abs(w);
      if (revs <= 0) fail(where, "revolutions must be positive");
      if (t_cruise < 0 && !beyond_limits) fail(where, "too few revolutions for the ramps at this rate and acceleration");
    } else {
      t_cruise = seg.required_number("duration_s") - 2.0 * t_ramp;
      if (t_cruise < 0 && !beyond_limits) fail(where, "duration_s shorter than the two ramps");
    }
    const double sign = w > 0 ? 1.0 : -1.0;
    Piece up = make_piece(t_ramp, name, "rate");
    up.axis[static_cast<std::size_t>(a)] = AxisFunc::quadratic(pose_rad[a], 0.0, sign * acc);
    push(std::move(up));
    if (t_cruise > 0) {
      Piece cruise = make_piece(t_cruise, name, "rate");
      cruise.axis[static_cast<std::size_t>(a)] = AxisFunc::quadratic(pose_rad[a], w, 0.0);
      push(std::move(cruise));
    }
    Piece down = make_piece(t_ramp, name, "rate");
    down.axis[static_cast<std::size_t>(a)] = AxisFunc::quadratic(pose_rad[a], w, -sign * acc);
    push(std::move(down));
  }

  AxisFunc sine_func(int a, double amp_deg, double period_s, double cycles, double phase_deg, double ramp_s,
                     const std::string& where) const {
    if (period_s <= 0) fail(where, "period_s must be positive");
    if (cycles <= 0) fail(where, "cycles must be positive");
    const double T = period_s * cycles;
    if (ramp_s < 0 || 2 * ramp_s > T) fail(where, "ramp_s must be between 0 and half the segment");
    AxisFunc f;
    f.kind = AxisFunc::Kind::Sine;
    f.theta0 = pose_rad[a];
    f.amp = amp_deg * kDegToRad;
    f.omega = 2.0 * kPi / period_s;
    f.phase = phase_deg * kDegToRad;
    f.duration = T;
    f.ramp = ramp_s;
    return f;
  }

  void sine(ObjectReader& seg, const std::string& name, const std::string& where) {
    const int a = axis_index(seg, "axis", where);
    const double period = seg.required_number("period_s"), cycles = seg.required_number("cycles");
    Piece p = make_piece(period * cycles, name, "sine");
    p.axis[static_cast<std::size_t>(a)] =
        sine_func(a, seg.required_number("amplitude_deg"), period, cycles, seg.number("phase_deg").value_or(90.0),
                  seg.number("ramp_s").value_or(0.0), where);
    push(std::move(p));
  }

  void coning(ObjectReader& seg, const std::string& name, const std::string& where) {
    const json* axes = seg.get("axes");
    if (axes == nullptr || !axes->is_array() || axes->size() != 2) fail(where, "\"axes\" must name two axes");
    const int ia = axis_named(&(*axes)[0], "axes", where), ib = axis_named(&(*axes)[1], "axes", where);
    if (ia == ib) fail(where, "coning needs two different axes");
    double amp_a, amp_b;
    if (seg.has("amplitude_deg") && seg.get("amplitude_deg")->is_array()) {
      const json& am = seg.required("amplitude_deg");
      if (am.size() != 2 || !am[0].is_number() || !am[1].is_number()) fail(where, "amplitude_deg: one number or two");
      amp_a = am[0].get<double>();
      amp_b = am[1].get<double>();
    } else {
      amp_a = amp_b = seg.required_number("amplitude_deg");
    }
    const double period = seg.required_number("period_s"), cycles = seg.required_number("cycles");
    const double ramp = seg.number("ramp_s").value_or(period);
    Piece p = make_piece(period * cycles, name, "coning");
    p.axis[static_cast<std::size_t>(ia)] = sine_func(ia, amp_a, period, cycles, 0.0, ramp, where);
    p.axis[static_cast<std::size_t>(ib)] = sine_func(ib, amp_b, period, cycles, 90.0, ramp, where);
    push(std::move(p));
  }
};

}  // namespace

Program compile_program(const std::string& json_text, const TableLimits& limits) {
  json j;
  try {
    j = json::parse(json_text);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(std::string("program: not valid JSON: ") + e.what());
  }
  Builder b{limits, {}, Eigen::Vector3d::Zero(), 0.0};
  const ObjectReader::ThrowAtFirst throwing{"program "};
  ObjectReader r(j, "", throwing);
  b.program.name = r.string("name").value_or("unnamed");
  b.program.source_json = j.dump();
  if (const json* start = r.get("start_deg")) b.pose_rad = Builder::angles3(*start, "start_deg");
  r.get("comment");
  const json* segments = r.get("segments");
  if (segments == nullptr || !segments->is_array() || segments->empty())
    Builder::fail("", "\"segments\" must be a non-empty list");
  r.finish();
  int index = 0;
  for (const json& seg : *segments) {
    ++index;
    if (!seg.is_object() || !seg.contains("type") || !seg.at("type").is_string())
      Builder::fail("segment " + std::to_string(index), "needs a \"type\"");
    const std::string type = seg.at("type").get<std::string>();
    const std::string name = seg.value("name", type + "-" + std::to_string(index));
    const std::string where = "segment " + std::to_string(index) + " '" + name + "'";
    ObjectReader sr(seg, where, throwing);
    sr.get("type");
    sr.get("name");
    if (type == "hold") {
      b.hold(sr.required_number("duration_s"), name, sr.string("kind").value_or("static"), where);
    } else if (type == "power-cycle") {
      // The IMU is switched off and on before it (imucald prompts the operator and waits); the
      // table rests for duration_s after the power-on.
      b.hold(sr.required_number("duration_s"), name, "power-cycle", where);
    } else if (type == "move") {
      const json* to = sr.get("to_deg");
      if (to == nullptr) Builder::fail(where, "missing \"to_deg\"");
      b.move(Builder::angles3(*to, where), sr.number("duration_s").value_or(0.0), name);
    } else if (type == "positions") {
      b.positions(sr, name, "static", where);
    } else if (type == "tilts") {
      b.positions(sr, name, "tilt", where);
    } else if (type == "rate") {
      b.rate(sr, name, where);
    } else if (type == "sine") {
      b.sine(sr, name, where);
    } else if (type == "coning") {
      b.coning(sr, name, where);
    } else {
      Builder::fail(where, "unknown type \"" + type + "\" (hold, move, positions, tilts, rate, sine, coning, power-cycle)");
    }
    sr.finish();
  }
  return b.program;
}

std::vector<std::string> validate_program(const Program& program, const TableLimits& limits) {
  std::vector<std::string> problems;
  char buf[320];
  auto rate_at = [](const Piece& p, int a, double tau) {
    double angle, rate, accel;
    p.axis[static_cast<std::size_t>(a)].eval(tau, angle, rate, accel);
    return rate;
  };
  for (std::size_t k = 0; k < program.pieces.size(); ++k) {
    const Piece& p = program.pieces[k];
    const double T = p.t1_s - p.t0_s;
    const int n = std::max(200, static_cast<int>(T * 20.0));
    for (int a = 0; a < 3; ++a) {
      const AxisLimits& lim = limits.axis[static_cast<std::size_t>(a)];
      double max_rate = 0, max_accel = 0, lo = 1e300, hi = -1e300;
      for (int i = 0; i <= n; ++i) {
        double angle, rate, accel;
        p.axis[static_cast<std::size_t>(a)].eval(T * i / n, angle, rate, accel);
        max_rate = std::max(max_rate, std::abs(rate));
        max_accel = std::max(max_accel, std::abs(accel));
        lo = std::min(lo, angle);
        hi = std::max(hi, angle);
      }
      const char* axis = kAxisNames[static_cast<std::size_t>(a)];
      if (max_rate * kRadToDeg > lim.rate_dps * (1 + 1e-9)) {
        std::snprintf(buf, sizeof buf, "segment '%s' (t=%.1f s) axis %s: rate %.4g deg/s exceeds the limit %.4g deg/s",
                      p.segment.c_str(), p.t0_s, axis, max_rate * kRadToDeg, lim.rate_dps);
        problems.emplace_back(buf);
      }
      if (max_accel * kRadToDeg > lim.accel_dps2 * (1 + 1e-9)) {
        std::snprintf(buf, sizeof buf,
                      "segment '%s' (t=%.1f s) axis %s: acceleration %.4g deg/s^2 exceeds the limit %.4g deg/s^2",
                      p.segment.c_str(), p.t0_s, axis, max_accel * kRadToDeg, lim.accel_dps2);
        problems.emplace_back(buf);
      }
      if (lo * kRadToDeg < lim.min_deg - 1e-9 || hi * kRadToDeg > lim.max_deg + 1e-9) {
        std::snprintf(buf, sizeof buf,
                      "segment '%s' (t=%.1f s) axis %s: angle range [%.3f, %.3f] deg leaves the limits [%.3f, %.3f] deg",
                      p.segment.c_str(), p.t0_s, axis, lo * kRadToDeg, hi * kRadToDeg, lim.min_deg, lim.max_deg);
        problems.emplace_back(buf);
      }
      // The table cannot change rate in zero time: rates must join across pieces and start and end at rest.
      const double before = k == 0 ? 0.0 : rate_at(program.pieces[k - 1], a, program.pieces[k - 1].t1_s - program.pieces[k - 1].t0_s);
      const double after = rate_at(p, a, 0.0);
      if (std::abs(after - before) > 1e-9) {
        std::snprintf(buf, sizeof buf,
                      "segment '%s' (t=%.1f s) axis %s: the rate jumps by %.3f deg/s at its start "
                      "(start sines at phase 90 or 270 deg, or give a ramp_s)",
                      p.segment.c_str(), p.t0_s, axis, (after - before) * kRadToDeg);
        problems.emplace_back(buf);
      }
      if (k + 1 == program.pieces.size() && std::abs(rate_at(p, a, T)) > 1e-9) {
        std::snprintf(buf, sizeof buf, "segment '%s' axis %s: the program ends with the axis moving at %.3f deg/s",
                      p.segment.c_str(), axis, rate_at(p, a, T) * kRadToDeg);
        problems.emplace_back(buf);
      }
    }
  }
  return problems;
}

Program load_program(const std::string& name_or_path, const TableLimits& limits) {
  const auto names = builtin_program_names();
  if (std::find(names.begin(), names.end(), name_or_path) != names.end())
    return compile_program(builtin_program_json(name_or_path), limits);
  std::ifstream in(name_or_path);
  if (!in) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    throw std::invalid_argument("program '" + name_or_path + "' is neither a built-in (" + list +
                                ") nor a readable file");
  }
  std::stringstream ss;
  ss << in.rdbuf();
  return compile_program(ss.str(), limits);
}

}  // namespace imucal::motion
