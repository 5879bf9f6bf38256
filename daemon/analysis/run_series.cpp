#include "daemon/analysis/run_series.hpp"

#include "core/number_text.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/units.hpp"
#include "motion_programs/program.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

// Minimum and maximum per column of one channel, null where the column has nothing.
struct Envelope {
  std::vector<double> min, max;
  std::vector<bool> seen;
  explicit Envelope(std::size_t n)
      : min(n, std::numeric_limits<double>::infinity()), max(n, -std::numeric_limits<double>::infinity()), seen(n) {}
  void add(std::size_t k, double v) {
    min[k] = std::min(min[k], v);
    max[k] = std::max(max[k], v);
    seen[k] = true;
  }
  json to_json() const {
    json lo = json::array(), hi = json::array();
    for (std::size_t k = 0; k < seen.size(); ++k) {
      lo.push_back(seen[k] ? json(min[k]) : json(nullptr));
      hi.push_back(seen[k] ? json(max[k]) : json(nullptr));
    }
    return {{"min", std::move(lo)}, {"max", std::move(hi)}};
  }
};

}  // namespace

json run_series_json(const storage::RunDb& run, SeriesRange range) {
  if (range.columns < 1 || range.columns > kMaxSeriesColumns)
    throw std::invalid_argument("points must be 1.." + std::to_string(kMaxSeriesColumns) + ", not " +
                                std::to_string(range.columns));
  if (!std::isfinite(range.from_s) || !std::isfinite(range.to_s) || range.from_s < 0 || range.from_s > kMaxSeriesTime_s ||
      range.to_s > kMaxSeriesTime_s)
    throw std::invalid_argument("from_s and to_s must be program seconds from 0 to " + number_text(kMaxSeriesTime_s));
  const auto last_ns = run.last_frame_t_ns();
  const double rate_hz = run.meta().rate_hz;
  json out = {{"format", "imucal-series/1"}, {"rate_hz", rate_hz}, {"columns", range.columns}};
  const double to_s = range.to_s > range.from_s ? range.to_s : (last_ns ? static_cast<double>(*last_ns) / units::kNsPerS : 0.0);
  if (!last_ns || to_s <= range.from_s) {  // nothing recorded (yet) in the range
    out.update({{"from_s", range.from_s}, {"to_s", range.from_s}, {"t_s", json::array()}, {"frames", json::array()}});
    return out;
  }
  const auto t0_ns = static_cast<std::int64_t>(std::llround(range.from_s * units::kNsPerS));
  // One nanosecond past the end, so that the last frame falls in the last column.
  const auto t1_ns = static_cast<std::int64_t>(std::llround(to_s * units::kNsPerS)) + 1;
  const std::vector<storage::PlotColumn> cols = run.decimate(t0_ns, t1_ns, range.columns);
  const std::size_t n = cols.size();

  const double per_frame = rate_hz > 0 ? rate_hz : 1.0;  // increment -> mean rate over the frame
  std::array<Envelope, 9> frame_channels{Envelope(n), Envelope(n), Envelope(n), Envelope(n), Envelope(n),
                                         Envelope(n), Envelope(n), Envelope(n), Envelope(n)};
  json t_s = json::array(), frames = json::array();
  for (std::size_t k = 0; k < n; ++k) {
    t_s.push_back(static_cast<double>(cols[k].t0_ns) / units::kNsPerS);
    frames.push_back(cols[k].frames);
    if (cols[k].frames == 0) continue;
    for (std::size_t c = 0; c < 9; ++c) {
      // dtheta (rad) -> deg/s, dv (m/s) -> m/s^2, table angles as they are.
      const double scale = c < 3 ? per_frame * units::kRadToDeg : c < 6 ? per_frame : 1.0;
      frame_channels[c].add(k, cols[k].min[c] * scale);
      frame_channels[c].add(k, cols[k].max[c] * scale);
    }
  }

  // Temperatures come a few a second: all of the range's samples, into the same columns.
  const char* temp_names[] = {"chamber", "setpoint", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"};
  std::vector<Envelope> temps(8, Envelope(n));
  const double span_ns = static_cast<double>(t1_ns - t0_ns);
  for (const TempSample& s : run.temps(t0_ns, t1_ns - 1)) {
    const auto k = std::min(n - 1, static_cast<std::size_t>(static_cast<double>(s.t_ns - t0_ns) / span_ns * static_cast<double>(n)));
    temps[0].add(k, s.chamber_C);
    if (s.chamber_setpoint_C) temps[1].add(k, *s.chamber_setpoint_C);
    for (int j = 0; j < 3; ++j) {
      temps[static_cast<std::size_t>(2 + j)].add(k, s.gyro_C[j]);
      temps[static_cast<std::size_t>(5 + j)].add(k, s.accel_C[j]);
    }
  }

  const char* axes[] = {"x", "y", "z"};
  json table = json::object(), gyro = json::object(), accel = json::object(), temperature = json::object();
  for (std::size_t j = 0; j < 3; ++j) {
    gyro[axes[j]] = frame_channels[j].to_json();
    accel[axes[j]] = frame_channels[3 + j].to_json();
    table[motion::kAxisNames[j]] = frame_channels[6 + j].to_json();
  }
  for (std::size_t i = 0; i < temps.size(); ++i)
    if (std::find(temps[i].seen.begin(), temps[i].seen.end(), true) != temps[i].seen.end())
      temperature[temp_names[i]] = temps[i].to_json();
  out.update({{"from_s", range.from_s}, {"to_s", to_s}, {"t_s", std::move(t_s)}, {"frames", std::move(frames)},
              {"table_deg", std::move(table)}, {"gyro_dps", std::move(gyro)}, {"accel_mps2", std::move(accel)},
              {"temperature_C", std::move(temperature)}});
  return out;
}

}  // namespace imucal::daemon
