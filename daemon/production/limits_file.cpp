#include "daemon/production/limits_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace imucal::daemon {

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

void write_durably(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot write " + tmp + ": " + std::strerror(errno));
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const std::string why = std::strerror(errno);
      ::close(fd);
      throw std::runtime_error("cannot write " + tmp + ": " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  const bool synced = ::fsync(fd) == 0;
  ::close(fd);
  if (!synced) throw std::runtime_error("cannot write " + tmp + ": fsync failed");
  fs::rename(tmp, path);
}

}  // namespace

LimitsFile::LimitsFile(std::string path) : path_(std::move(path)) {
  limits_.source = fs::path(path_).filename().string();
  std::ifstream in(path_);
  if (!in) return;
  std::stringstream text;
  text << in.rdbuf();
  const json j = json::parse(text.str(), nullptr, false);
  if (j.is_discarded()) throw std::runtime_error("acceptance limits " + path_ + ": not valid JSON");
  try {
    limits_.parts = limits_from_json(j);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error("acceptance limits " + path_ + ": " + e.what());
  }
}

AcceptanceLimits LimitsFile::current() const {
  std::lock_guard lock(mutex_);
  return limits_;
}

json LimitsFile::document() const {
  std::lock_guard lock(mutex_);
  return limits_to_json(limits_.parts);
}

void LimitsFile::replace(const json& document) {
  auto parts = limits_from_json(document);  // throws before anything changes
  std::lock_guard lock(mutex_);
  if (const fs::path dir = fs::path(path_).parent_path(); !dir.empty()) fs::create_directories(dir);
  write_durably(path_, limits_to_json(parts).dump(2) + "\n");
  limits_.parts = std::move(parts);
}

}  // namespace imucal::daemon
