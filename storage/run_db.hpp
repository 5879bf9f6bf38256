// RunDb: one SQLite file holds one calibration run (meta, IMU frames, temperatures, segments and
// key/value extras written by later stages). The recorder appends to it, estimators stream from it.
//
// Frames are stored in chunks of up to kFramesPerChunk frames per row, because one row per sample
// costs ~3x the space and an order of magnitude in read speed. The chunk codec is documented in
// run_db.cpp. Decoded frames are bit-identical to the appended ones.
//
// A RunDb is not thread-safe: one thread (the recorder) owns it. Other processes may read the same
// file concurrently (WAL mode).
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/recording.hpp"

namespace imucal::storage {

// Every failure of the storage layer; the message names the file and the reason, so that it can be
// shown to a person as it is.
class StorageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Space accounting of the frame table (for tests and `imucal bench`).
struct FrameStorageStats {
  std::int64_t chunks = 0;
  std::int64_t codec1_chunks = 0;  // integer counts
  std::int64_t codec2_chunks = 0;  // doubles
  std::int64_t frames = 0;         // stored frames, without the not yet flushed buffer
  std::int64_t blob_bytes = 0;     // sum of the chunk payloads
};

class RunDb {
 public:
  static constexpr int kSchemaVersion = 1;  // PRAGMA user_version
  static constexpr std::size_t kFramesPerChunk = 4096;

  // Makes a new run file; a file already at `path` is an error (never overwrite a run).
  static RunDb create(const std::string& path, const RecordingMeta& meta);
  // Opens an existing run for reading and appending; checks the schema version and runs
  // PRAGMA quick_check.
  static RunDb open(const std::string& path);

  RunDb(RunDb&&) noexcept;
  RunDb& operator=(RunDb&&) noexcept;
  RunDb(const RunDb&) = delete;
  RunDb& operator=(const RunDb&) = delete;
  // Flushes the buffered frames; a failure there is logged, not thrown. Call flush() to see it.
  ~RunDb();

  const std::string& path() const;

  // ---- writing ----
  // Frames must have strictly increasing t_ns (also across calls). They are buffered and written
  // a full chunk at a time; all chunks that one call completes go into one transaction.
  void append(std::span<const ImuFrame> frames);
  // Writes the buffered frames (the open, partial chunk) and commits. Later appends keep filling
  // the same chunk row, so frequent flushes do not fragment the table.
  void flush();
  // Temperature samples, strictly increasing t_ns; written at once, one transaction per call.
  void append_temps(std::span<const TempSample> temps);
  // Replaces the run's segment list.
  void set_segments(const std::vector<SegmentInfo>& segments);
  // Key/value store for later stages (calibration results, reports, import gaps). `json_text`
  // must be valid JSON; an existing key is replaced.
  void set_extra(const std::string& key, const std::string& json_text);

  // ---- reading (the not yet flushed frames are included) ----
  std::optional<std::string> extra(const std::string& key) const;
  RecordingMeta meta() const;  // with the current segment list
  std::int64_t frame_count() const;
  // Streams the frames with t0_ns <= t_ns <= t1_ns in time order, a decoded chunk at a time.
  // `fn` may call other reading functions of this RunDb, but not append().
  void for_each_frame(const std::function<void(const ImuFrame&)>& fn,
                      std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
                      std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  std::vector<ImuFrame> read_frames(
      std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
      std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  std::vector<TempSample> temps() const;
  FrameStorageStats frame_storage_stats() const;

 private:
  struct Impl;
  explicit RunDb(std::unique_ptr<Impl> impl);
  Impl& impl() const;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::storage
