// The writer lease of a run file: `<run>-writer` beside the database makes one RunDb at a time the
// run's only writer (an open-file-description lock, so a second process -- or a second RunDb in the
// same process -- gets a clear error instead of interleaving frames), and carries a page of
// progress counters that the writer updates in shared memory. The page survives a crash of the
// writer (kill -9 leaves the kernel's page cache intact), so the next open can tell how many
// frames the recorder had accepted but never committed.
//
// The file exists while a writer holds it and after a writer died; a clean close removes it.
#pragma once

#include <chrono>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace imucal::storage {

// What a writer published in its lease page. Frames counts are within the writer's session.
struct LeaseCounters {
  std::int32_t pid = 0;
  std::int64_t started_unix_ms = 0;
  std::int64_t session_id = 0;          // recorder_session.id in the run
  std::int64_t frames_at_open = 0;      // frames in the run when the session began
  std::int64_t accepted_frames = 0;     // handed to the writer (queue or RunDb::append)
  std::int64_t accepted_t_ns = 0;       // time of the last accepted frame (valid if accepted > 0)
  std::int64_t committed_frames = 0;    // committed by the session
  std::int64_t committed_t_ns = 0;      // time of the last committed frame (valid if committed > 0)
  std::int64_t dropped_frames = 0;
  std::int64_t high_water_frames = 0;
};

class WriterLease {
 public:
  // Takes the lease of `db_path`; throws StorageError naming the holder when another writer has it
  // (still, after waiting up to `patience` for it: a reader recovering a dead writer's run holds
  // it for milliseconds).
  static std::unique_ptr<WriterLease> acquire(const std::string& db_path,
                                              std::chrono::milliseconds patience = std::chrono::milliseconds(0));

  struct Probe {
    bool held = false;                      // a live writer holds the lease now
    std::optional<LeaseCounters> counters;  // the page, if the file exists and is valid
  };
  // Looks at the lease without taking it (a reader's question: is someone writing, or did a
  // writer die?).
  static Probe probe(const std::string& db_path);

  static std::string lease_path(const std::string& db_path) { return db_path + "-writer"; }

  ~WriterLease();  // release(false)
  WriterLease(const WriterLease&) = delete;
  WriterLease& operator=(const WriterLease&) = delete;

  // Starts a session: resets the page. Counters the lease held before (a crashed writer's) are
  // returned by previous().
  void begin_session(std::int64_t session_id, std::int64_t frames_at_open);
  const std::optional<LeaseCounters>& previous() const { return previous_; }

  // Thread-safe, wait-free: the producer thread publishes what it hands over, the writer thread
  // what it commits.
  void add_accepted(std::int64_t frames, std::int64_t last_t_ns);
  void set_committed(std::int64_t frames, std::int64_t last_t_ns);
  void add_dropped(std::int64_t frames);
  void raise_high_water(std::int64_t frames);
  LeaseCounters counters() const;

  // Gives the lease up. `clean`: the session ended with everything committed, so the file is
  // removed; otherwise it stays for the next open's recovery.
  void release(bool clean);

  struct Page;  // the file's layout (writer_lease.cpp)

 private:
  WriterLease(std::string path, int fd, Page* page);
  std::string path_;
  int fd_ = -1;
  Page* page_ = nullptr;
  std::optional<LeaseCounters> previous_;
};

}  // namespace imucal::storage
