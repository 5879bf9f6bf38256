// The run engine's documents (after Bluesky's RunEngine: the loop emits what happens, subscribers
// store, display and alarm; docs/ARCHITECTURE.md "The run engine"). The loop (engine.cpp) drives
// the devices, the suspenders and the state machine and knows no database; everything it wants
// kept or shown leaves it as one of these, delivered to each subscriber in the order they were
// subscribed (the service database first, so that what the others show is stored).
//
// Threads: a document is delivered on the thread that emits it, synchronously. Most come from the
// run's thread (RunResults too: the estimators finish during RunEnding); FramesCommitted from the
// recording's writer thread; EstimatorProgress from the estimators' worker thread; a Transition
// from the thread that changed the state (an operator's request), in the order the changes were
// made (each change takes a ticket under the sequencer's lock and is delivered in its turn, the
// lock released). A subscriber must be quick (RunEnding excepted) and must not change a run's
// state; it may read the sequencer.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/db/run_state.hpp"

namespace imucal::daemon {

struct CampaignSpec;

// The run begins (a first start or a resume), its run file open: what it runs and where it records.
struct RunStart {
  std::int64_t campaign = 0;
  const CampaignSpec* spec = nullptr;   // lives as long as the run
  std::string run_file;                 // its path
  std::string run_file_relative;        // under the data directory ("runs/7.db")
  bool resuming = false;                // the run file existed: an earlier start recorded into it
  std::optional<std::int64_t> committed_t_ns;  // the last frame the run file holds
};

// A change of a campaign's state. The active run's state lives in the sequencer and the service
// database follows it through this document (`stored` false); a campaign not running has its
// state in the database, changed there by the sequencer (a compare-and-set) before the document
// says so (`stored` true).
struct Transition {
  std::int64_t campaign = 0;
  RunState from = RunState::Created, to = RunState::Created;
  std::string reason;
  bool stored = false;
};

// Something that happened in a run ("info", "alarm", "error", "suspended", "redo", ...); a serious
// kind raises an alarm (subscribers/alarms.hpp).
struct RunEvent {
  std::int64_t campaign = 0;
  std::string kind;
  std::optional<std::int64_t> segment;
  std::optional<double> program_time_s;
  std::string reason;
};

// A segment begins: where a resume takes up if the run stops inside it.
struct Checkpoint {
  std::int64_t campaign = 0;
  std::int64_t segment = 0;
  double t_s = 0.0;
};

// The run's counters, as they are now.
struct RunCounters {
  double program_time_s = 0.0;
  std::int64_t frames = 0, lost = 0, bad = 0;
};

// What the run looks like now, at most 20 times a second and whenever it changes state: the live
// telemetry's body (docs/api.md "Live", without "estimators", which the live feed adds from
// EstimatorProgress), and its counters. `force`: a moment that must be seen and stored (a hold,
// the run's end), not one of many.
struct Snapshot {
  std::int64_t campaign = 0;
  nlohmann::json telemetry;
  RunCounters counters;
  bool force = false;
};

// The run file holds every frame up to t_ns (recording's writer thread).
struct FramesCommitted {
  std::int64_t campaign = 0;
  std::int64_t t_ns = 0;
};

// An online estimator's progress (the estimators' worker thread).
struct EstimatorProgress {
  std::int64_t campaign = 0;
  std::string estimator;
  double program_time_s = 0.0;
  nlohmann::json progress;
};

// The program has ended (or the run ends early): `results` says whether the run's estimators give
// results from the data so far (done, stopped, aborted, failed) or are cancelled (interrupted).
// The estimators' subscriber finishes here, on the run's thread, calling `while_waiting` about
// every 200 ms (the run goes on publishing snapshots while they work through the recording's
// tail), and emits RunResults.
struct RunEnding {
  std::int64_t campaign = 0;
  bool results = false;
  std::optional<std::int64_t> last_t_ns;  // the last frame recorded
  std::function<void()> while_waiting;
};

// The estimators' final results: each estimator's report (or why there is none) and the last
// calibration stage's model (imucal-imu-model/1 text), when one was calibrated; or, `failed`, why
// they could not finish ({"error": ...}).
struct RunResults {
  std::int64_t campaign = 0;
  nlohmann::json results;
  std::optional<std::string> model_json;
  bool failed = false;
};

// Why the run failed (kept with the campaign).
struct RunError {
  std::int64_t campaign = 0;
  std::string why;
};

// The run's closing figures, before its last transition: its counters, and whether a run ending
// in a final state ran its whole program (`complete`; nothing for an interrupted one).
struct RunStop {
  std::int64_t campaign = 0;
  RunCounters counters;
  std::optional<bool> complete;
};

// A subscriber overrides what it takes; the rest it ignores. Adding one: docs/ARCHITECTURE.md.
class RunSubscriber {
 public:
  virtual ~RunSubscriber() = default;
  virtual void start(const RunStart&) {}
  virtual void transition(const Transition&) {}
  virtual void event(const RunEvent&) {}
  virtual void checkpoint(const Checkpoint&) {}
  virtual void snapshot(const Snapshot&) {}
  virtual void frames_committed(const FramesCommitted&) {}
  virtual void progress(const EstimatorProgress&) {}
  virtual void ending(const RunEnding&) {}
  virtual void results(const RunResults&) {}
  virtual void error(const RunError&) {}
  virtual void stop(const RunStop&) {}
};

// The subscribers of every run, in order. Subscribed before the first run starts; never changed
// while one runs (no lock on the list).
class Documents {
 public:
  void subscribe(RunSubscriber& subscriber) { subscribers_.push_back(&subscriber); }
  // A subscriber that emits documents while it takes one (the estimators: their results during
  // RunEnding) is given each document after every other subscriber, so that all of them see the
  // documents in the order they were made.
  void subscribe_emitter(RunSubscriber& subscriber) { emitters_.push_back(&subscriber); }
  template <typename Document>
  void emit(void (RunSubscriber::*deliver)(const Document&), const Document& document) const {
    for (RunSubscriber* s : subscribers_) (s->*deliver)(document);
    for (RunSubscriber* s : emitters_) (s->*deliver)(document);
  }

 private:
  std::vector<RunSubscriber*> subscribers_, emitters_;
};

}  // namespace imucal::daemon
