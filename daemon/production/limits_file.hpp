// The acceptance limits (imucal-limits/1) the daemon judges runs by, kept by the registry
// (registry.hpp limits_document): the stand's limits file on SQLite, the lab's one document on
// PostgreSQL, so that limits replaced on one stand apply on every stand at its next reading.
// Replaced whole by an operator (PUT /api/limits). Thin I/O around acceptance.hpp's parser.
#pragma once

#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/production/acceptance.hpp"
#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

class LimitsFile {
 public:
  // `source`: the name the limits go by (AcceptanceLimits::source: the file's name, or the lab's
  // registry). Reads them now (none stored: no limits). Throws std::runtime_error naming the
  // source and the entry at fault: a daemon must not judge units by limits it misread. A registry
  // that cannot be reached now (the lab's server away) is no error: no limits until it answers.
  LimitsFile(Registry& registry, std::string source);

  // The registry's current limits, read again at each call (another stand may have replaced
  // them). While it cannot be read (its server away), or holds a document this imucald cannot
  // read, the limits last read, the reason in the log.
  AcceptanceLimits current() const;
  // The limits as JSON (the empty imucal-limits/1 document when there are none).
  nlohmann::json document() const;
  // Validates and stores a new document put by `actor`; throws std::invalid_argument naming the
  // entry at fault and changes nothing (a failure of the store: its StorageError).
  void replace(const nlohmann::json& document, const std::string& actor);
  const std::string& source() const { return source_; }

 private:
  // Reads the registry's document into text_ and limits_ (under mutex_); `at_start`: a misread
  // document throws instead of keeping the last limits.
  void refresh(bool at_start) const;

  Registry& registry_;
  std::string source_;
  mutable std::mutex mutex_;
  mutable std::optional<std::string> text_;  // the document last read (none: none stored)
  mutable AcceptanceLimits limits_;
  mutable bool unreadable_ = false;  // the registry could not be read when last asked
  mutable std::optional<std::string> misread_;  // the last document refused (said once in the log)
};

}  // namespace imucal::daemon
