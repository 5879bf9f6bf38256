// The table's ASCII command language, in the style of the Acutrol ACL (docs/drivers.md, "Table
// over TCP"): one command per line, exactly one reply line per command, SCPI-like keywords,
// axes numbered 1 (outer) .. 3 (inner). Replies may carry an NMEA-style checksum "*HH" (XOR of
// the bytes before '*') once the host asked for it with ":SYST:CHEC ON". Pure formatting and
// parsing for both ends (the driver and the simulated table), fuzzed in the tests.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <variant>

#include "drivers/interfaces.hpp"

namespace imucal::drivers::acl {

inline constexpr std::size_t kMaxLineBytes = 512;

// Error codes of "ERR <code>,<text>" replies.
enum ErrorCode : int {
  kErrSyntax = 100,        // unknown command, malformed line
  kErrArgument = 101,      // bad axis, number, mode
  kErrInterlock = 200,     // interlock open: no motion
  kErrLimit = 201,         // demand beyond the axis limits of its mode
  kErrAxisFault = 202,     // latched axis fault (limit hit): interlock reset needed
  kErrWatchdog = 203,      // axis dropped to off by the watchdog: set the mode again
  kErrMode = 204,          // demand does not match the axis mode
};

// Per-axis status flags of a STAT reply (hex).
namespace flag {
inline constexpr unsigned kAtLimit = 0x1;
inline constexpr unsigned kFault = 0x2;
inline constexpr unsigned kWatchdog = 0x4;
inline constexpr unsigned kMoving = 0x8;
}  // namespace flag

enum class Op {
  identify,            // *IDN?
  checksum,            // :SYST:CHEC ON|OFF         flag
  interlock_close,     // :INT:CLOS
  interlock_open,      // :INT:OPEN
  interlock_reset,     // :INT:RES
  mode,                // :MODE a,OFF|POS|RATE|SYNT
  demand_position,     // :DEM:POS a,deg
  demand_rate,         // :DEM:RATE a,dps
  demand_oscillation,  // :DEM:OSC a,amp_deg,freq_hz,phase_deg
  limit_position,      // :LIM:POS a,mode,min_deg,max_deg
  limit_rate,          // :LIM:RATE a,mode,dps
  limit_accel,         // :LIM:ACC a,mode,dps2
  watchdog,            // :CONF:WDOG seconds
  read_positions,      // :READ:POS?
  read_status,         // :READ:STAT?
};

struct Command {
  Op op = Op::identify;
  int axis = 0;  // 1..3 where the command names one
  TableMode mode = TableMode::off;
  std::array<double, 3> args{};
  bool flag = false;
};

struct ParseError {
  int code = kErrSyntax;
  std::string text;
};

std::string format_command(const Command& c);  // without the line terminator
std::variant<Command, ParseError> parse_command(std::string_view line);

struct Reply {
  enum class Kind { ok, error, positions, status, identity } kind = Kind::ok;
  int error_code = 0;
  std::string text;  // error text or identity
  std::int64_t time_us = 0;
  std::array<double, 3> angle_deg{};
  std::array<double, 3> rate_dps{};
  InterlockState interlock = InterlockState::open;
  std::array<TableMode, 3> modes{};
  std::array<unsigned, 3> flags{};
};

std::string format_reply(const Reply& r);  // without checksum and terminator
// One reply line (terminator already removed, a trailing '\r' tolerated). With `checksum`, the
// line must end in "*HH" matching its body (DriverErrc::crc_error otherwise).
Result<Reply> parse_reply(std::string_view line, bool checksum);

// Appends "*HH" when asked, and the '\n' terminator.
std::string frame_line(std::string_view body, bool checksum);
std::uint8_t xor_checksum(std::string_view body) noexcept;

const char* mode_token(TableMode mode) noexcept;

}  // namespace imucal::drivers::acl
