#include "storage/recorder.hpp"

#include <algorithm>
#include <cstdio>
#include <utility>

#include <spdlog/spdlog.h>

#include "core/number_text.hpp"

namespace imucal::storage {

const char* to_string(RecorderAlarmKind kind) {
  switch (kind) {
    case RecorderAlarmKind::QueueHighWater:
      return "queue_high_water";
    case RecorderAlarmKind::FramesDropped:
      return "frames_dropped";
    case RecorderAlarmKind::WriteHeld:
      return "write_held";
    case RecorderAlarmKind::WriteFailed:
      return "write_failed";
  }
  return "?";
}

Recorder::Recorder(RunDb db, RecorderOptions options, AlarmHandler on_alarm, CommitListener on_commit)
    : db_(std::move(db)),
      path_(db_.path()),
      options_(options),
      on_alarm_(std::move(on_alarm)),
      on_commit_(std::move(on_commit)) {
  if (!(options_.commit_interval_s > 0.0)) throw StorageError("recorder: commit_interval_s must be positive");
  if (!(options_.retry_interval_s > 0.0)) throw StorageError("recorder: retry_interval_s must be positive");
  if (options_.queue_capacity_frames < static_cast<std::int64_t>(kBlockFrames)) {
    throw StorageError("recorder: queue_capacity_frames must be at least " + std::to_string(kBlockFrames));
  }
  db_.claim_writer();
  db_.set_accepted_counted_by_caller(true);
  lease_ = db_.lease();
  recovery_ = db_.recovery();
  stats_.queue_capacity_frames = options_.queue_capacity_frames;
  stats_.stored_frames = lease_->counters().frames_at_open;
  last_pushed_t_ns_ = db_.last_frame_t_ns();  // a continued run: new frames must come after it
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() {
  if (!close()) spdlog::error("recorder '{}': {}", path_, error().value_or("failed"));
}

void Recorder::raise(RecorderAlarmKind kind, std::string message) {
  if (!on_alarm_) return;
  RecorderAlarm alarm;
  alarm.kind = kind;
  alarm.message = std::move(message);
  alarm.stats = stats();
  on_alarm_(alarm);
}

std::vector<ImuFrame> Recorder::take_block_locked() {
  if (free_blocks_.empty()) {
    std::vector<ImuFrame> block;
    block.reserve(kBlockFrames);
    return block;
  }
  std::vector<ImuFrame> block = std::move(free_blocks_.back());
  free_blocks_.pop_back();
  return block;
}

Recorder::Push Recorder::push(std::span<const ImuFrame> frames) { return push(frames, options_.wait_when_full); }

// push() is cut into pieces of a few branches each: the optional-access analysis of the static
// check (.clang-tidy) ran for minutes unfinished on it as one function.
Recorder::Push Recorder::push(std::span<const ImuFrame> frames, bool wait_when_full) {
  if (frames.empty()) return Push::Queued;
  std::optional<PushAlarm> alarm;  // raised once the lock is released
  Push result = Push::Queued;
  {
    std::unique_lock lock(mutex_);
    result = admit_locked(frames);
    if (result != Push::Queued) return result;
    const auto n = static_cast<std::int64_t>(frames.size());
    if (!wait_when_full && stats_.queued_frames + n > options_.queue_capacity_frames) {
      alarm = drop_batch_locked(frames);
      result = Push::Dropped;
    } else {
      result = queue_batch_locked(lock, frames);
      if (result != Push::Queued) return result;
      alarm = after_queued_locked();
    }
  }
  if (alarm) raise(alarm->kind, std::move(alarm->message));
  return result;
}

// Producer's thread, lock held: Push::Queued if the recorder can take the batch, else the answer.
// The times are checked here, so that a bad batch is refused at once instead of failing the
// writer later.
Recorder::Push Recorder::admit_locked(std::span<const ImuFrame> frames) const {
  if (error_ || closing_) return Push::Failed;
  if (write_problem_) return Push::Refused;
  bool have_previous = false;
  std::int64_t previous = 0;
  if (last_pushed_t_ns_) {
    have_previous = true;
    previous = *last_pushed_t_ns_;
  }
  for (const auto& frame : frames) {
    if (have_previous && frame.t_ns <= previous) return Push::Rejected;
    have_previous = true;
    previous = frame.t_ns;
  }
  return Push::Queued;
}

// Producer's thread, lock held: a batch that does not fit is dropped as a whole, never in part
// (the gap is then exactly this batch); the first drop of a run of drops raises the alarm.
std::optional<Recorder::PushAlarm> Recorder::drop_batch_locked(std::span<const ImuFrame> frames) {
  const auto n = static_cast<std::int64_t>(frames.size());
  stats_.dropped_frames += n;
  lease_->add_dropped(n);
  if (!pending_drops_.empty() && pending_drops_.back().t1_ns == last_pushed_t_ns_) {
    pending_drops_.back().t1_ns = frames.back().t_ns;
    pending_drops_.back().frames += n;
  } else {
    pending_drops_.push_back({0, frames.front().t_ns, frames.back().t_ns, n});
  }
  last_pushed_t_ns_ = frames.back().t_ns;
  if (dropping_) return std::nullopt;
  dropping_ = true;
  return PushAlarm{RecorderAlarmKind::FramesDropped,
                   "recorder '" + path_ + "': the queue is full (" + std::to_string(stats_.queued_frames) + " of " +
                       std::to_string(options_.queue_capacity_frames) + " frames); dropping frames from t = " +
                       std::to_string(frames.front().t_ns) + " ns (the writer falls behind the device)"};
}

// Producer's thread, lock held: the batch into the queue, slice by slice, each waiting for room.
// A slice never exceeds one block, so any batch fits eventually whatever the capacity. Push::Queued,
// or why it stopped (the slices before are held; the producer takes up after last_accepted_t_ns()).
Recorder::Push Recorder::queue_batch_locked(std::unique_lock<std::mutex>& lock, std::span<const ImuFrame> frames) {
  const std::int64_t capacity = options_.queue_capacity_frames;
  std::size_t done = 0;
  while (done < frames.size()) {
    const std::size_t slice = std::min(frames.size() - done, kBlockFrames);
    cv_space_.wait(lock, [&] {
      return error_ || closing_ || write_problem_ ||
             stats_.queued_frames + static_cast<std::int64_t>(slice) <= capacity;
    });
    if (error_ || closing_) return Push::Failed;
    if (write_problem_) return Push::Refused;
    copy_slice_locked(frames.subspan(done, slice));
    // The writer woken for each slice, not only once the batch is queued: it is what makes room for
    // the next slice, and an idle writer (no batch open) would otherwise sleep while this waits.
    cv_work_.notify_one();
    const auto added = static_cast<std::int64_t>(slice);
    stats_.queued_frames += added;
    stats_.accepted_frames += added;
    const std::int64_t last_t_ns = frames[done + slice - 1].t_ns;
    last_pushed_t_ns_ = last_t_ns;
    lease_->add_accepted(added, last_t_ns);
    done += slice;
  }
  return Push::Queued;
}

// Lock held: frames appended to the queue's last block of frames, new blocks as they fill.
void Recorder::copy_slice_locked(std::span<const ImuFrame> slice) {
  std::size_t copied = 0;
  while (copied < slice.size()) {
    if (queue_.empty() || queue_.back().kind != Item::Kind::Frames || queue_.back().frames.size() >= kBlockFrames) {
      Item item;
      item.kind = Item::Kind::Frames;
      item.frames = take_block_locked();
      queue_.push_back(std::move(item));
    }
    std::vector<ImuFrame>& block = queue_.back().frames;
    const std::size_t room = std::min(kBlockFrames - block.size(), slice.size() - copied);
    const auto first = slice.begin() + static_cast<std::ptrdiff_t>(copied);
    block.insert(block.end(), first, first + static_cast<std::ptrdiff_t>(room));
    copied += room;
  }
}

// Producer's thread, lock held, the whole batch queued: the high-water mark, its alarm, the writer
// woken.
std::optional<Recorder::PushAlarm> Recorder::after_queued_locked() {
  std::optional<PushAlarm> alarm;
  dropping_ = false;
  if (stats_.queued_frames > stats_.high_water_frames) {
    stats_.high_water_frames = stats_.queued_frames;
    lease_->raise_high_water(stats_.high_water_frames);
  }
  const std::int64_t capacity = options_.queue_capacity_frames;
  const auto alarm_level =
      static_cast<std::int64_t>(options_.high_water_alarm_fraction * static_cast<double>(capacity));
  if (!high_water_alarmed_ && stats_.queued_frames >= alarm_level) {
    high_water_alarmed_ = true;
    alarm = PushAlarm{RecorderAlarmKind::QueueHighWater,
                      "recorder '" + path_ + "': the queue holds " + std::to_string(stats_.queued_frames) + " of " +
                          std::to_string(capacity) + " frames (the writer falls behind the device)"};
  }
  cv_work_.notify_one();
  return alarm;
}

bool Recorder::enqueue_small(Item item) {
  {
    std::lock_guard lock(mutex_);
    if (error_ || closing_) return false;
    queue_.push_back(std::move(item));
  }
  cv_work_.notify_one();
  return true;
}

bool Recorder::push_temps(std::span<const TempSample> temps) {
  if (temps.empty()) return true;
  Item item;
  item.kind = Item::Kind::Temps;
  item.temps.assign(temps.begin(), temps.end());
  return enqueue_small(std::move(item));
}

bool Recorder::set_segments(std::vector<SegmentInfo> segments) {
  Item item;
  item.kind = Item::Kind::Segments;
  item.segments = std::move(segments);
  return enqueue_small(std::move(item));
}

bool Recorder::set_extra(std::string key, std::string json_text) {
  Item item;
  item.kind = Item::Kind::Extra;
  item.key = std::move(key);
  item.text = std::move(json_text);
  return enqueue_small(std::move(item));
}

bool Recorder::commit_and_wait() {
  std::unique_lock lock(mutex_);
  if (error_ || closing_) return !error_;
  if (write_problem_) return false;
  Item item;
  item.kind = Item::Kind::Barrier;
  item.barrier = next_barrier_++;
  const std::uint64_t mine = item.barrier;
  queue_.push_back(std::move(item));
  cv_work_.notify_one();
  cv_barrier_.wait(lock, [&] { return error_ || done_barrier_ >= mine; });
  return !error_ && mine > failed_barrier_;
}

bool Recorder::close() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
  }
  cv_work_.notify_all();
  cv_space_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lock(mutex_);
  return !error_;
}

RecorderStats Recorder::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

std::optional<std::string> Recorder::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

std::optional<std::string> Recorder::write_problem() const {
  std::lock_guard lock(mutex_);
  return write_problem_;
}

std::optional<std::int64_t> Recorder::last_accepted_t_ns() const {
  std::lock_guard lock(mutex_);
  return last_pushed_t_ns_;
}

namespace {

// A failure the disk may get over (space freed, a transient I/O error): the writer holds what
// failed and tries again. Anything else (a damaged file) ends the recording.
bool worth_retrying(const sql::SqliteError& e) {
  return e.kind() == sql::SqliteError::Kind::full || e.kind() == sql::SqliteError::Kind::io;
}

// What the held frames need on the disk to be committed and checkpointed: each frame once in the
// WAL and once in the database file (52.6 bytes a frame with its chunk's share, docs/storage.md),
// and one WAL's worth between checkpoints (SQLite's 1000 pages of 16 KiB).
std::int64_t megabytes_needed(std::int64_t held_frames) {
  constexpr std::int64_t kBytesPerFrame = 53, kWalBytes = 1000 * 16384, kMB = 1'000'000;
  return (2 * held_frames * kBytesPerFrame + kWalBytes + kMB - 1) / kMB;
}

}  // namespace

// Writer thread, lock held: the committed batch's frames leave the recorder's memory.
void Recorder::release_batch_locked() {
  for (Item& item : batch_items_) {
    if (item.kind != Item::Kind::Frames) continue;
    // Counted out only now that the frames are committed: the bound holds for everything the
    // recorder keeps in memory, the frames of a batch that may yet fail included.
    stats_.queued_frames -= static_cast<std::int64_t>(item.frames.size());
    item.frames.clear();
    // Keep as many blocks as the queue can ever hold; more would be garbage.
    if (free_blocks_.size() * kBlockFrames < static_cast<std::size_t>(options_.queue_capacity_frames)) {
      free_blocks_.push_back(std::move(item.frames));
    }
  }
  batch_items_.clear();
  batch_drops_.clear();
  batch_frames_ = 0;
  stats_.held_frames = 0;
  const auto rearm_level = static_cast<std::int64_t>(0.5 * options_.high_water_alarm_fraction *
                                                     static_cast<double>(options_.queue_capacity_frames));
  if (stats_.queued_frames < rearm_level) high_water_alarmed_ = false;
  cv_space_.notify_all();
}

// Writer thread, lock held, after a batch failed for want of space or by an I/O error (the RunDb
// has rolled it back to the last commit): what it wrote goes back to the head of the queue, to be
// written again at the next attempt; commits waited for are answered "not committed". Returns the
// write problem it records.
std::string Recorder::hold_failed_batch_locked(const std::string& why, bool disk_full, std::optional<std::uint64_t> barrier) {
  for (auto it = batch_items_.rbegin(); it != batch_items_.rend(); ++it) queue_.push_front(std::move(*it));
  batch_items_.clear();
  batch_frames_ = 0;
  pending_drops_.insert(pending_drops_.begin(), batch_drops_.begin(), batch_drops_.end());
  batch_drops_.clear();
  batch_dirty_ = false;
  std::int64_t held = 0;
  for (const Item& item : queue_)
    if (item.kind == Item::Kind::Frames) held += static_cast<std::int64_t>(item.frames.size());
  stats_.held_frames = held;
  if (closing_) {
    // No later attempt: the run's next open counts these frames as lost (recovery).
    throw StorageError(why + "; the recorder was closed while it held " + std::to_string(held) +
                       " frames it could not write");
  }
  char text[200];
  std::snprintf(text, sizeof text, "; %lld frames held in memory, written again every %s s",
                static_cast<long long>(held), number_text(options_.retry_interval_s).c_str());
  const std::string problem = (disk_full ? "disk full: at least " + std::to_string(megabytes_needed(held)) +
                                               " MB free needed for run '" + path_ + "'"
                                         : "I/O error writing run '" + path_ + "'") +
                              text + " (" + why + ")";
  write_problem_ = problem;
  retry_at_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                 std::chrono::duration<double>(options_.retry_interval_s));
  // Every commit asked for so far is not done; the queue's later barriers are answered now too.
  if (barrier) done_barrier_ = std::max(done_barrier_, *barrier);
  failed_barrier_ = next_barrier_ - 1;
  done_barrier_ = std::max(done_barrier_, failed_barrier_);
  cv_barrier_.notify_all();
  cv_space_.notify_all();  // a producer waiting for room gets Push::Refused
  return problem;
}

// Writer thread: the batch so far, with the counters, in one COMMIT.
void Recorder::commit_batch() {
  const auto t0 = Clock::now();
  {
    std::lock_guard lock(mutex_);
    db_.set_queue_counters(stats_.high_water_frames, stats_.dropped_frames);
  }
  db_.commit_batch();
  batch_dirty_ = false;
  if (Clock::now() - last_checkpoint_ >=
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options_.checkpoint_interval_s))) {
    try {
      db_.checkpoint();
    } catch (const sql::SqliteError& e) {
      // The commit is in the WAL; copying it into the database file waits for space.
      if (!worth_retrying(e)) throw;
      spdlog::warn("recorder: checkpoint postponed: {}", e.what());
    }
    last_checkpoint_ = Clock::now();
  }
  const double took_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const LeaseCounters published = lease_->counters();
  RecorderStats snapshot;
  {
    std::lock_guard lock(mutex_);
    stats_.committed_frames = published.committed_frames;
    stats_.stored_frames = published.frames_at_open + published.committed_frames;
    if (published.committed_frames > 0 || stats_.committed_t_ns) stats_.committed_t_ns = published.committed_t_ns;
    ++stats_.commits;
    release_batch_locked();
    if (write_problem_) {
      spdlog::info("recorder '{}': the run file can be written again; recording goes on", path_);
      write_problem_.reset();
    }
    stats_.last_commit_s = took_s;
    stats_.max_commit_s = std::max(stats_.max_commit_s, took_s);
    snapshot = stats_;
  }
  if (on_commit_) on_commit_(snapshot);
}

void Recorder::run() {
  const auto interval =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options_.commit_interval_s));
  last_checkpoint_ = Clock::now();
  std::unique_lock lock(mutex_);
  try {
    for (;;) {
      if (write_problem_) {
        // Holding a failed batch: the next attempt when its time comes, or at once when closing
        // (the last chance to write what is held).
        cv_work_.wait_until(lock, retry_at_, [&] { return closing_; });
      }
      const auto deadline = batch_dirty_ ? batch_started_ + interval : Clock::time_point::max();
      cv_work_.wait_until(lock, deadline, [&] {
        return !queue_.empty() || !pending_drops_.empty() || closing_ ||
               (batch_dirty_ && Clock::now() >= deadline);
      });
      if (queue_.empty() && pending_drops_.empty() && closing_) break;

      std::optional<Item> item;
      std::vector<DroppedSpan> drops;
      if (!queue_.empty()) {
        item = std::move(queue_.front());
        queue_.pop_front();
      }
      drops.swap(pending_drops_);
      lock.unlock();

      // Kept until the batch commits, from before anything is written (a write that fails has
      // them), so that a batch that fails can be written again.
      const bool barrier = item && item->kind == Item::Kind::Barrier;
      const Item* kept = nullptr;
      if (item && !barrier) {
        batch_items_.push_back(std::move(*item));
        kept = &batch_items_.back();
        if (kept->kind == Item::Kind::Frames) batch_frames_ += static_cast<std::int64_t>(kept->frames.size());
      }
      batch_drops_.insert(batch_drops_.end(), drops.begin(), drops.end());
      std::optional<std::string> failed;
      bool failed_full = false;
      try {
        if ((item || !drops.empty()) && !batch_dirty_) {
          db_.begin_batch();
          batch_dirty_ = true;
          batch_started_ = Clock::now();
        }
        for (const auto& span : drops) db_.record_dropped(span.t0_ns, span.t1_ns, span.frames);
        if (kept != nullptr) {
          switch (kept->kind) {
            case Item::Kind::Frames:
              db_.append(kept->frames);
              break;
            case Item::Kind::Temps:
              db_.append_temps(kept->temps);
              break;
            case Item::Kind::Segments:
              db_.set_segments(kept->segments);
              break;
            case Item::Kind::Extra:
              db_.set_extra(kept->key, kept->text);
              break;
            case Item::Kind::Barrier:
              break;
          }
        }
        // A batch also commits once it holds half the queue's capacity: its frames stay in memory
        // (and in the bound) until they are committed, so a producer faster than one commit
        // interval must not wait for the interval to end.
        if (batch_dirty_ && (barrier || Clock::now() >= batch_started_ + interval ||
                             2 * batch_frames_ >= options_.queue_capacity_frames))
          commit_batch();
      } catch (const sql::SqliteError& e) {
        // Only a batch the RunDb has rolled back can be written again.
        if (!worth_retrying(e) || db_.in_batch()) throw;
        failed = e.what();
        failed_full = e.kind() == sql::SqliteError::Kind::full;
      }

      lock.lock();
      if (failed) {
        const bool first = !write_problem_;
        const std::string message =
            hold_failed_batch_locked(*failed, failed_full, barrier ? std::optional(item->barrier) : std::nullopt);
        if (first) {
          lock.unlock();
          spdlog::warn("recorder: {}", message);
          raise(RecorderAlarmKind::WriteHeld, message);
          lock.lock();
        }
        continue;
      }
      if (barrier) {
        done_barrier_ = std::max(done_barrier_, item->barrier);
        cv_barrier_.notify_all();
      }
    }
    lock.unlock();
    if (batch_dirty_) {
      try {
        commit_batch();
      } catch (const sql::SqliteError& e) {
        if (!worth_retrying(e)) throw;
        lock.lock();
        (void)hold_failed_batch_locked(e.what(), e.kind() == sql::SqliteError::Kind::full, std::nullopt);  // throws: closing
      }
    }
    db_.close();  // the clean end of the writer session: the next open needs no recovery
    lock.lock();
  } catch (const std::exception& e) {
    if (!lock.owns_lock()) lock.lock();
    error_ = e.what();
    write_problem_.reset();
    queue_.clear();
    batch_items_.clear();
    stats_.queued_frames = 0;
    stats_.held_frames = 0;
    lock.unlock();
    spdlog::error("recorder: {}", e.what());
    raise(RecorderAlarmKind::WriteFailed, std::string("recording stopped: ") + e.what());
    // Not closed as a clean end: the next open recovers the run and counts the accepted frames
    // that were never committed.
    db_.abandon(e.what());
    lock.lock();
  }
  // Wake every waiter: barriers are satisfied (or failed), producers must not wait for space.
  done_barrier_ = next_barrier_;
  cv_barrier_.notify_all();
  cv_space_.notify_all();
}

}  // namespace imucal::storage
