// The run file as the run loop sees it: where frames and temperatures go, with back-pressure (the
// loop must know at once whether the file took them, to hold and redo what it did not). The loop
// includes no storage header; the implementation over storage's Recorder and RunDb is a
// subscriber's (subscribers/run_file.hpp), which also keeps the run's record in the file.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/recording.hpp"

namespace imucal::daemon {

struct RecordingStats {
  std::int64_t queued_frames = 0;  // accepted, not yet committed
  std::int64_t queue_capacity_frames = 0;
  std::int64_t high_water_frames = 0;
  std::int64_t stored_frames = 0;  // in the file after the last commit (earlier runs too)
  std::int64_t dropped_frames = 0;
};

// What the recording reports, for the run to note and to suspend on.
struct RecordingAlarm {
  enum class Kind {
    QueueHighWater,  // the writer falls behind
    FramesDropped,   // a batch did not fit the queue and was dropped
    WriteHeld,       // the file cannot be written now; held in memory, retried
    WriteFailed,     // the file cannot be written; recording stopped
  };
  Kind kind = Kind::QueueHighWater;
  std::string kind_name;  // "queue high-water", ... as the recorder names it
  std::string message;
  RecordingStats stats;
};

class RunRecording {
 public:
  virtual ~RunRecording() = default;
  enum class Push { Queued, Dropped, Rejected, Failed, Refused };
  // Frames after the last one taken; Refused: the file cannot be written now, nothing after
  // last_accepted_t_ns() was taken.
  virtual Push push(const std::vector<ImuFrame>& frames) = 0;
  virtual bool push_temps(const std::vector<TempSample>& temps) = 0;
  virtual std::optional<std::int64_t> last_accepted_t_ns() const = 0;
  // Commits what is queued and waits; false when it cannot now (write_problem) or has failed.
  virtual bool commit_and_wait() = 0;
  virtual bool close() = 0;
  virtual RecordingStats stats() const = 0;
  virtual std::optional<std::string> error() const = 0;
  virtual std::optional<std::string> write_problem() const = 0;
  // The alarms raised since the last call (on any thread), oldest first.
  virtual std::vector<RecordingAlarm> take_alarms() = 0;
  // Whether a producer waits for room in the queue (a simulated bench) rather than dropping
  // frames (devices that cannot wait).
  virtual bool waits_when_full() const = 0;
};

// Where the run file left off when it was opened: the resume point.
struct RecordingOpened {
  std::unique_ptr<RunRecording> recording;
  std::optional<std::int64_t> last_frame_t_ns, last_temperature_t_ns;
  std::int64_t frames = 0;
};

class RecordingFactory {
 public:
  virtual ~RecordingFactory() = default;
  struct Request {
    std::int64_t campaign = 0;
    std::string path;
    RecordingMeta meta;       // written when the file is created
    bool paced_by_consumer = false;  // the bench waits for the recorder (simulation)
    // Called on the writer thread after each commit with the last committed frame's time.
    std::function<void(std::int64_t)> committed;
  };
  // Creates the run file, or opens it (recovering it after a crash or a failed write).
  virtual RecordingOpened open(const Request& request) = 0;
};

}  // namespace imucal::daemon
