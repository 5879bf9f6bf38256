// Recorder: the thread that owns a run's RunDb while a campaign records, fed through a bounded
// queue so that the device readers never touch SQLite.
//
// Guarantees:
//  - Batches: everything that arrives within one commit interval goes into one transaction
//    (WAL, synchronous=NORMAL), or less when the batch reaches half the queue's capacity first; a
//    frame is committed at most commit_interval_s after the writer took it from the queue. A
//    commit survives a crash of the process (kill -9) at any moment.
//  - Memory is bounded: at most queue_capacity_frames frames not yet committed (waiting in the
//    queue or in the open batch, in recycled blocks), plus one partial chunk inside the RunDb.
//  - Backpressure is visible: the queue's high-water mark and every dropped frame are counted,
//    stored in the run (recorder_session, dropped_span) and raised as alarms, so that the
//    campaign can be suspended; nothing is lost silently.
//  - A full disk (or an I/O error) is survived: the batch that failed is rolled back (everything
//    committed before stays), its frames stay in memory with the queue's (they count against
//    queue_capacity_frames until committed), the writer tries again every retry_interval_s and
//    goes on where it left off once a commit succeeds. Meanwhile push() accepts nothing
//    (Push::Refused): the producer knows exactly which frames the recorder holds
//    (last_accepted_t_ns()) and must supply the rest again later (the daemon redoes the segment),
//    so nothing beyond the bound is lost silently. Other failures (a damaged file) stop it.
//  - Crash accounting: frames are counted as accepted in the run's writer lease (shared memory)
//    when they enter the queue; after a crash the next RunDb::open reports how many accepted
//    frames were never committed (RunDb::recovery()).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "core/recording.hpp"
#include "storage/run_db.hpp"

namespace imucal::storage {

struct RecorderOptions {
  double commit_interval_s = 1.0;
  std::int64_t queue_capacity_frames = std::int64_t{1} << 18;  // ~21 MB of frames, 0.13 s at 2 MHz
  // Default of push(): false drops a batch that does not fit (real devices must never block on
  // the disk); true makes the producer wait (simulation and benchmarks, paced by the recorder).
  bool wait_when_full = false;
  // The QueueHighWater alarm fires when the queue passes this fraction of its capacity, and is
  // re-armed when it drains below half of it.
  double high_water_alarm_fraction = 0.75;
  // A commit survives a crash of the process at once; against a power loss only after a
  // checkpoint has synced the WAL (synchronous=NORMAL). SQLite checkpoints by itself every
  // 1000 WAL pages (16 MB, ~300 k frames); at 2 kHz that is minutes, so the recorder also
  // checkpoints at least this often.
  double checkpoint_interval_s = 10.0;
  // While the run file cannot be written (disk full, I/O error), the writer tries again this often.
  double retry_interval_s = 1.0;
};

struct RecorderStats {
  std::int64_t queued_frames = 0;  // accepted, not yet committed (waiting, in the open batch or held)
  std::int64_t queue_capacity_frames = 0;
  std::int64_t high_water_frames = 0;
  std::int64_t accepted_frames = 0;   // entered the queue in this session
  std::int64_t committed_frames = 0;  // committed in this session
  std::int64_t stored_frames = 0;     // in the run after the last commit (earlier sessions too)
  std::optional<std::int64_t> committed_t_ns;  // time of the last committed frame
  std::int64_t dropped_frames = 0;
  std::int64_t commits = 0;
  double last_commit_s = 0.0;  // how long the last commit took (chunk flush, session row, COMMIT)
  double max_commit_s = 0.0;
  // Frames whose commit failed for want of space (or an I/O error), held for the next attempt;
  // they are part of queued_frames.
  std::int64_t held_frames = 0;
};

enum class RecorderAlarmKind {
  QueueHighWater,  // the writer falls behind; frames will be dropped if it goes on
  FramesDropped,   // a batch did not fit the queue and was dropped (counted, stored in the run)
  WriteHeld,       // the run cannot be written now (disk full, I/O error); held in memory, retried
  WriteFailed,     // the run cannot be written (damaged file, closed while held, ...); recording stopped
};

struct RecorderAlarm {
  RecorderAlarmKind kind = RecorderAlarmKind::QueueHighWater;
  std::string message;  // for a person: what happened and to which run
  RecorderStats stats;
};

const char* to_string(RecorderAlarmKind kind);

class Recorder {
 public:
  // Called on the pushing thread (QueueHighWater, FramesDropped) or the writer thread
  // (WriteFailed), never with the recorder's lock held; must be quick and must not call push()
  // or commit_and_wait(). The daemon suspends the campaign from here.
  using AlarmHandler = std::function<void(const RecorderAlarm&)>;
  // Called on the writer thread after every commit (e.g. estimators tail the run up to
  // committed_t_ns).
  using CommitListener = std::function<void(const RecorderStats&)>;

  // Takes the run's writer role (throws StorageError when another writer holds it) and starts
  // the writer thread.
  Recorder(RunDb db, RecorderOptions options = {}, AlarmHandler on_alarm = {}, CommitListener on_commit = {});
  ~Recorder();  // close(), errors logged
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  enum class Push {
    Queued,
    Dropped,   // the queue was full (counted, alarmed, recorded in the run)
    Rejected,  // times do not increase strictly after everything pushed before; nothing queued
    Failed,    // the recorder has failed or is closed (see error())
    Refused,   // the run file cannot be written now (write_problem()); from the first frame after
               // last_accepted_t_ns() on, nothing of the call was queued
  };
  // Copies the frames into the queue. The first form uses options.wait_when_full.
  Push push(std::span<const ImuFrame> frames);
  Push push(std::span<const ImuFrame> frames, bool wait_when_full);
  // Temperatures, segments and extras are small: they always wait for space and never drop.
  bool push_temps(std::span<const TempSample> temps);
  bool set_segments(std::vector<SegmentInfo> segments);
  bool set_extra(std::string key, std::string json_text);

  // Commits everything queued so far and waits for it. False when the recorder has failed, or
  // when the run file cannot be written now (write_problem(); what it holds is written later).
  bool commit_and_wait();
  // Commits the rest, closes the writer session cleanly and ends the thread (idempotent).
  // False when the recorder has failed.
  bool close();

  RecorderStats stats() const;
  std::optional<std::string> error() const;
  // While the run file cannot be written and the recorder holds what failed ("disk full: at least
  // N MB free needed ..."); nothing once a commit has succeeded again.
  std::optional<std::string> write_problem() const;
  // The time of the last frame the recorder accepted (queued, held or committed).
  std::optional<std::int64_t> last_accepted_t_ns() const;
  const std::string& path() const { return path_; }
  // What opening the run found when the previous writer had died (see RunDb::recovery()).
  const std::optional<RecoveryReport>& recovery() const { return recovery_; }

 private:
  using Clock = std::chrono::steady_clock;
  struct Item {
    enum class Kind { Frames, Temps, Segments, Extra, Barrier } kind = Kind::Frames;
    std::vector<ImuFrame> frames;
    std::vector<TempSample> temps;
    std::vector<SegmentInfo> segments;
    std::string key, text;
    std::uint64_t barrier = 0;
  };
  static constexpr std::size_t kBlockFrames = RunDb::kFramesPerChunk;

  // An alarm push() raises once its lock is released.
  struct PushAlarm {
    RecorderAlarmKind kind;
    std::string message;
  };
  // The pieces of push(), lock held.
  Push admit_locked(std::span<const ImuFrame> frames) const;
  std::optional<PushAlarm> drop_batch_locked(std::span<const ImuFrame> frames);
  Push queue_batch_locked(std::unique_lock<std::mutex>& lock, std::span<const ImuFrame> frames);
  void copy_slice_locked(std::span<const ImuFrame> slice);
  std::optional<PushAlarm> after_queued_locked();

  void run();
  void commit_batch();
  void release_batch_locked();
  // Returns the write problem it records (write_problem_).
  std::string hold_failed_batch_locked(const std::string& why, bool disk_full, std::optional<std::uint64_t> barrier);
  bool enqueue_small(Item item);
  std::vector<ImuFrame> take_block_locked();
  void raise(RecorderAlarmKind kind, std::string message);

  RunDb db_;  // the writer thread's, between construction and the end of run()
  std::string path_;
  RecorderOptions options_;
  AlarmHandler on_alarm_;
  CommitListener on_commit_;
  WriterLease* lease_ = nullptr;  // owned by db_
  std::optional<RecoveryReport> recovery_;

  mutable std::mutex mutex_;
  std::condition_variable cv_work_, cv_space_, cv_barrier_;
  std::deque<Item> queue_;
  std::vector<std::vector<ImuFrame>> free_blocks_;  // recycled, so a steady state allocates nothing
  RecorderStats stats_;
  std::optional<std::int64_t> last_pushed_t_ns_;
  std::vector<DroppedSpan> pending_drops_;
  bool dropping_ = false;             // inside a run of drops (one alarm per run)
  bool high_water_alarmed_ = false;   // until the queue drains below half the alarm level
  std::uint64_t next_barrier_ = 1, done_barrier_ = 0;
  std::uint64_t failed_barrier_ = 0;  // barriers up to this one were answered "not committed"
  std::optional<std::string> write_problem_;
  Clock::time_point retry_at_{};
  bool closing_ = false;
  std::optional<std::string> error_;
  std::thread thread_;

  // Writer thread only.
  bool batch_dirty_ = false;
  // What the open batch wrote, kept until it commits: a batch that fails for want of space goes
  // back to the head of the queue with its frames, to be written again.
  std::vector<Item> batch_items_;
  std::int64_t batch_frames_ = 0;
  std::vector<DroppedSpan> batch_drops_;
  Clock::time_point batch_started_{};
  Clock::time_point last_checkpoint_{};
};

}  // namespace imucal::storage
