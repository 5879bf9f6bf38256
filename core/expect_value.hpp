// The value of an optional that must hold one by the program's own logic (a row just written, the
// result of a stage that reported done, a state set with every success), not by anything a client
// or a file sends: those are checked where they are read, with a message naming the key.
// `*opt` on an empty optional is undefined behaviour and `opt.value()` throws a bare
// bad_optional_access; expect_value throws a std::logic_error saying what was missing, which the
// daemon answers as an internal error (500) naming it. The static check
// (bugprone-unchecked-optional-access) sees the test here, so the callers need none of their own.
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

namespace imucal {

// `what` completes "internal error: ... is missing" ("the state of a command that succeeded").
template <class T>
const T& expect_value(const std::optional<T>& value, const char* what) {
  if (!value) throw std::logic_error(std::string("internal error: ") + what + " is missing");
  return *value;
}

template <class T>
T& expect_value(std::optional<T>& value, const char* what) {
  if (!value) throw std::logic_error(std::string("internal error: ") + what + " is missing");
  return *value;
}

// A temporary optional: its value moved out (a reference would outlive the temporary).
template <class T>
T expect_value(std::optional<T>&& value, const char* what) {
  if (!value) throw std::logic_error(std::string("internal error: ") + what + " is missing");
  return std::move(*value);
}

}  // namespace imucal
