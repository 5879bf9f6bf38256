// The acceptance limits file (imucal-limits/1) the daemon judges runs by: read at start, replaced
// whole by an operator (PUT /api/limits). Thin I/O around acceptance.hpp's parser.
#pragma once

#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/production/acceptance.hpp"

namespace imucal::daemon {

class LimitsFile {
 public:
  // Reads `path` if it exists (no file: no limits). Throws std::runtime_error naming the file and
  // the entry at fault: a daemon must not judge units by limits it misread.
  explicit LimitsFile(std::string path);

  AcceptanceLimits current() const;
  // The file as JSON (the empty imucal-limits/1 document when there is none).
  nlohmann::json document() const;
  // Validates and writes a new file (temporary file, fsync, rename: a crash leaves the old or the
  // new one); throws std::invalid_argument naming the entry at fault and changes nothing.
  void replace(const nlohmann::json& document);
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  mutable std::mutex mutex_;
  AcceptanceLimits limits_;
};

}  // namespace imucal::daemon
