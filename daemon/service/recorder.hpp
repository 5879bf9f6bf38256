// The recorder: a thread that owns the run database (storage::RunDb) and writes what the
// sequencer hands it through a bounded queue, committing at least every commit interval (and at
// every checkpoint the sequencer asks for). The sequencer never touches SQLite on its own thread.
//
// Backpressure: with simulated devices the producer waits when the queue is full (the simulation
// slows down to the disk's speed); with real devices a full queue drops the batch, counts the
// frames and raises an alarm, so that recording never blocks the device readers.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/recording.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

struct RecorderStats {
  std::int64_t queued_frames = 0;
  std::int64_t high_water_frames = 0;
  std::int64_t committed_frames = 0;      // frames in the run file after the last commit
  std::int64_t dropped_frames = 0;        // real devices only: queue overflow
  std::optional<std::int64_t> committed_t_ns;  // time of the last committed frame
  std::int64_t commits = 0;
};

class Recorder {
 public:
  // Called on the recorder thread after every commit (the estimator worker tails the file).
  using CommitListener = std::function<void(const RecorderStats&)>;

  Recorder(storage::RunDb db, double commit_interval_s, std::int64_t queue_frames, CommitListener on_commit);
  ~Recorder();  // close()
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  enum class Push { Queued, Dropped, Failed };
  // Queues frames (strictly after everything queued before). `wait_when_full`: block while the
  // queue is full instead of dropping. Failed when the recorder has failed (see error()).
  Push push_frames(std::vector<ImuFrame> frames, bool wait_when_full);
  bool push_temps(std::vector<TempSample> temps);
  void set_extra(const std::string& key, const std::string& json_text);
  // Waits until everything queued so far is committed. False when the recorder has failed.
  bool commit_and_wait();
  // Commits the rest and ends the thread (idempotent).
  void close();

  RecorderStats stats() const;
  std::optional<std::string> error() const;
  const std::string& path() const { return path_; }

 private:
  struct Item {
    enum class Kind { Frames, Temps, Extra, Barrier } kind = Kind::Frames;
    std::vector<ImuFrame> frames;
    std::vector<TempSample> temps;
    std::string key, text;
    std::uint64_t barrier = 0;
  };
  void run();
  Push enqueue(Item item, std::int64_t frames, bool wait_when_full);

  storage::RunDb db_;
  std::string path_;
  double commit_interval_s_;
  std::int64_t queue_capacity_frames_;
  CommitListener on_commit_;

  mutable std::mutex mutex_;
  std::condition_variable cv_work_, cv_space_, cv_barrier_;
  std::deque<Item> queue_;
  RecorderStats stats_;
  std::uint64_t next_barrier_ = 1, done_barrier_ = 0;
  bool closing_ = false;
  std::optional<std::string> error_;
  std::vector<TempSample> pending_temps_;      // recorder thread only: written with the next commit
  std::int64_t appended_frames_ = 0;           // recorder thread only
  std::optional<std::int64_t> appended_t_ns_;  // recorder thread only
  std::thread thread_;
};

}  // namespace imucal::daemon
