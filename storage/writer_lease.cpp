#include "storage/writer_lease.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>

#include "storage/run_db.hpp"
#include "storage/sqlite.hpp"

namespace imucal::storage {

// The page as it lies in the file (native layout: the lease never leaves the machine).
struct WriterLease::Page {
  std::uint64_t magic;
  std::uint32_t version;
  std::int32_t pid;
  std::int64_t started_unix_ms;
  std::int64_t session_id;
  std::int64_t frames_at_open;
  std::int64_t accepted_frames;
  std::int64_t accepted_t_ns;
  std::int64_t committed_frames;
  std::int64_t committed_t_ns;
  std::int64_t dropped_frames;
  std::int64_t high_water_frames;
};

namespace {

constexpr std::uint64_t kMagic = 0x4553414C43554D49ULL;  // "IMUCLASE"
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kFileBytes = 4096;

[[noreturn]] void fail_errno(const std::string& db_path, const std::string& what) {
  const int err = errno;
  throw StorageError("run database '" + db_path + "': " + what + ": " + std::strerror(err));
}

// One byte at offset 0 stands for the whole run; OFD locks belong to the open file description,
// not the process, so they also keep two RunDbs of one process apart, and closing an unrelated
// descriptor of the file does not drop them (unlike classic POSIX locks).
struct flock lock_request(short type) {
  struct flock request {};
  request.l_type = type;
  request.l_whence = SEEK_SET;
  request.l_start = 0;
  request.l_len = 1;
  return request;
}

std::optional<LeaseCounters> read_page(int fd) {
  WriterLease::Page page{};
  if (::pread(fd, &page, sizeof(page), 0) != static_cast<ssize_t>(sizeof(page))) return std::nullopt;
  if (page.magic != kMagic || page.version != kVersion) return std::nullopt;
  LeaseCounters c;
  c.pid = page.pid;
  c.started_unix_ms = page.started_unix_ms;
  c.session_id = page.session_id;
  c.frames_at_open = page.frames_at_open;
  c.accepted_frames = page.accepted_frames;
  c.accepted_t_ns = page.accepted_t_ns;
  c.committed_frames = page.committed_frames;
  c.committed_t_ns = page.committed_t_ns;
  c.dropped_frames = page.dropped_frames;
  c.high_water_frames = page.high_water_frames;
  return c;
}

std::string describe_holder(const std::optional<LeaseCounters>& counters) {
  if (!counters) return "another writer";
  const std::time_t started = static_cast<std::time_t>(counters->started_unix_ms / 1000);
  char when[64] = "?";
  std::tm tm{};
  if (::gmtime_r(&started, &tm) != nullptr) std::strftime(when, sizeof(when), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return "process " + std::to_string(counters->pid) + " (recording since " + when + ")";
}

}  // namespace

WriterLease::WriterLease(std::string path, int fd, Page* page) : path_(std::move(path)), fd_(fd), page_(page) {}

WriterLease::~WriterLease() { release(false); }

std::unique_ptr<WriterLease> WriterLease::acquire(const std::string& db_path, std::chrono::milliseconds patience) {
  const std::string path = lease_path(db_path);
  // A releasing writer unlinks the file while holding the lock; whoever locked the unlinked
  // inode meanwhile must start over on the new file, or two writers would each hold "the" lease.
  // A reader that finds a dead writer's run recovers it under the lease, for milliseconds: a
  // writer opening the run meanwhile (imucald resuming a run after a crash while a viewer looks at
  // it) waits for that instead of failing the run. A live writer holds the lease for good.
  const auto wait_until = std::chrono::steady_clock::now() + patience;
  for (int attempt = 0; attempt < 100; ++attempt) {
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) fail_errno(db_path, "cannot open the writer lease '" + path + "'");
    struct flock request = lock_request(F_WRLCK);
    if (::fcntl(fd, F_OFD_SETLK, &request) != 0) {
      const int err = errno;
      const auto holder = read_page(fd);
      ::close(fd);
      if ((err == EAGAIN || err == EACCES) && std::chrono::steady_clock::now() < wait_until) {
        ::usleep(10'000);
        --attempt;
        continue;
      }
      if (err == EAGAIN || err == EACCES) {
        throw StorageError("run database '" + db_path + "': the run is being recorded by " + describe_holder(holder) +
                           "; only one writer may hold a run (stop it, or open the run for reading only)");
      }
      errno = err;
      fail_errno(db_path, "cannot lock the writer lease '" + path + "'");
    }
    struct stat by_fd {}, by_path {};
    if (::fstat(fd, &by_fd) != 0 || ::stat(path.c_str(), &by_path) != 0 || by_fd.st_ino != by_path.st_ino ||
        by_fd.st_dev != by_path.st_dev) {
      ::close(fd);
      continue;
    }
    std::optional<LeaseCounters> previous = read_page(fd);
    if (::ftruncate(fd, static_cast<off_t>(kFileBytes)) != 0) {
      const int err = errno;
      ::close(fd);
      errno = err;
      fail_errno(db_path, "cannot size the writer lease '" + path + "'");
    }
    void* mapped = ::mmap(nullptr, kFileBytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (mapped == MAP_FAILED) {
      const int err = errno;
      ::close(fd);
      errno = err;
      fail_errno(db_path, "cannot map the writer lease '" + path + "'");
    }
    std::unique_ptr<WriterLease> lease(new WriterLease(path, fd, static_cast<Page*>(mapped)));
    lease->previous_ = previous;
    return lease;
  }
  throw StorageError("run database '" + db_path + "': the writer lease '" + path +
                     "' keeps being replaced; another process is opening and closing the run");
}

WriterLease::Probe WriterLease::probe(const std::string& db_path) {
  Probe probe;
  const std::string path = lease_path(db_path);
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return probe;  // no lease file: nobody writes, and nobody died writing
  struct flock request = lock_request(F_WRLCK);
  if (::fcntl(fd, F_OFD_GETLK, &request) == 0) {
    probe.held = request.l_type != F_UNLCK;
  } else {
    probe.held = true;  // cannot tell: assume a writer, which only skips a recovery
  }
  probe.counters = read_page(fd);
  ::close(fd);
  return probe;
}

void WriterLease::begin_session(std::int64_t session_id, std::int64_t frames_at_open) {
  Page fresh{};
  fresh.magic = kMagic;
  fresh.version = kVersion;
  fresh.pid = static_cast<std::int32_t>(::getpid());
  fresh.started_unix_ms = unix_ms_now();
  fresh.session_id = session_id;
  fresh.frames_at_open = frames_at_open;
  std::memcpy(static_cast<void*>(page_), &fresh, sizeof(fresh));
}

// std::atomic_ref on the mapped words: lock-free 64-bit stores that a reader in another process
// (or after a crash) sees whole.
namespace {
std::int64_t load(std::int64_t& word) { return std::atomic_ref<std::int64_t>(word).load(std::memory_order_acquire); }
void store(std::int64_t& word, std::int64_t value) {
  std::atomic_ref<std::int64_t>(word).store(value, std::memory_order_release);
}
}  // namespace

void WriterLease::add_accepted(std::int64_t frames, std::int64_t last_t_ns) {
  // Time first: a reader that sees the new count also sees a time at least that recent.
  store(page_->accepted_t_ns, last_t_ns);
  std::atomic_ref<std::int64_t>(page_->accepted_frames).fetch_add(frames, std::memory_order_acq_rel);
}

void WriterLease::set_committed(std::int64_t frames, std::int64_t last_t_ns) {
  store(page_->committed_t_ns, last_t_ns);
  store(page_->committed_frames, frames);
}

void WriterLease::add_dropped(std::int64_t frames) {
  std::atomic_ref<std::int64_t>(page_->dropped_frames).fetch_add(frames, std::memory_order_acq_rel);
}

void WriterLease::raise_high_water(std::int64_t frames) {
  std::atomic_ref<std::int64_t> word(page_->high_water_frames);
  std::int64_t seen = word.load(std::memory_order_relaxed);
  while (frames > seen && !word.compare_exchange_weak(seen, frames, std::memory_order_acq_rel)) {
  }
}

LeaseCounters WriterLease::counters() const {
  LeaseCounters c;
  c.pid = page_->pid;
  c.started_unix_ms = page_->started_unix_ms;
  c.session_id = page_->session_id;
  c.frames_at_open = page_->frames_at_open;
  c.accepted_frames = load(page_->accepted_frames);
  c.accepted_t_ns = load(page_->accepted_t_ns);
  c.committed_frames = load(page_->committed_frames);
  c.committed_t_ns = load(page_->committed_t_ns);
  c.dropped_frames = load(page_->dropped_frames);
  c.high_water_frames = load(page_->high_water_frames);
  return c;
}

void WriterLease::release(bool clean) {
  if (fd_ < 0) return;
  if (clean) ::unlink(path_.c_str());  // still locked: see acquire()
  ::munmap(page_, kFileBytes);
  ::close(fd_);  // drops the lock
  fd_ = -1;
  page_ = nullptr;
}

}  // namespace imucal::storage
