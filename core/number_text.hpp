// Numbers in messages for people: no trailing zeros, no six decimals of noise. "46.6" rather than
// "46.600000", "5000" rather than "5000.0", "4x" rather than "4.000000x". One rule for every
// message the daemon, the stages and the command line write.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>

namespace imucal {

// `v` with at most `significant` significant digits, in the shortest form (%g): 46.6, 5000,
// 0.25, 1e-07. Six digits keep program times to 0.1 ms up to 10^4 s.
inline std::string number_text(double v, int significant = 6) {
  char text[40];
  std::snprintf(text, sizeof text, "%.*g", significant, v);
  return text;
}

// The whole of `text` read as a number ("-1.5e-3", "+3", "46.6"), or nothing ("soon", "3 s", "",
// "-x"): what a query value, a command-line word or a CSV field is, told the same way everywhere.
inline std::optional<double> parse_number_text(const std::string& text) {
  if (text.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0') return std::nullopt;
  return v;
}

// A temperature for people: "31.43 °C" (four significant digits: a chamber's 0.01 C resolution).
inline std::string celsius_text(double c) { return number_text(c, 4) + " °C"; }

}  // namespace imucal
