// A recorded run as plot series (GET /api/campaigns/{id}/series, docs/api.md): table angles, IMU
// rates and specific forces, and temperatures over a time range, decimated to a number of columns
// with the minimum and maximum of each channel in each column, so that a plot of a 12 h run draws
// every excursion from about a thousand columns and opens in about a second (RunDb::decimate takes
// a chunk inside one column from its stored summary without decoding it).
#pragma once

#include <cstdint>

#include <nlohmann/json.hpp>

namespace imucal::storage {
class RunDb;
}

namespace imucal::daemon {

// The time range a series request may ask for, and its columns.
struct SeriesRange {
  double from_s = 0;  // program time (the recording's time base)
  double to_s = 0;    // <= from_s: up to the last frame recorded
  int columns = 800;
};
inline constexpr int kMaxSeriesColumns = 4000;
// The latest program time a range may name (about 115 days; a run is at most days long): its
// nanoseconds must fit the recording's 64-bit time base.
inline constexpr double kMaxSeriesTime_s = 1e7;

// {"format": "imucal-series/1", "from_s", "to_s", "columns", "rate_hz",
//  "t_s": [column starts], "frames": [frames per column],
//  "table_deg": {"outer": {"min": [...], "max": [...]}, "middle": ..., "inner": ...},
//  "gyro_dps": {"x": ..., "y": ..., "z": ...}, "accel_mps2": {"x": ..., ...},
//  "temperature_C": {"chamber", "setpoint", "gyro_x", "gyro_y", "gyro_z", "accel_x", ...: {min, max}}}
// A column without frames (or temperatures) holds null. Rates and specific forces are the
// increments over the nominal frame interval (1 / rate_hz). Throws std::invalid_argument for a
// range or a column count it cannot give.
nlohmann::json run_series_json(const storage::RunDb& run, SeriesRange range);

}  // namespace imucal::daemon
