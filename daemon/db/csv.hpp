// One field of RFC 4180 CSV, for every CSV imucald writes (a unit's history, a run's events).
#pragma once

#include <string>
#include <string_view>

#include "core/number_text.hpp"

namespace imucal::daemon {

// Quoted when it holds a comma, a quote, CR or LF (quotes doubled). Text that a spreadsheet would
// run as a formula (starting with = + - @, and not a number) gets a leading apostrophe: an
// operator's reason or a device's message must not become a formula in a lab's spreadsheet.
inline std::string csv_field(std::string_view text) {
  std::string field(text);
  if (!field.empty() && std::string_view("=+-@").find(field.front()) != std::string_view::npos &&
      !parse_number_text(field))
    field.insert(0, "'");
  if (field.find_first_of(",\"\r\n") == std::string::npos) return field;
  std::string out = "\"";
  for (const char c : field) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

}  // namespace imucal::daemon
