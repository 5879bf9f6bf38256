// Import and export of the `imucal-recording/1` bundle (formats.md): a folder with meta.json and
// frames.csv, the format in which recordings cross the project's boundary.
//
// import_bundle(export_bundle(run)) gives back the same run: meta, every frame bit for bit, and
// the same temperatures at every frame. Beyond formats.md the export adds keys the format allows
// (imu.gyro_lsb_rad, imu.accel_lsb_mps, and mount.r0_p_m when millimetres cannot carry the metre
// value exactly) and the files program.json and truth.json (RecordingMeta::program_json and
// truth_json, verbatim; the example bundle's truth.json is read the same way), and the run's
// faulted intervals (kFaultedIntervalsKey) when its writer recorded any.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "storage/run_db.hpp"

namespace imucal::storage {

inline constexpr const char* kRecordingFormat = "imucal-recording/1";

// A hole in the sample stream: more than 1.5 nominal sample periods between two lines.
// Estimators must not integrate across it. `line` is the frames.csv line (1-based, header = 1)
// of the first sample after the hole.
struct Gap {
  double t0_s = 0.0;  // last sample before the gap
  double t1_s = 0.0;  // first sample after it
  std::int64_t line = 0;
  std::int64_t t0_ns = 0;
  std::int64_t t1_ns = 0;
};

struct ImportReport {
  std::int64_t frames = 0;
  std::int64_t temp_samples = 0;  // stored run-length: one per change of any temperature
  std::vector<Gap> gaps;
  // Columns after the required ones that the import does not keep (any but chamber_setpoint_C
  // and the 24 coil sensors temp_gx_1_C .. temp_gz_8_C, which are kept only when all 24 are
  // there), so that nothing is dropped without saying so.
  std::vector<std::string> ignored_columns;
};

// The run's extra key holding the import gaps as JSON.
inline constexpr const char* kGapsExtraKey = "gaps";

// The run's extra key holding the intervals in which its recording was held by a fault (imucald's
// suspensions and interruptions, docs/storage.md): a JSON array of objects its writer defines.
// The export writes it into meta.json under the same key; the import keeps meta.json's back in
// the run, verbatim, so that a bundle read and written again still lists them.
inline constexpr const char* kFaultedIntervalsKey = "faulted_intervals";

// The fraction of the frames written (0..1), every few thousand frames; it may throw to stop.
using ExportProgress = std::function<void(double fraction)>;

// Writes `dir`/meta.json and `dir`/frames.csv (the folder is created; files in it are replaced).
// Temperatures are sample-and-hold: each frame gets the latest temperature sample at or before its
// time, frames before the first sample get the first one (a run without any temperature samples
// is written with TempSample's defaults).
void export_bundle(const RunDb& run, const std::string& dir, const ExportProgress& progress = {});

// Reads a bundle into a new run file `db_path` (which must not exist). Rejects malformed input
// with StorageError("... frames.csv line N: reason"); then no file is left at `db_path`.
// Table angles are unwrapped; gaps are reported and stored under kGapsExtraKey.
ImportReport import_bundle(const std::string& dir, const std::string& db_path);

// The gaps an import stored in the run (empty when there are none or the run was not imported).
std::vector<Gap> stored_gaps(const RunDb& run);

}  // namespace imucal::storage
