// A table controller's command language as data (`imucal-table-dialect/1`, docs/drivers.md "Table
// dialects"): one ASCII command per line and exactly one reply line per command, each command and
// each reply a template of literal text and named placeholders ("{axis}", "{angle_deg}"), the
// tokens for axes, modes and the interlock, how numbers and time tags are written, the status flag
// bits, the error codes and what each means, and an optional reply checksum. imucal's ACL-style
// language is one dialect (drivers/table_dialects/imucal-acl.json); another controller family is
// another file. Pure formatting and parsing for both ends (the driver, tcp_table.hpp, and the
// simulated table), fuzzed in the tests.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "drivers/interfaces.hpp"

namespace imucal::drivers::dialect {

inline constexpr const char* kFormat = "imucal-table-dialect/1";
inline constexpr std::size_t kMaxLineBytes = 512;

// Why a controller refuses a command. A dialect gives each its own error code.
enum class Refusal {
  none,
  syntax,            // unknown command, malformed line
  argument,          // bad axis, number, mode
  interlock_open,    // interlock open: no motion
  limit_exceeded,    // demand beyond the axis limits of its mode
  axis_fault,        // latched axis fault (limit hit): interlock reset needed
  watchdog_expired,  // axis dropped to off by the watchdog: set the mode again
  wrong_mode,        // demand does not match the axis mode
};
inline constexpr std::size_t kRefusals = 8;  // with none
const char* refusal_name(Refusal r) noexcept;

enum class Op {
  identify,
  checksum,            // reply checksums on (flag) or off: the dialect's reply_checksum commands
  interlock_close,
  interlock_open,
  interlock_reset,
  mode,                // {axis} {mode}
  demand_position,     // {axis} {angle_deg}
  demand_rate,         // {axis} {rate_dps}
  demand_oscillation,  // {axis} {amplitude_deg} {frequency_hz} {phase_deg}
  limit_position,      // {axis} {mode} {min_deg} {max_deg}
  limit_rate,          // {axis} {mode} {rate_dps}
  limit_accel,         // {axis} {mode} {accel_dps2}
  watchdog,            // {period_s}
  read_positions,
  read_status,
};
inline constexpr std::size_t kOps = 15;

struct Command {
  Op op = Op::identify;
  int axis = 0;  // 0 outer, 1 middle, 2 inner, where the command names one
  TableMode mode = TableMode::off;
  std::array<double, 3> args{};  // the op's numbers in the order of the comment above
  bool flag = false;
};

struct ParseError {
  Refusal refusal = Refusal::syntax;
  std::string text;
};

// Per-axis status flags of a status reply, as the driver reads them.
struct StatusFlags {
  bool at_limit = false, fault = false, watchdog_expired = false, moving = false;
  bool operator==(const StatusFlags&) const = default;
};

struct Reply {
  enum class Kind { ok, error, positions, status, identity } kind = Kind::ok;
  Refusal refusal = Refusal::none;  // error: what the code means (none: a code the dialect does not list)
  std::string code;                 // error: the code as the controller wrote it
  std::string text;                 // error text or identity
  std::int64_t time_us = 0;
  std::array<double, 3> angle_deg{};
  std::array<double, 3> rate_dps{};
  InterlockState interlock = InterlockState::open;
  std::array<TableMode, 3> modes{};
  std::array<StatusFlags, 3> flags{};
};

// Literal text and placeholders, as parsed from a template string.
struct Template {
  struct Part {
    bool placeholder = false;
    std::string text;  // the literal, or the placeholder's name
  };
  std::string text;  // as written in the dialect
  std::vector<Part> parts;
};

enum class TimeUnit { us, ms, s };

struct Dialect {
  std::string name;
  std::string source;  // what the dialect was written from (a manual and its revision)
  std::string line_end = "\n";  // "\n" or "\r\n"; a '\r' before '\n' is always accepted
  bool commands_case_insensitive = true;
  std::array<std::string, 3> axes;   // outer, middle, inner
  std::array<std::string, 4> modes;  // by TableMode
  std::optional<int> decimals;       // numbers in commands and replies; empty: shortest exact
  TimeUnit time_unit = TimeUnit::us;
  std::array<Template, kOps> commands;  // by Op; `checksum` holds the "on" command
  std::optional<Template> checksum_off;
  bool has_reply_checksum = false;       // "*HH": XOR of the bytes before the separator
  char checksum_separator = '*';
  Template reply_ok, reply_error, reply_identity, reply_positions, reply_status;
  std::array<std::string, 2> interlock;  // by InterlockState (open, closed)
  int flag_radix = 16;
  unsigned flag_at_limit = 0, flag_fault = 0, flag_watchdog = 0, flag_moving = 0;
  std::array<std::string, kRefusals> error_codes;  // by Refusal; [none] unused
};

// Parses and checks an `imucal-table-dialect/1` description: every command the driver sends and
// every reply it reads present, each with exactly the placeholders it needs, distinct tokens and
// codes. std::invalid_argument listing every problem with its key path.
Dialect dialect_from_json(const std::string& json_text);
// A built-in dialect by name, or a dialect file.
Dialect load_dialect(const std::string& name_or_path);
std::vector<std::string> builtin_dialect_names();
std::string builtin_dialect_json(const std::string& name);  // throws for an unknown name
// imucal's own ACL-style language, parsed once.
const Dialect& imucal_acl();

// The command line, without the line end.
std::string format_command(const Dialect& d, const Command& c);
// A command line (line end removed or not) as the controller reads it.
std::variant<Command, ParseError> parse_command(const Dialect& d, std::string_view line);

// A reply line without checksum and line end.
std::string format_reply(const Dialect& d, const Reply& r);
// One reply line (line end already removed, a trailing '\r' tolerated): an error reply or a reply
// of the `expected` kind. With `checksum`, the line must end in the dialect's checksum
// (DriverErrc::crc_error otherwise); any other mismatch is DriverErrc::protocol_error.
Result<Reply> parse_reply(const Dialect& d, std::string_view line, Reply::Kind expected, bool checksum);
// The reply kind that answers `op`.
Reply::Kind reply_kind_of(Op op) noexcept;

// Appends the checksum when asked, and the dialect's line end.
std::string frame_line(const Dialect& d, std::string_view body, bool checksum);
std::uint8_t xor_checksum(std::string_view body) noexcept;

}  // namespace imucal::drivers::dialect
