// Strict reading of JSON objects written by people (the daemon configuration, campaigns, API
// bodies, device descriptions): every problem names its location, an unknown key is a problem (a
// typo must not become a silent default), and keys starting with '_' are comments (JSON has none)
// and ignored. Two ways to report: collect every problem (a configuration is answered with all of
// them at once), or throw at the first, for a description whose later checks need the values read
// before (an IMU link's field offsets against its frame length).
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace imucal {

// JSON text that cannot throw: a string that is not valid UTF-8 (a client's bytes echoed in a
// message) is written with U+FFFD in place of the bad bytes. Every reply the daemon sends is
// written by it (nlohmann's dump() throws type_error.316 there instead).
inline std::string json_text(const nlohmann::json& value) {
  return value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

// A stored JSON text as JSON: null when there is none, or when it does not parse (a column
// written by an older daemon is shown as missing, never fails the reply that reads it).
inline nlohmann::json parse_or_null(const std::optional<std::string>& text) {
  if (!text) return nullptr;
  try {
    return nlohmann::json::parse(*text);
  } catch (const nlohmann::json::exception&) {
    return nullptr;
  }
}

class ObjectReader {
 public:
  // Throw std::invalid_argument(prefix + problem) at the first problem.
  struct ThrowAtFirst {
    std::string prefix;  // names the document ("imu link 'kvh-1750': ")
  };

  // `where` names the object in messages ("config", "campaign.chamber"). A non-object is reported
  // at once and every getter then returns nothing.
  ObjectReader(const nlohmann::json& object, std::string where, std::vector<std::string>& problems);
  // Throwing: a required getter then never returns nothing, and the caller calls finish() itself.
  ObjectReader(const nlohmann::json& object, std::string where, ThrowAtFirst mode);
  ObjectReader(const ObjectReader&) = delete;
  ObjectReader& operator=(const ObjectReader&) = delete;
  // Collecting: reports the unknown keys (once). Throwing: nothing (a destructor must not throw).
  ~ObjectReader();

  bool is_object() const { return object_ != nullptr; }
  bool has(const char* key) const;
  // The value, marking the key as known; nullptr when absent (and a problem when `required`).
  const nlohmann::json* get(const char* key, bool required = false);

  std::optional<double> number(const char* key, bool required = false);
  // A finite number >= min (and <= max when given); outside: a problem naming the range.
  std::optional<double> number_in(const char* key, double min, std::optional<double> max = std::nullopt,
                                  bool required = false);
  std::optional<std::int64_t> integer(const char* key, std::int64_t min, std::int64_t max, bool required = false);
  std::optional<std::string> string(const char* key, bool required = false);
  std::optional<bool> boolean(const char* key, bool required = false);

  // Throwing readers: the value of a required key, never nothing (absent, of the wrong type or
  // out of range: the problem is thrown). On a collecting reader a missing value is a logic_error,
  // so that `*reader.number(key, true)`, which would read an empty optional there, is never needed.
  const nlohmann::json& required(const char* key);
  double required_number(const char* key);
  double required_number_in(const char* key, double min, std::optional<double> max = std::nullopt);
  std::int64_t required_integer(const char* key, std::int64_t min, std::int64_t max);
  std::string required_string(const char* key);

  // Reports keys that no getter asked for (besides '_' comments). Called by the destructor too.
  void finish();
  // For an exchange format other writers may extend (formats.md: a recording's meta.json): an
  // unknown key is ignored unless it is a near miss of a key asked for ("gravity_mps" for
  // "gravity_mps2"), which is reported with the key it resembles: a typo must not silently turn
  // into a default there either.
  void finish_extensible();

  const std::string& where() const { return where_; }
  // Records the problem, or throws it when throwing.
  void problem(const std::string& text);
  // Throws the problem (prefixed); for readers that throw at the first problem only.
  [[noreturn]] void fail(const std::string& text) const;
  // Throws "path: what" (a value's problem found by the caller), as fail(text).
  [[noreturn]] void fail(const std::string& path, const std::string& what) const { fail(path + ": " + what); }
  // The key's path: "where.key", or the key alone in a top-level reader whose `where` is empty.
  std::string at(const char* key) const { return where_.empty() ? std::string(key) : where_ + "." + key; }

 private:
  const nlohmann::json* object_ = nullptr;
  std::string where_;
  std::vector<std::string>* problems_ = nullptr;  // null when throwing
  std::string throw_prefix_;
  std::set<std::string> known_;
  bool finished_ = false;
};

// A device's timeout or back-off: a positive whole number of milliseconds, at most an hour (a
// longer one is a typo, not a setting), under `key`; absent: `out` kept.
void read_milliseconds(ObjectReader& r, const char* key, std::chrono::milliseconds& out);

// "JSON type" in words for messages ("a string", "an array").
std::string json_type_name(const nlohmann::json& value);

}  // namespace imucal
