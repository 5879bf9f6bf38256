#include "drivers/acl_protocol.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <vector>

namespace imucal::drivers::acl {

namespace {

std::string upper(std::string_view s) {
  std::string out(s);
  for (char& c : out)
    if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  return out;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= s.size(); ++i) {
    if (i == s.size() || s[i] == sep) {
      out.push_back(trim(s.substr(start, i - start)));
      start = i + 1;
    }
  }
  return out;
}

bool parse_double(std::string_view s, double& out) {
  if (s.empty() || s.size() > 64) return false;
  // from_chars rejects a leading '+', which a human typing commands may use.
  if (s.front() == '+') s.remove_prefix(1);
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size() && std::isfinite(out);
}

bool parse_int(std::string_view s, std::int64_t& out) {
  if (s.empty() || s.size() > 20) return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

bool parse_hex(std::string_view s, unsigned& out) {
  if (s.empty() || s.size() > 4) return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out, 16);
  return ec == std::errc() && ptr == s.data() + s.size();
}

bool parse_mode(std::string_view s, TableMode& m) {
  const std::string u = upper(s);
  if (u == "OFF") m = TableMode::off;
  else if (u == "POS") m = TableMode::position;
  else if (u == "RATE") m = TableMode::rate;
  else if (u == "SYNT") m = TableMode::synthesis;
  else return false;
  return true;
}

std::string num(double v) {
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, ptr) : std::string("nan");
}

struct Spec {
  const char* keyword;
  Op op;
  int n_args;      // after the axis (or total when no axis)
  bool has_axis;
  bool has_mode;   // the first argument after the axis is a mode token
};

constexpr Spec kSpecs[] = {
    {"*IDN?", Op::identify, 0, false, false},
    {":SYST:CHEC", Op::checksum, 1, false, false},
    {":INT:CLOS", Op::interlock_close, 0, false, false},
    {":INT:OPEN", Op::interlock_open, 0, false, false},
    {":INT:RES", Op::interlock_reset, 0, false, false},
    {":MODE", Op::mode, 0, true, true},
    {":DEM:POS", Op::demand_position, 1, true, false},
    {":DEM:RATE", Op::demand_rate, 1, true, false},
    {":DEM:OSC", Op::demand_oscillation, 3, true, false},
    {":LIM:POS", Op::limit_position, 2, true, true},
    {":LIM:RATE", Op::limit_rate, 1, true, true},
    {":LIM:ACC", Op::limit_accel, 1, true, true},
    {":CONF:WDOG", Op::watchdog, 1, false, false},
    {":READ:POS?", Op::read_positions, 0, false, false},
    {":READ:STAT?", Op::read_status, 0, false, false},
};

const Spec& spec_of(Op op) {
  for (const Spec& s : kSpecs)
    if (s.op == op) return s;
  return kSpecs[0];
}

}  // namespace

const char* mode_token(TableMode mode) noexcept {
  switch (mode) {
    case TableMode::off: return "OFF";
    case TableMode::position: return "POS";
    case TableMode::rate: return "RATE";
    case TableMode::synthesis: return "SYNT";
  }
  return "OFF";
}

std::uint8_t xor_checksum(std::string_view body) noexcept {
  std::uint8_t x = 0;
  for (char c : body) x = static_cast<std::uint8_t>(x ^ static_cast<std::uint8_t>(c));
  return x;
}

std::string frame_line(std::string_view body, bool checksum) {
  std::string out(body);
  if (checksum) {
    char buf[8];
    std::snprintf(buf, sizeof buf, "*%02X", static_cast<unsigned>(xor_checksum(body)));
    out += buf;
  }
  out += '\n';
  return out;
}

std::string format_command(const Command& c) {
  const Spec& s = spec_of(c.op);
  std::string out = s.keyword;
  if (c.op == Op::checksum) return out + (c.flag ? " ON" : " OFF");
  std::vector<std::string> fields;
  if (s.has_axis) fields.push_back(std::to_string(c.axis));
  if (s.has_mode) fields.emplace_back(mode_token(c.mode));
  for (int i = 0; i < s.n_args; ++i) fields.push_back(num(c.args[static_cast<std::size_t>(i)]));
  for (std::size_t i = 0; i < fields.size(); ++i) out += (i == 0 ? " " : ",") + fields[i];
  return out;
}

std::variant<Command, ParseError> parse_command(std::string_view line) {
  line = trim(line);
  if (line.size() > kMaxLineBytes) return ParseError{kErrSyntax, "line too long"};
  const std::size_t sp = line.find(' ');
  const std::string keyword = upper(line.substr(0, sp));
  const std::string_view rest = sp == std::string_view::npos ? std::string_view() : trim(line.substr(sp + 1));
  const Spec* spec = nullptr;
  for (const Spec& s : kSpecs)
    if (keyword == s.keyword) spec = &s;
  if (!spec) return ParseError{kErrSyntax, "unknown command"};
  Command c;
  c.op = spec->op;
  if (c.op == Op::checksum) {
    const std::string u = upper(rest);
    if (u == "ON") c.flag = true;
    else if (u == "OFF") c.flag = false;
    else return ParseError{kErrArgument, "expected ON or OFF"};
    return c;
  }
  const std::vector<std::string_view> f = rest.empty() ? std::vector<std::string_view>{} : split(rest, ',');
  const std::size_t expected = static_cast<std::size_t>((spec->has_axis ? 1 : 0) + (spec->has_mode ? 1 : 0) + spec->n_args);
  if (f.size() != expected) return ParseError{kErrArgument, "expected " + std::to_string(expected) + " arguments"};
  std::size_t i = 0;
  if (spec->has_axis) {
    std::int64_t a = 0;
    if (!parse_int(f[i++], a) || a < 1 || a > 3) return ParseError{kErrArgument, "axis must be 1, 2 or 3"};
    c.axis = static_cast<int>(a);
  }
  if (spec->has_mode && !parse_mode(f[i++], c.mode)) return ParseError{kErrArgument, "mode must be OFF, POS, RATE or SYNT"};
  for (int k = 0; k < spec->n_args; ++k)
    if (!parse_double(f[i++], c.args[static_cast<std::size_t>(k)])) return ParseError{kErrArgument, "bad number"};
  return c;
}

std::string format_reply(const Reply& r) {
  switch (r.kind) {
    case Reply::Kind::ok: return "OK";
    case Reply::Kind::error: {
      std::string text = r.text;
      // The text must not break the framing.
      std::replace_if(text.begin(), text.end(), [](char ch) { return ch == '\n' || ch == '\r' || ch == '*'; }, ' ');
      return "ERR " + std::to_string(r.error_code) + "," + text;
    }
    case Reply::Kind::identity: return "IDN " + r.text;
    case Reply::Kind::positions: {
      std::string out = "POS " + std::to_string(r.time_us);
      for (double a : r.angle_deg) out += "," + num(a);
      for (double w : r.rate_dps) out += "," + num(w);
      return out;
    }
    case Reply::Kind::status: {
      std::string out = "STAT " + std::to_string(r.time_us);
      out += r.interlock == InterlockState::closed ? ",CLOSED" : ",OPEN";
      for (TableMode m : r.modes) out += std::string(",") + mode_token(m);
      for (unsigned f : r.flags) {
        char buf[8];
        std::snprintf(buf, sizeof buf, ",%X", f & 0xFFFFu);
        out += buf;
      }
      return out;
    }
  }
  return "ERR 100,internal";
}

Result<Reply> parse_reply(std::string_view line, bool checksum) {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  if (line.size() > kMaxLineBytes) return {DriverErrc::protocol_error, "reply longer than " + std::to_string(kMaxLineBytes) + " bytes"};
  for (char ch : line)
    if (static_cast<unsigned char>(ch) < 0x20 || static_cast<unsigned char>(ch) > 0x7E)
      return {checksum ? DriverErrc::crc_error : DriverErrc::protocol_error, "reply holds a non-printable byte"};
  std::string_view body = line;
  if (checksum) {
    const std::size_t star = line.rfind('*');
    unsigned sum = 0;
    auto upper_hex = [](char ch) { return (ch >= '0' && ch <= '9') || (ch >= 'A' && ch <= 'F'); };
    // Exactly two upper-case hex digits: a case change of a digit is a corruption too.
    if (star == std::string_view::npos || star + 3 != line.size() || !upper_hex(line[star + 1]) ||
        !upper_hex(line[star + 2]) || !parse_hex(line.substr(star + 1), sum))
      return {DriverErrc::crc_error, "reply without a valid checksum: '" + std::string(line) + "'"};
    body = line.substr(0, star);
    if (sum != xor_checksum(body))
      return {DriverErrc::crc_error, "reply checksum mismatch: '" + std::string(line) + "'"};
  }
  auto bad = [&](const char* why) {
    return Result<Reply>(DriverErrc::protocol_error, std::string(why) + ": '" + std::string(line) + "'");
  };
  Reply r;
  if (body == "OK") return r;
  const std::size_t sp = body.find(' ');
  if (sp == std::string_view::npos) return bad("unrecognised reply");
  const std::string_view head = body.substr(0, sp), rest = body.substr(sp + 1);
  if (head == "ERR") {
    const std::size_t comma = rest.find(',');
    std::int64_t code = 0;
    if (comma == std::string_view::npos || !parse_int(rest.substr(0, comma), code) || code < 0 || code > 999)
      return bad("malformed error reply");
    r.kind = Reply::Kind::error;
    r.error_code = static_cast<int>(code);
    r.text = std::string(rest.substr(comma + 1));
    return r;
  }
  if (head == "IDN") {
    r.kind = Reply::Kind::identity;
    r.text = std::string(rest);
    return r;
  }
  const std::vector<std::string_view> f = split(rest, ',');
  if (head == "POS") {
    if (f.size() != 7) return bad("position reply needs 7 fields");
    r.kind = Reply::Kind::positions;
    if (!parse_int(f[0], r.time_us)) return bad("bad time tag");
    for (std::size_t k = 0; k < 3; ++k)
      if (!parse_double(f[1 + k], r.angle_deg[k]) || !parse_double(f[4 + k], r.rate_dps[k])) return bad("bad number");
    return r;
  }
  if (head == "STAT") {
    if (f.size() != 8) return bad("status reply needs 8 fields");
    r.kind = Reply::Kind::status;
    if (!parse_int(f[0], r.time_us)) return bad("bad time tag");
    if (f[1] == "CLOSED") r.interlock = InterlockState::closed;
    else if (f[1] == "OPEN") r.interlock = InterlockState::open;
    else return bad("bad interlock state");
    for (std::size_t k = 0; k < 3; ++k) {
      if (!parse_mode(f[2 + k], r.modes[k])) return bad("bad mode");
      if (!parse_hex(f[5 + k], r.flags[k])) return bad("bad flags");
    }
    return r;
  }
  return bad("unrecognised reply");
}

}  // namespace imucal::drivers::acl
