// The thermal section, its compensation and the eq. 8 fits.
//
// Why every model is additive (value + polynomial in T + polynomial in dT/dt):
//  - Misalignment angles: the seed's multiplicative C~ = C^ (d + sum d_Tn T^n)(1 + ...) cannot
//    move an angle whose stage-1 value is zero, and the temperature moves angles by tens of arc
//    seconds whatever their value; the polynomial is in arc seconds, added.
//  - Scale factors: M = 1/(1 + s) is within 2e-3 of one, so M^ (c + p(T)) (1 + q(rate)) equals
//    M^ (1 + (c - 1) + p(T) + q(rate)) up to the product p q, below 2e-3 * 1e-4 = 0.2 ppm for the
//    sensitivities the seed reports, and the additive form in ppm is linear in its parameters:
//    plain least squares, and the same shape for every coefficient.
//  - Biases: eq. 8 is already additive.
#include "estimators/thermal.hpp"

#include <algorithm>
#include <optional>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "core/model_json.hpp"
#include "core/units.hpp"
#include "estimators/held_back.hpp"

namespace imucal::thermal {

using nlohmann::json;

namespace {

const char* const kAxisName[3] = {"x", "y", "z"};

}  // namespace

const std::array<Coefficient, kCoefficients>& coefficients() {
  static const std::array<Coefficient, kCoefficients> table = [] {
    std::array<Coefficient, kCoefficients> t{};
    int i = 0;
    auto add = [&](const char* group, const char* member, bool gyro, int axis, double factor) {
      t[static_cast<std::size_t>(i)] = Coefficient{i, group, member, gyro, axis, factor};
      ++i;
    };
    for (int j = 0; j < 3; ++j) add("gyro.bias_dph", kAxisName[j], true, j, units::kRadpsToDph);
    for (int j = 0; j < 3; ++j) add("gyro.scale_pos_ppm", kAxisName[j], true, j, 1e6);
    for (int j = 0; j < 3; ++j) add("gyro.scale_neg_ppm", kAxisName[j], true, j, 1e6);
    for (const MisalignmentKey& k : kMisalignmentKeys)
      add("gyro.misalignment_arcsec", k.name, true, k.name[0] - 'x', units::kRadToArcsec);
    for (int j = 0; j < 3; ++j) add("accel.bias_mps2", kAxisName[j], false, j, 1.0);
    for (int j = 0; j < 3; ++j) add("accel.scale_ppm", kAxisName[j], false, j, 1e6);
    for (const MisalignmentKey& k : kMisalignmentKeys)
      add("accel.misalignment_arcsec", k.name, false, k.name[0] - 'x', units::kRadToArcsec);
    return t;
  }();
  return table;
}

const std::array<const char*, 7>& groups() {
  static const std::array<const char*, 7> g = {"accel.bias_mps2",    "accel.scale_ppm",    "accel.misalignment_arcsec",
                                               "gyro.bias_dph",      "gyro.scale_pos_ppm", "gyro.scale_neg_ppm",
                                               "gyro.misalignment_arcsec"};
  return g;
}

std::string full_key(const Coefficient& c) { return std::string(c.group) + "." + c.member; }

const char* channel_name(int ch) {
  static const char* const names[kChannels] = {"temp_gx_C", "temp_gy_C", "temp_gz_C",
                                               "temp_ax_C", "temp_ay_C", "temp_az_C"};
  return ch >= 0 && ch < kChannels ? names[ch] : "temp_?";
}

namespace {
// The SI field behind coefficient index i (const or not, one mapping for get and set).
template <class G, class A>
auto field(G& g, A& a, int i) -> decltype(&g.bias_radps[0]) {
  if (i < 3) return &g.bias_radps[i];
  if (i < 6) return &g.scale_pos[i - 3];
  if (i < 9) return &g.scale_neg[i - 6];
  if (i < 15) return &(g.misalignment_rad.*kMisalignmentKeys[static_cast<std::size_t>(i - 9)].member);
  if (i < 18) return &a.bias_mps2[i - 15];
  if (i < 21) return &a.scale[i - 18];
  return &(a.misalignment_rad.*kMisalignmentKeys[static_cast<std::size_t>(i - 21)].member);
}
}  // namespace

double get(const GyroErrors& g, const AccelErrors& a, const Coefficient& c) { return *field(g, a, c.index) * c.si_to_json; }

void set(GyroErrors& g, AccelErrors& a, const Coefficient& c, double v) { *field(g, a, c.index) = v / c.si_to_json; }

// ------------------------------------------------------------------------------------------------
double Poly::eval(double dT, double rate) const {
  double out = 0, p = 1;
  for (double c : T) {
    p *= dT;
    out += c * p;
  }
  p = 1;
  for (double c : dTdt) {
    p *= rate;
    out += c * p;
  }
  return out;
}

double oscillation_dph(const Oscillation& o, int axis, double t_s, double rate) {
  if (o.amplitude_dph == 0.0 || o.period_s <= 0) return 0.0;
  const double span = std::max(1e-12, o.full_C_per_min - o.onset_C_per_min);
  const double x = std::clamp((std::abs(rate) - o.onset_C_per_min) / span, 0.0, 1.0);
  const double gate = x * x * (3.0 - 2.0 * x);
  const double phase = o.phase_deg[static_cast<std::size_t>(axis)] * units::kDegToRad;
  return o.amplitude_dph * gate * std::sin(2.0 * units::kPi * t_s / o.period_s + phase);
}

bool ThermalSection::has_models() const {
  return std::any_of(poly.begin(), poly.end(), [](const Poly& p) { return !p.empty(); });
}

// ------------------------------------------------------------------------------------------------
// JSON

namespace {

// The section is read with the one strict reader (core/json_reader.hpp) and the model's helpers
// (core/model_json.hpp), throwing at the first problem as a std::runtime_error.
using model_json::num;

std::vector<double> numbers(const ObjectReader& r, const json& j, const std::string& where) {
  if (!j.is_array()) r.fail(where, "expected a list of numbers");
  std::vector<double> out;
  for (std::size_t k = 0; k < j.size(); ++k) out.push_back(num(r, j[k], where + "[" + std::to_string(k) + "]"));
  return out;
}

std::array<double, 2> range(const ObjectReader& r, const json& j, const std::string& where) {
  const auto v = numbers(r, j, where);
  if (v.size() != 2 || v[0] > v[1]) r.fail(where, "expected [low, high]");
  return {v[0], v[1]};
}

// Coefficient index from triad, group key within the triad and member.
int index_of(bool gyro, const std::string& group_key, const std::string& member) {
  for (const Coefficient& c : coefficients()) {
    const std::string g = c.group;
    const std::string prefix = gyro ? "gyro." : "accel.";
    if (c.gyro == gyro && g == prefix + group_key && member == c.member) return c.index;
  }
  return -1;
}

}  // namespace

namespace {

ThermalSection thermal_from(const json& j, const ObjectReader::ThrowAtFirst& throwing) {
  ObjectReader r(j, "thermal", throwing);
  ThermalSection s;
  if (const auto format = r.string("format"); format && *format != "imucal-thermal/1")
    r.fail(r.at("format"), "expected \"imucal-thermal/1\"");
  if (const auto t = r.number("T_ref_C")) s.T_ref_C = *t;
  if (const auto unit = r.string("dTdt_unit"); unit && *unit != "C/min")
    r.fail(r.at("dTdt_unit"), "only \"C/min\" is defined (the rate polynomials are in C/min)");
  if (const json* v = r.get("fitted_T_C")) s.fitted_T_C = range(r, *v, r.at("fitted_T_C"));
  if (const json* v = r.get("fitted_dTdt_C_per_min"))
    s.fitted_rate_C_per_min = range(r, *v, r.at("fitted_dTdt_C_per_min"));
  r.get("comment");
  for (const bool gyro : {true, false}) {
    const char* triad = gyro ? "gyro" : "accel";
    const json* tj = r.get(triad);
    if (tj == nullptr) continue;
    ObjectReader t(*tj, r.at(triad), throwing);
    const auto groups = gyro ? std::vector<const char*>{"bias_dph", "scale_pos_ppm", "scale_neg_ppm", "misalignment_arcsec"}
                             : std::vector<const char*>{"bias_mps2", "scale_ppm", "misalignment_arcsec"};
    for (const char* group : groups) {
      const json* members = t.get(group);
      if (members == nullptr) continue;
      ObjectReader g(*members, t.at(group), throwing);
      for (const auto& [member, entry] : members->items()) {
        const int i = index_of(gyro, group, member);
        if (i < 0) g.fail(g.at(member.c_str()), "unknown axis (x, y, z; angles xy, xz, yx, yz, zx, zy)");
        ObjectReader e(g.required(member.c_str()), g.at(member.c_str()), throwing);
        Poly& p = s.poly[static_cast<std::size_t>(i)];
        if (const json* v = e.get("T")) p.T = numbers(e, *v, e.at("T"));
        if (const json* v = e.get("dTdt")) p.dTdt = numbers(e, *v, e.at("dTdt"));
        e.finish();
      }
    }
    t.finish();
  }
  if (const json* oj = r.get("sim_oscillation")) {
    ObjectReader o(*oj, r.at("sim_oscillation"), throwing);
    Oscillation osc;
    if (const auto v = o.number("gyro_bias_amplitude_dph")) osc.amplitude_dph = *v;
    if (const auto v = o.number("period_s")) osc.period_s = *v;
    if (const auto v = o.number("onset_C_per_min")) osc.onset_C_per_min = *v;
    if (const auto v = o.number("full_C_per_min")) osc.full_C_per_min = *v;
    if (const json* v = o.get("phase_deg")) {
      const auto ph = numbers(o, *v, o.at("phase_deg"));
      if (ph.size() != 3) o.fail(o.at("phase_deg"), "expected three numbers (gyro x, y, z)");
      osc.phase_deg = {ph[0], ph[1], ph[2]};
    }
    o.finish();
    if (osc.period_s <= 0) o.fail(o.at("period_s"), "must be positive");
    if (osc.full_C_per_min <= osc.onset_C_per_min) o.fail(o.where(), "full_C_per_min must exceed onset_C_per_min");
    s.sim_oscillation = osc;
  }
  r.finish();
  return s;
}

}  // namespace

ThermalSection parse_thermal(const std::string& text, const std::string& where0) {
  return model_json::read_model_text(text, where0 + ": thermal",
                                     [&](const json& j) { return thermal_from(j, ObjectReader::ThrowAtFirst{where0 + ": "}); });
}

std::string thermal_to_json_text(const ThermalSection& s) {
  json j = {{"format", "imucal-thermal/1"}, {"T_ref_C", s.T_ref_C}, {"dTdt_unit", "C/min"}};
  if (s.fitted_T_C) j["fitted_T_C"] = {(*s.fitted_T_C)[0], (*s.fitted_T_C)[1]};
  if (s.fitted_rate_C_per_min) j["fitted_dTdt_C_per_min"] = {(*s.fitted_rate_C_per_min)[0], (*s.fitted_rate_C_per_min)[1]};
  for (const Coefficient& c : coefficients()) {
    const Poly& p = s.poly[static_cast<std::size_t>(c.index)];
    if (p.empty()) continue;
    const std::string group = c.group;
    const std::string triad = c.gyro ? "gyro" : "accel";
    const std::string key = group.substr(triad.size() + 1);
    json e = json::object();
    if (!p.T.empty()) e["T"] = p.T;
    if (!p.dTdt.empty()) e["dTdt"] = p.dTdt;
    j[triad][key][c.member] = e;
  }
  if (s.sim_oscillation) {
    const Oscillation& o = *s.sim_oscillation;
    j["sim_oscillation"] = {{"gyro_bias_amplitude_dph", o.amplitude_dph},
                            {"period_s", o.period_s},
                            {"onset_C_per_min", o.onset_C_per_min},
                            {"full_C_per_min", o.full_C_per_min},
                            {"phase_deg", o.phase_deg}};
  }
  return j.dump();
}

std::optional<ThermalSection> thermal_of(const ImuModel& m) {
  if (m.thermal_json.empty()) return std::nullopt;
  return parse_thermal(m.thermal_json, "model");
}

void apply_thermal(const ThermalSection& s, const ChannelTemps& t, GyroErrors& g, AccelErrors& a) {
  for (const Coefficient& c : coefficients()) {
    const Poly& p = s.poly[static_cast<std::size_t>(c.index)];
    if (p.empty()) continue;
    const int ch = channel_of(c);
    *field(g, a, c.index) += p.eval(t.T_C[ch] - s.T_ref_C, t.rate_C_per_min[ch]) / c.si_to_json;
  }
}

// ------------------------------------------------------------------------------------------------
void ChannelRate::push(const TempSample& s) {
  Entry e;
  e.t_s = static_cast<double>(s.t_ns) * 1e-9;
  e.T_C << s.gyro_C, s.accel_C;
  if (!e.T_C.allFinite()) return;  // a missing reading: keep the last good ones
  samples_.push_back(e);
  while (samples_.size() > 2 && samples_.front().t_s < e.t_s - window_s_) samples_.pop_front();
}

ChannelTemps ChannelRate::current() const {
  ChannelTemps out;
  if (samples_.empty()) return out;
  out.T_C = samples_.back().T_C;
  const auto n = static_cast<double>(samples_.size());
  if (samples_.size() < 2) return out;
  double tm = 0;
  for (const Entry& e : samples_) tm += e.t_s / n;
  double stt = 0;
  Eigen::Matrix<double, kChannels, 1> sty = Eigen::Matrix<double, kChannels, 1>::Zero();
  for (const Entry& e : samples_) {
    const double dt = e.t_s - tm;
    stt += dt * dt;
    sty += dt * e.T_C;
  }
  if (stt > 0) out.rate_C_per_min = sty / stt * 60.0;
  return out;
}

// ------------------------------------------------------------------------------------------------
// Fits

namespace {

struct Design {
  double T_ref, T_scale, rate_scale;
  // Columns: 1, x, x^2, .., r, r^2, .. with x = (T - T_ref)/T_scale, r = rate/rate_scale, so that
  // every column is O(1) and the solve sees the geometry, not the units.
  Eigen::RowVectorXd row(const Sample& s, int nT, int nR) const {
    Eigen::RowVectorXd r(1 + nT + nR);
    r[0] = 1.0;
    const double x = (s.T_C - T_ref) / T_scale, q = s.rate_C_per_min / rate_scale;
    double p = 1;
    for (int k = 0; k < nT; ++k) r[1 + k] = (p *= x);
    p = 1;
    for (int k = 0; k < nR; ++k) r[1 + nT + k] = (p *= q);
    return r;
  }
};

struct Solved {
  Eigen::VectorXd x;
  bool ok = false;
};

Solved solve(const std::vector<const Sample*>& rows, const std::vector<double>& w, const Design& d, int nT, int nR) {
  const int p = 1 + nT + nR;
  const auto n = static_cast<Eigen::Index>(rows.size());
  Eigen::MatrixXd A(n, p);
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double sw = std::sqrt(w[static_cast<std::size_t>(i)]);
    A.row(i) = sw * d.row(*rows[static_cast<std::size_t>(i)], nT, nR);
    b[i] = sw * rows[static_cast<std::size_t>(i)]->value;
  }
  Solved s;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  qr.setThreshold(1e-9);  // columns are O(1): anything smaller is not in the data
  if (qr.rank() < p) return s;
  s.x = qr.solve(b);
  s.ok = s.x.allFinite();
  return s;
}

// The design's scales: the largest distance from T_ref and the largest rate (not below 1e-3 C
// and 1e-4 C/min), so that the columns are of order one.
Design design_for(const std::vector<Sample>& samples, double T_ref_C) {
  Design d{T_ref_C, 0.0, 0.0};
  for (const Sample& s : samples) {
    d.T_scale = std::max(d.T_scale, std::abs(s.T_C - T_ref_C));
    d.rate_scale = std::max(d.rate_scale, std::abs(s.rate_C_per_min));
  }
  d.T_scale = std::max(d.T_scale, 1e-3);
  d.rate_scale = std::max(d.rate_scale, 1e-4);
  return d;
}

struct Candidate {
  DegreeScore score;
  held_back::Score held;  // held-back squared residuals, per sample
};

// The polynomial of degrees (nT, nR) fitted to every sample, and each sample predicted by the
// fit of the folds that hold it back; none when a fit fails or a fold is too small.
std::optional<Candidate> cross_validate(const std::vector<Sample>& samples, const std::vector<double>& w, const Design& d,
                                        int nT, int nR, int folds) {
  const std::size_t n = samples.size();
  const int p = 1 + nT + nR;
  std::vector<const Sample*> all;
  for (const Sample& s : samples) all.push_back(&s);
  const Solved full = solve(all, w, d, nT, nR);
  if (!full.ok) return std::nullopt;
  Candidate c{{nT, nR, 0.0, 0.0}, {p, std::vector<double>(n, 0.0)}};
  double ss = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = samples[i].value - d.row(samples[i], nT, nR).dot(full.x);
    ss += r * r;
  }
  c.score.fit_rms = std::sqrt(ss / static_cast<double>(n));
  for (int f = 0; f < folds; ++f) {
    std::vector<const Sample*> train;
    std::vector<double> wt;
    for (std::size_t i = 0; i < n; ++i)
      if (static_cast<int>(i % static_cast<std::size_t>(folds)) != f) {
        train.push_back(&samples[i]);
        wt.push_back(w[i]);
      }
    if (static_cast<int>(train.size()) <= p) return std::nullopt;
    const Solved part = solve(train, wt, d, nT, nR);
    if (!part.ok) return std::nullopt;
    for (std::size_t i = static_cast<std::size_t>(f); i < n; i += static_cast<std::size_t>(folds)) {
      const double r = samples[i].value - d.row(samples[i], nT, nR).dot(part.x);
      c.held.e2[i] = r * r;
    }
  }
  c.score.cv_rms = std::sqrt(c.held.mean_e2());
  return c;
}

// The chosen degrees fitted to every sample: the polynomial in physical units, and the constant's
// sigma from (A'WA)^-1 scaled by the weighted residual variance.
void fit_chosen(const std::vector<Sample>& samples, const std::vector<double>& w, const Design& d, PolyFit& out) {
  const std::size_t n = samples.size();
  std::vector<const Sample*> all;
  for (const Sample& s : samples) all.push_back(&s);
  const Solved full = solve(all, w, d, out.T_degree, out.rate_degree);
  const int p = 1 + out.T_degree + out.rate_degree;
  out.constant = full.x[0];
  for (int k = 0; k < out.T_degree; ++k) out.poly.T.push_back(full.x[1 + k] / std::pow(d.T_scale, k + 1));
  for (int k = 0; k < out.rate_degree; ++k)
    out.poly.dTdt.push_back(full.x[1 + out.T_degree + k] / std::pow(d.rate_scale, k + 1));
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(p, p);
  double wrss = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::RowVectorXd r = d.row(samples[i], out.T_degree, out.rate_degree);
    N += w[i] * r.transpose() * r;
    const double e = samples[i].value - r.dot(full.x);
    wrss += w[i] * e * e;
  }
  const double s0sq = static_cast<double>(n) > p ? wrss / (static_cast<double>(n) - p) : 0.0;
  const Eigen::MatrixXd Ninv = N.ldlt().solve(Eigen::MatrixXd::Identity(p, p));
  out.constant_sigma = std::sqrt(std::max(0.0, Ninv(0, 0) * s0sq));
}

}  // namespace

PolyFit fit_polynomial(const std::vector<Sample>& samples, double T_ref_C, const FitOptions& o) {
  const std::size_t n = samples.size();
  if (n < 3) throw std::runtime_error("fit: " + std::to_string(n) + " cycles (need 3 at least)");
  const Design d = design_for(samples, T_ref_C);
  // Equal weights: the per-cycle sigmas of stage 1 grow with the drift inside a cycle while the
  // chamber ramps (its residuals are no longer noise), and those are the cycles that carry the
  // dT/dt information.
  const std::vector<double> w(n, 1.0);
  std::vector<Candidate> cands;
  const int folds = std::max(2, o.folds);
  for (int nT = 0; nT <= o.max_T_degree; ++nT)
    for (int nR = 0; nR <= o.max_rate_degree; ++nR) {
      if (static_cast<double>(n) < o.min_samples_per_parameter * (1 + nT + nR)) continue;
      if (auto c = cross_validate(samples, w, d, nT, nR, folds)) cands.push_back(std::move(*c));
    }
  if (cands.empty()) throw std::runtime_error("fit: no polynomial could be fitted to " + std::to_string(n) + " cycles");

  // The simplest model that predicts held-back cycles as well as the best one, within the noise
  // of that comparison: a higher degree must earn its place.
  std::vector<held_back::Score> held;
  for (const Candidate& c : cands) held.push_back(c.held);
  const Candidate* chosen = &cands[held_back::choose(held, {o.standard_errors, o.min_improvement, o.resolution})];

  PolyFit out;
  out.T_degree = chosen->score.T_degree;
  out.rate_degree = chosen->score.rate_degree;
  out.fit_rms = chosen->score.fit_rms;
  out.cv_rms = chosen->score.cv_rms;
  out.samples = static_cast<int>(n);
  for (const Candidate& c : cands) out.scores.push_back(c.score);
  fit_chosen(samples, w, d, out);
  return out;
}

}  // namespace imucal::thermal
