#include "daemon/registry/certificate_sequence.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "storage/durable_file.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

constexpr const char* kFormat = "imucal-certificate-sequence/1";
// Clocks kept by NTP agree to milliseconds: a minute apart is a clock set wrong.
constexpr std::int64_t kClockBehindWarning_ms = 60'000;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error("certificate sequence file '" + path + "': " + what);
}

std::string os_error() { return std::strerror(errno); }

// Holds an exclusive flock on PATH.lock for its lifetime. The lock is on a file of its own:
// the sequence file itself is replaced by rename, which a lock on its old inode would not cover.
class FileLock {
 public:
  explicit FileLock(const std::string& path) {
    const std::string lock_path = path + ".lock";
    fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) fail(path, "cannot open its lock file " + lock_path + ": " + os_error());
    // Blocking: another daemon holds it only for the few milliseconds of one number.
    while (::flock(fd_, LOCK_EX) != 0) {
      if (errno == EINTR) continue;
      const std::string why = os_error();
      ::close(fd_);
      fail(path, "cannot lock " + lock_path + ": " + why);
    }
  }
  ~FileLock() { ::close(fd_); }  // closing releases the lock
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_ = -1;
};

// Replaces `path` with `text` so that a crash leaves either the old or the new file, complete.
void replace_file(const std::string& path, const std::string& text) {
  try {
    storage::replace_file_durably(path, text);  // one writer at a time: under the lock
  } catch (const storage::FileError& e) {
    fail(path, e.what());
  }
}

}  // namespace

CertificateSequence::CertificateSequence(std::string path) : path_(std::move(path)) {}

CertificateSequence::Taken CertificateSequence::read_last() const {
  std::ifstream in(path_);
  if (!in) {
    if (!std::filesystem::exists(path_)) return {};  // the site's first certificate
    fail(path_, "cannot read it");
  }
  std::stringstream text;
  text << in.rdbuf();
  // A damaged file must stop the daemon from issuing numbers, not restart them at 1.
  const json j = json::parse(text.str(), nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.value("format", std::string()) != kFormat)
    fail(path_, std::string("not an ") + kFormat + " file; repair it by hand (its \"last\" number must not go back)");
  const auto last = j.find("last");
  if (last == j.end() || !last->is_number_integer() || last->get<std::int64_t>() < 0)
    fail(path_, "\"last\" must be a whole number >= 0");
  // Files written before the time was kept have none: the next number takes its own clock's.
  const auto issued = j.find("last_issued_ms");
  if (issued != j.end() && !issued->is_number_integer())
    fail(path_, "\"last_issued_ms\" must be a whole number of milliseconds");
  return {last->get<std::int64_t>(), issued == j.end() ? 0 : issued->get<std::int64_t>()};
}

std::int64_t CertificateSequence::last() const {
  std::lock_guard guard(mutex_);
  FileLock lock(path_);
  return read_last().number;
}

CertificateSequence::Taken CertificateSequence::take(std::int64_t floor, std::int64_t now_ms) {
  std::lock_guard guard(mutex_);
  const auto dir = std::filesystem::path(path_).parent_path();
  std::error_code ec;
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
  if (ec) fail(path_, "cannot create its directory: " + ec.message());
  FileLock lock(path_);
  const Taken last = read_last();
  const Taken taken{std::max(last.number, floor) + 1, std::max(last.issued_ms, now_ms)};
  // Dated by another daemon's clock ahead of this one's: said, so that a clock set wrong (which
  // would date every later certificate by it) is seen and set right.
  if (last.issued_ms - now_ms > kClockBehindWarning_ms)
    spdlog::warn("certificate {}: dated {} s later than this computer's clock, by the last number's time in the "
                 "shared sequence file '{}' (another daemon's clock ahead): set the clocks of the daemons sharing it",
                 taken.number, (last.issued_ms - now_ms) / 1000, path_);
  replace_file(path_, json{{"format", kFormat},
                           {"last", taken.number},
                           {"last_issued_ms", taken.issued_ms},
                           {"comment", "imucald's certificate numbers on this site: never edit \"last\" downwards"}}
                              .dump(1) + "\n");
  return taken;
}

}  // namespace imucal::daemon
