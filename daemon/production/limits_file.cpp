#include "daemon/production/limits_file.hpp"

#include <stdexcept>

#include <spdlog/spdlog.h>

#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

using nlohmann::json;

LimitsFile::LimitsFile(Registry& registry, std::string source) : registry_(registry), source_(std::move(source)) {
  limits_.source = source_;
  std::lock_guard lock(mutex_);
  refresh(true);
}

void LimitsFile::refresh(bool at_start) const {
  std::optional<std::string> text;
  try {
    text = registry_.limits_document();
  } catch (const std::exception& e) {
    if (!is_database_failure(e)) throw;
    // The lab's server away: the limits last read still judge (none yet at a start without it).
    // Said once per absence: every verdict asks.
    if (!unreadable_)
      spdlog::warn("acceptance limits: {} cannot be read now, the limits last read apply: {}", source_, e.what());
    unreadable_ = true;
    return;
  }
  unreadable_ = false;
  if (text == text_) return;  // unchanged: parsed already
  std::map<std::string, PartLimits> parts;
  try {
    if (text) {
      const json j = json::parse(*text, nullptr, false);
      if (j.is_discarded()) throw std::invalid_argument("not valid JSON");
      parts = limits_from_json(j);
    }
  } catch (const std::exception& e) {
    const std::string why = "acceptance limits " + source_ + ": " + e.what();
    if (at_start) throw std::runtime_error(why);
    if (text != misread_) spdlog::error("{}; the limits last read apply", why);  // once per document
    misread_ = std::move(text);
    return;
  }
  text_ = std::move(text);
  limits_.parts = std::move(parts);
}

AcceptanceLimits LimitsFile::current() const {
  std::lock_guard lock(mutex_);
  refresh(false);
  return limits_;
}

json LimitsFile::document() const { return limits_to_json(current().parts); }

void LimitsFile::replace(const json& document, const std::string& actor) {
  auto parts = limits_from_json(document);  // throws before anything changes
  std::string text = limits_to_json(parts).dump(2) + "\n";
  std::lock_guard lock(mutex_);
  registry_.put_limits_document(text, actor);
  // Read back as put (a journaled put is not readable from the lab's server until replayed).
  text_ = std::move(text);
  limits_.parts = std::move(parts);
}

}  // namespace imucal::daemon
