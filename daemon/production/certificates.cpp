#include "daemon/production/certificates.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/earth.hpp"
#include "daemon/production/reference_equipment.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

constexpr const char* kFormat = "imucal-certificate-sequence/1";

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

void write_all(int fd, const std::string& text, const std::string& path) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail(path, "cannot write: " + os_error());
    done += static_cast<std::size_t>(n);
  }
}

// Replaces `path` with `text` so that a crash leaves either the old or the new file, complete.
void replace_file(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";  // one writer at a time: under the lock
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail(path, "cannot create " + tmp + ": " + os_error());
  try {
    write_all(fd, text, tmp);
    if (::fsync(fd) != 0) fail(path, "cannot fsync " + tmp + ": " + os_error());
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
  if (::rename(tmp.c_str(), path.c_str()) != 0) fail(path, "cannot rename " + tmp + " onto it: " + os_error());
  // The rename itself is durable only once the directory is.
  const std::string dir = std::filesystem::path(path).parent_path().string();
  const int dfd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace

CertificateSequence::CertificateSequence(std::string path) : path_(std::move(path)) {}

std::int64_t CertificateSequence::read_last() const {
  std::ifstream in(path_);
  if (!in) {
    if (!std::filesystem::exists(path_)) return 0;  // the site's first certificate
    fail(path_, "cannot read it");
  }
  std::stringstream text;
  text << in.rdbuf();
  // A damaged file must stop the daemon from issuing numbers, not restart them at 1.
  const json j = json::parse(text.str(), nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.value("format", std::string()) != kFormat)
    fail(path_, std::string("not an ") + kFormat + " file; repair it by hand (its \"last\" number must not go back)");
  const auto it = j.find("last");
  if (it == j.end() || !it->is_number_integer() || it->get<std::int64_t>() < 0)
    fail(path_, "\"last\" must be a whole number >= 0");
  return it->get<std::int64_t>();
}

std::int64_t CertificateSequence::last() const {
  std::lock_guard guard(mutex_);
  FileLock lock(path_);
  return read_last();
}

std::int64_t CertificateSequence::next(std::int64_t floor) {
  std::lock_guard guard(mutex_);
  const auto dir = std::filesystem::path(path_).parent_path();
  std::error_code ec;
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
  if (ec) fail(path_, "cannot create its directory: " + ec.message());
  FileLock lock(path_);
  const std::int64_t number = std::max(read_last(), floor) + 1;
  replace_file(path_, json{{"format", kFormat},
                           {"last", number},
                           {"comment", "imucald's certificate numbers on this site: never edit \"last\" downwards"}}
                              .dump(1) + "\n");
  return number;
}

std::string certificate_number(const std::string& prefix, int year, std::int64_t sequence) {
  char digits[32];
  std::snprintf(digits, sizeof digits, "%04d-%06lld", year, static_cast<long long>(sequence));
  return prefix + "-" + digits;
}

json certificate_bench_json(const DaemonConfig& config, std::int64_t campaign_ended_ms) {
  const bool configured = config.site.gravity_mps2.has_value();
  return {{"devices", config.devices},
          {"simulated", config.devices.rfind("sim", 0) == 0},
          // Judged on the day the run ended: out of calibration when it was used.
          {"reference_equipment", reference_equipment_json(config, utc_day(campaign_ended_ms), false)},
          {"gravity",
           {{"value_mps2", earth::site_gravity_mps2(config.site)},
            {"sigma_mps2", earth::site_gravity_sigma_mps2(config.site)},
            {"source", configured ? "configured" : "normal_gravity"},
            {"latitude_deg", config.site.latitude_deg},
            {"height_m", config.site.height_m}}}};
}

}  // namespace imucal::daemon
