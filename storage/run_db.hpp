// RunDb: one SQLite file holds one calibration run (meta, IMU frames, temperatures, segments,
// key/value extras written by later stages, and the history of its recorder sessions). The
// recorder (storage/recorder.hpp) appends to it, estimators, plots and export read it.
//
// Frames are stored in chunks of up to kFramesPerChunk frames per row, because one row per sample
// costs ~3x the space and an order of magnitude in read speed. The chunk codec is documented in
// run_db.cpp. Decoded frames are bit-identical to the appended ones.
//
// One writer per run: the first write (or create(), or open(.., OpenMode::Write)) takes the
// run's writer lease (storage/writer_lease.hpp); a second writer, in this or another process,
// gets a StorageError naming the holder. Readers never need the lease and may read while the
// writer records (WAL). A writer that ends without closing its session (crash, kill -9, power
// loss) leaves a marker; the next open runs PRAGMA integrity_check and reports what was lost
// (RunDb::recovery()).
//
// A RunDb is not thread-safe: one thread (the recorder) owns it.
#pragma once

#include <array>
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
#include "storage/sqlite.hpp"
#include "storage/writer_lease.hpp"

namespace imucal::storage {

// StorageError (storage/sqlite.hpp): every failure of the storage layer; the message names the
// file and the reason, so that it can be shown to a person as it is.

// Space accounting of the frame table (for tests and `imucal bench`).
struct FrameStorageStats {
  std::int64_t chunks = 0;
  std::int64_t codec1_chunks = 0;  // integer counts
  std::int64_t codec2_chunks = 0;  // doubles
  std::int64_t frames = 0;         // stored frames, without the not yet flushed buffer
  std::int64_t blob_bytes = 0;     // sum of the chunk payloads
};

// One writer session of the run (table recorder_session): who wrote, how it ended, and the
// recorder's backpressure counters, so that a run tells its own history.
struct RecorderSession {
  std::int64_t id = 0;
  std::int64_t opened_unix_ms = 0;
  std::optional<std::int64_t> closed_unix_ms;  // absent: still writing, or died (see unclean)
  std::int64_t pid = 0;
  std::string host;
  std::int64_t frames_at_open = 0;
  std::int64_t committed_frames = 0;  // frames the session committed
  std::optional<std::int64_t> committed_t_ns;
  std::int64_t commits = 0;
  std::int64_t queue_high_water_frames = 0;
  std::int64_t dropped_frames = 0;
  bool unclean = false;  // closed by a later open's recovery, not by the writer
  std::optional<std::int64_t> lost_uncommitted_frames;  // recovery's count; absent: unknown
  std::string integrity;                                // recovery's integrity_check verdict
};

// Frames the recorder had to drop (queue full), merged into spans; estimators see them as gaps.
struct DroppedSpan {
  std::int64_t session_id = 0;
  std::int64_t t0_ns = 0;  // first dropped frame
  std::int64_t t1_ns = 0;  // last dropped frame
  std::int64_t frames = 0;
};

// What open() found and did after a writer ended without closing its session.
struct RecoveryReport {
  std::int64_t session_id = 0;
  std::int64_t pid = 0;  // the writer that died
  std::string integrity = "ok";
  std::int64_t committed_frames = 0;  // frames of that session that are in the run
  std::optional<std::int64_t> committed_t_ns;
  // Frames the writer had accepted (queued or buffered) but not committed when it died, and the
  // time of the last one; absent when its lease page was gone (e.g. only the .db was copied).
  std::optional<std::int64_t> lost_uncommitted_frames;
  std::optional<std::int64_t> accepted_t_ns;
};

// Minimum and maximum of every channel over one pixel column of a plot.
struct PlotColumn {
  std::int64_t t0_ns = 0;  // the column's interval [t0_ns, t1_ns)
  std::int64_t t1_ns = 0;
  std::int64_t frames = 0;  // 0: no data in the column (min/max meaningless)
  // Channels: dtheta_rad x y z, dv_mps x y z, table_deg outer middle inner.
  std::array<double, 9> min{};
  std::array<double, 9> max{};
};

// The payload RunDb stores for one chunk of `frames` (at most kFramesPerChunk, strictly
// increasing times) under the LSBs of `meta`: the same bytes, for benchmarks against a plain file.
// Returns the codec (1 counts, 2 doubles).
int encode_chunk_payload(std::span<const ImuFrame> frames, const RecordingMeta& meta,
                         std::vector<unsigned char>& out);
// Decodes such a payload of `n_frames` frames into `out`; throws StorageError when it is damaged.
void decode_chunk_payload(std::span<const unsigned char> data, std::int64_t n_frames, int codec,
                          std::vector<ImuFrame>& out);

enum class OpenMode {
  Auto,   // read now; take the writer lease at the first write
  Read,   // never write (writes throw)
  Write,  // take the writer lease now (throws when another writer holds it)
};

class RunDb {
 public:
  static constexpr int kSchemaVersion = 3;  // PRAGMA user_version; open() migrates older files
  static constexpr std::size_t kFramesPerChunk = 4096;
  static constexpr int kPlotChannels = 9;

  // Makes a new run file and becomes its writer; a file already at `path` is an error (never
  // overwrite a run).
  static RunDb create(const std::string& path, const RecordingMeta& meta);
  // Opens an existing run; checks the application id and schema version (migrating an older
  // schema), and recovers after an unclean end of the last writer (integrity_check, lost frames).
  static RunDb open(const std::string& path, OpenMode mode = OpenMode::Auto);

  RunDb(RunDb&&) noexcept;
  RunDb& operator=(RunDb&&) noexcept;
  RunDb(const RunDb&) = delete;
  RunDb& operator=(const RunDb&) = delete;
  // Flushes the buffered frames and closes the writer session; a failure there is logged, not
  // thrown (the session then stays open, and the next open recovers). Call close() to see it.
  ~RunDb();

  const std::string& path() const;

  // ---- writing ----
  // Frames must have strictly increasing t_ns (also across calls). They are buffered and written
  // a full chunk at a time; outside a batch, all chunks that one call completes go into one
  // transaction.
  void append(std::span<const ImuFrame> frames);
  // Writes the buffered frames (the open, partial chunk) and commits (inside a batch: writes, and
  // the batch commits). Later appends keep filling the same chunk row, so frequent flushes do not
  // fragment the table.
  void flush();
  // Temperature samples, strictly increasing t_ns; one transaction per call outside a batch.
  void append_temps(std::span<const TempSample> temps);
  // Replaces the run's segment list.
  void set_segments(const std::vector<SegmentInfo>& segments);
  // Key/value store for later stages (calibration results, reports, import gaps). `json_text`
  // must be valid JSON; an existing key is replaced.
  void set_extra(const std::string& key, const std::string& json_text);

  // A batch groups every write until commit_batch() into one transaction (the recorder's unit of
  // durability). commit_batch() writes the open chunk too, so that everything appended so far is
  // committed. When a write inside a batch fails (a full disk), the batch is rolled back and this
  // RunDb is put back where it was at begin_batch(): the same data may be written again in a new
  // batch (the recorder holds it). Only if SQLite could not roll back does it refuse further
  // writes; then reopen the run to continue.
  void begin_batch();
  void commit_batch();
  bool in_batch() const;

  // Copies the WAL into the database file and syncs both (PASSIVE: never waits for readers).
  // Commits under synchronous=NORMAL survive a crash of the process at once, but a power loss
  // only once checkpointed; the recorder calls this every RecorderOptions::checkpoint_interval_s.
  void checkpoint();

  // Flushes, closes the writer session and gives up the lease; throws on failure. Reads keep
  // working; a later write takes the lease again (a new session).
  void close();

  // Ends the writer session as a crash would, for a writer that gives up holding frames it
  // accepted but could not commit: nothing more is written through this handle, the session stays
  // open in the file, and the next open recovers the run and counts those frames as lost. Never
  // throws.
  void abandon(const std::string& why) noexcept;

  // ---- the writer's bookkeeping (the recorder uses these) ----
  void claim_writer();  // takes the lease now (no-op when held); throws when another writer has it
  bool is_writer() const;
  // The writer's lease page, for publishing accepted frames from another thread; null unless
  // this RunDb is the writer. Valid until close() or destruction.
  WriterLease* lease();
  // The recorder counts frames as accepted when they enter its queue (they are at risk from
  // then on); append() then leaves the lease's accepted counter alone.
  void set_accepted_counted_by_caller(bool by_caller);
  // Stored in the session row at every commit.
  void set_queue_counters(std::int64_t high_water_frames, std::int64_t dropped_frames);
  // Records dropped frames (written with the next commit, or at once outside a batch).
  void record_dropped(std::int64_t t0_ns, std::int64_t t1_ns, std::int64_t frames);
  // Limits the database file (SQLite max_page_count): writes past it fail as "disk full". For
  // keeping a reserve on the disk, and for testing a full disk.
  void set_size_limit_bytes(std::int64_t bytes);

  // ---- reading (the not yet flushed frames are included) ----
  std::optional<std::string> extra(const std::string& key) const;
  RecordingMeta meta() const;  // with the current segment list
  std::int64_t frame_count() const;
  // Time of the last frame (buffered ones included); absent for a run without frames.
  std::optional<std::int64_t> last_frame_t_ns() const;
  // Time of the last temperature sample (appended ones included); absent for a run without any.
  std::optional<std::int64_t> last_temperature_t_ns() const;
  // Streams the frames with t0_ns <= t_ns <= t1_ns in time order, a decoded chunk at a time.
  // `fn` may call other reading functions of this RunDb, but not append().
  void for_each_frame(const std::function<void(const ImuFrame&)>& fn,
                      std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
                      std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  // The same, a block of consecutive frames per call (one decoded chunk, trimmed to the range):
  // the fast path for bulk readers.
  void for_each_block(const std::function<void(std::span<const ImuFrame>)>& fn,
                      std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
                      std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  std::vector<ImuFrame> read_frames(
      std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
      std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  // [t0_ns, t1_ns) split into `columns` equal columns, each with the min and max of every channel:
  // what a plot of that width needs. A chunk that lies inside one column is taken from its stored
  // summary without decoding; only chunks across a column edge are decoded (a whole 12 h run at
  // 2 kHz into 1000 columns: ~0.25 s on the development machine).
  std::vector<PlotColumn> decimate(std::int64_t t0_ns, std::int64_t t1_ns, int columns) const;
  // The temperature samples with t0_ns <= t_ns <= t1_ns in time order (t_ns is the table's key:
  // a range is an index lookup, so an online reader can tail them).
  std::vector<TempSample> temps(std::int64_t t0_ns = std::numeric_limits<std::int64_t>::min(),
                                std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max()) const;
  FrameStorageStats frame_storage_stats() const;
  std::vector<RecorderSession> sessions() const;
  std::vector<DroppedSpan> dropped_spans() const;
  // Set when open() found that the last writer died; the report is also stored in its session.
  const std::optional<RecoveryReport>& recovery() const;

 private:
  struct Impl;
  explicit RunDb(std::unique_ptr<Impl> impl);
  Impl& impl() const;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::storage
