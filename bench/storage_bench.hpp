// `imucal bench record` and `imucal bench read`: the recorder's and the reader's speed on this
// disk, against appending the same bytes to a plain file with an fsync at the recorder's commit
// cadence. The stream is the simulator's (the direct-short program at 2 kHz, replayed with
// shifted times), and stage 1 (DirectCalibrator) consumes it while it is recorded.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace CLI {
class App;
}

namespace imucal::bench {

struct RecordBenchOptions {
  std::string dir = "bench-tmp";  // the run and the raw file go here (the disk under test)
  std::int64_t frames = 10'000'000;
  double data_hours = 0.0;  // > 0: frames = hours of data at rate_hz, recorder phase only (memory run)
  double rate_hz = 2000.0;  // the simulated IMU's rate (data time)
  double commit_interval_s = 1.0;
  std::int64_t batch_frames = 1000;  // frames per push, as a device reader hands them over
  std::int64_t queue_frames = std::int64_t{1} << 18;
  bool storage_only_phases = true;  // also measure both sinks without the estimator
  bool estimator = true;            // false: the recorder phase runs without stage 1
  bool keep = false;                // keep the run file
};

struct PhaseResult {
  std::int64_t frames = 0;
  double wall_s = 0.0;
  double frames_per_s = 0.0;
};

struct RecordBenchResult {
  PhaseResult recorder, raw;                            // with the estimator consuming the stream
  PhaseResult recorder_storage_only, raw_storage_only;  // without it (if measured)
  double raw_append_ratio = 0.0;                        // recorder / raw, with the estimator
  double raw_append_ratio_storage_only = 0.0;
  double bytes_per_frame = 0.0;       // run file after close (frames, chunk summaries, temperatures)
  double raw_bytes_per_frame = 0.0;   // the plain file
  std::int64_t estimator_intervals = 0;
  std::int64_t commits = 0;
  double max_commit_s = 0.0;
  std::int64_t queue_high_water_frames = 0;
  std::int64_t dropped_frames = 0;
  double peak_rss_mb = 0.0;            // whole process (includes the replayed frame pool)
  double rss_before_recording_mb = 0.0;
  std::vector<std::pair<double, double>> rss_mb_by_progress;  // (fraction of frames recorded, RSS)
  std::string run_path;                // when kept
};

RecordBenchResult run_record_bench(const RecordBenchOptions& options);

struct ReadBenchOptions {
  std::string db;                   // an existing run; empty: record one first (not timed)
  std::string dir = "bench-tmp";
  std::int64_t frames = 10'000'000; // for the run recorded first
  int range_reads = 200;            // random 10 s ranges
  int plot_columns = 1000;
};

struct ReadBenchResult {
  std::int64_t frames = 0;
  double wall_s = 0.0;
  double frames_per_s = 0.0;            // whole run, decoded block by block
  double range_frames_per_s = 0.0;      // random 10 s ranges through read_frames
  double decimate_full_ms = 0.0;        // the whole run into plot_columns min/max columns
  double decimate_decoded_ms = 0.0;     // a 60 s window (every chunk decoded)
  double bytes_per_frame = 0.0;
  // The same chunk bytes from a plain file, read(2) and decoded; the ratio is named as in
  // `bench record` so that both commands print the same keys.
  double raw_frames_per_s = 0.0;
  double raw_append_ratio = 0.0;
};

ReadBenchResult run_read_bench(const ReadBenchOptions& options);

// Adds `record` and `read` under `bench` (a CLI11 subcommand); they run from CLI11's callbacks
// and report failures as CLI::RuntimeError.
void add_storage_bench_commands(CLI::App& bench);

}  // namespace imucal::bench
