#include "core/table_json.hpp"

#include <cmath>
#include <fstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "core/units.hpp"

namespace imucal::table {

using nlohmann::json;
using ojson = nlohmann::ordered_json;

namespace {

// The small-angle model of CONVENTIONS.md is for arc seconds; a value in degrees or radians by
// mistake would be read as a wildly wrong table rather than refused.
constexpr double kMaxArcsec = 3600.0;
constexpr const char* kAxes[3] = {"outer", "middle", "inner"};

double number_at(const ObjectReader& r, const json& v, const std::string& path) {
  if (!v.is_number()) r.fail(path, "must be a number, not " + json_type_name(v));
  const double x = v.get<double>();
  if (!std::isfinite(x)) r.fail(path, "must be finite");
  return x;
}

double angle_arcsec(const ObjectReader& r, const json& v, const std::string& path, bool is_sigma) {
  const double x = number_at(r, v, path);
  if (std::abs(x) > kMaxArcsec) r.fail(path, "is " + std::to_string(x) + " arcsec; a table's error is arc seconds, at most 3600");
  if (is_sigma && x < 0) r.fail(path, "is a 1-sigma and cannot be negative");
  return x;
}

std::array<double, 2> pair_rad(ObjectReader& r, const char* key, bool is_sigma) {
  const json* v = r.get(key);
  if (v == nullptr) return {0.0, 0.0};
  if (!v->is_array() || v->size() != 2) r.fail(r.at(key), "must be an array of two numbers (arc seconds)");
  std::array<double, 2> out{};
  for (std::size_t i = 0; i < 2; ++i)
    out[i] = angle_arcsec(r, (*v)[i], r.at(key) + "[" + std::to_string(i) + "]", is_sigma) * units::kArcsecToRad;
  return out;
}

std::vector<EncoderHarmonic> harmonics(const ObjectReader& r, const json& v, const std::string& path, bool is_sigma) {
  if (!v.is_array()) r.fail(path, "must be an array of [k, a_arcsec, phi_deg] terms, not " + json_type_name(v));
  std::vector<EncoderHarmonic> out;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const std::string at = path + "[" + std::to_string(i) + "]";
    const json& term = v[i];
    if (!term.is_array() || term.size() != 3) r.fail(at, "must be [k, a_arcsec, phi_deg]");
    const double k = number_at(r, term[0], at + "[0]");
    if (k != std::floor(k) || k < 1 || k > 1000) r.fail(at + "[0]", "the harmonic's order k must be a whole number from 1 to 1000");
    EncoderHarmonic h;
    h.k = static_cast<int>(k);
    h.amplitude_rad = angle_arcsec(r, term[1], at + "[1]", is_sigma) * units::kArcsecToRad;
    const double phi_deg = number_at(r, term[2], at + "[2]");
    if (is_sigma && phi_deg < 0) r.fail(at + "[2]", "is a 1-sigma and cannot be negative");
    h.phase_rad = phi_deg * units::kDegToRad;
    out.push_back(h);
  }
  return out;
}

}  // namespace

TableGeometry read_table_geometry(const json& j, const std::string& where, bool is_sigma) {
  ObjectReader r(j, where, ObjectReader::ThrowAtFirst{});
  TableGeometry g;
  g.outer_tilt_rad = pair_rad(r, "outer_tilt_arcsec", is_sigma);
  g.middle_axis_rad = pair_rad(r, "middle_axis_arcsec", is_sigma);
  g.inner_axis_rad = pair_rad(r, "inner_axis_arcsec", is_sigma);
  if (const json* enc = r.get("encoder_error_arcsec")) {
    ObjectReader er(*enc, r.at("encoder_error_arcsec"), ObjectReader::ThrowAtFirst{});
    for (std::size_t axis = 0; axis < 3; ++axis)
      if (const json* v = er.get(kAxes[axis])) g.encoder_error[axis] = harmonics(er, *v, er.at(kAxes[axis]), is_sigma);
    er.finish();
  }
  r.finish();
  return g;
}

std::optional<TableCertificate> read_table_certificate(ObjectReader& r) {
  const json* geometry = r.get("geometry");
  const json* sigma = r.get("sigma");
  const std::optional<std::string> name = r.string("certificate");
  if (geometry == nullptr && sigma == nullptr && !name) return std::nullopt;
  TableCertificate c;
  if (geometry != nullptr) c.geometry = read_table_geometry(*geometry, r.at("geometry"), false);
  if (sigma != nullptr) c.sigma = read_table_geometry(*sigma, r.at("sigma"), true);
  if (name) c.certificate = *name;
  return c;
}

TableCertificate read_table_certificate_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::parse_error& e) {
    throw std::runtime_error(path + ": not valid JSON: " + e.what());
  }
  const bool recording = j.is_object() && j.contains("table") && j.contains("format");
  std::optional<TableCertificate> c;
  try {
    ObjectReader r(recording ? j.at("table") : j, recording ? "table" : "", ObjectReader::ThrowAtFirst{});
    c = read_table_certificate(r);
    if (!recording) r.finish();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  if (!c) throw std::runtime_error(path + ": names no table geometry, sigma or certificate");
  return *c;
}

ojson table_geometry_to_json(const TableGeometry& g) {
  const auto pair = [](const std::array<double, 2>& v) {
    return ojson::array({v[0] * units::kRadToArcsec, v[1] * units::kRadToArcsec});
  };
  ojson out;
  out["outer_tilt_arcsec"] = pair(g.outer_tilt_rad);
  out["middle_axis_arcsec"] = pair(g.middle_axis_rad);
  out["inner_axis_arcsec"] = pair(g.inner_axis_rad);
  ojson enc = ojson::object();
  for (std::size_t axis = 0; axis < 3; ++axis) {
    ojson terms = ojson::array();
    for (const EncoderHarmonic& h : g.encoder_error[axis])
      terms.push_back({h.k, h.amplitude_rad * units::kRadToArcsec, h.phase_rad / units::kDegToRad});
    enc[kAxes[axis]] = terms;
  }
  out["encoder_error_arcsec"] = enc;
  return out;
}

ojson table_certificate_to_json(const TableCertificate& c) {
  ojson out = ojson::object();
  if (c.geometry) out["geometry"] = table_geometry_to_json(*c.geometry);
  if (c.sigma) out["sigma"] = table_geometry_to_json(*c.sigma);
  if (!c.certificate.empty()) out["certificate"] = c.certificate;
  return out;
}

}  // namespace imucal::table
