#include "drivers/table_dialect.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "drivers/embedded_json.hpp"
#include "drivers/table_dialects_builtin.hpp"  // generated from drivers/table_dialects/*.json

namespace imucal::drivers::dialect {

using nlohmann::json;

namespace {

// ------------------------------------------------------------------------------------------------
// What each command and reply carries.

struct OpSpec {
  Op op;
  const char* key;  // in "commands"; checksum's commands are in "reply_checksum"
  bool has_axis;
  bool has_mode;
  std::vector<const char*> numbers;  // Command::args in this order
};

const std::array<OpSpec, kOps>& op_specs() {
  static const std::array<OpSpec, kOps> specs = {{
      {Op::identify, "identify", false, false, {}},
      {Op::checksum, "on", false, false, {}},
      {Op::interlock_close, "interlock_close", false, false, {}},
      {Op::interlock_open, "interlock_open", false, false, {}},
      {Op::interlock_reset, "interlock_reset", false, false, {}},
      {Op::mode, "mode", true, true, {}},
      {Op::demand_position, "demand_position", true, false, {"angle_deg"}},
      {Op::demand_rate, "demand_rate", true, false, {"rate_dps"}},
      {Op::demand_oscillation, "demand_oscillation", true, false, {"amplitude_deg", "frequency_hz", "phase_deg"}},
      {Op::limit_position, "limit_position", true, true, {"min_deg", "max_deg"}},
      {Op::limit_rate, "limit_rate", true, true, {"rate_dps"}},
      {Op::limit_accel, "limit_accel", true, true, {"accel_dps2"}},
      {Op::watchdog, "watchdog", false, false, {"period_s"}},
      {Op::read_positions, "read_positions", false, false, {}},
      {Op::read_status, "read_status", false, false, {}},
  }};
  return specs;
}

const OpSpec& spec_of(Op op) { return op_specs()[static_cast<std::size_t>(op)]; }

std::vector<std::string> placeholders_of(const OpSpec& s) {
  std::vector<std::string> names;
  if (s.has_axis) names.emplace_back("axis");
  if (s.has_mode) names.emplace_back("mode");
  for (const char* n : s.numbers) names.emplace_back(n);
  return names;
}

constexpr std::array<const char*, 3> kAxisKeys = {"outer", "middle", "inner"};
constexpr std::array<const char*, 4> kModeKeys = {"off", "position", "rate", "synthesis"};  // by TableMode
constexpr std::array<const char*, 2> kInterlockKeys = {"open", "closed"};                   // by InterlockState
constexpr std::array<const char*, kRefusals> kRefusalKeys = {
    "none", "syntax", "argument", "interlock_open", "limit_exceeded", "axis_fault", "watchdog_expired", "wrong_mode"};

// Per-axis placeholders of the data replies: "{angle_deg.outer}" and so on.
std::vector<std::string> per_axis(const char* what) {
  std::vector<std::string> names;
  for (const char* a : kAxisKeys) names.push_back(std::string(what) + "." + a);
  return names;
}

// ------------------------------------------------------------------------------------------------
// Text helpers.

bool blank(char c) { return c == ' ' || c == '\t'; }

std::string_view trim(std::string_view s) {
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && (blank(s.back()) || s.back() == '\r' || s.back() == '\n')) s.remove_suffix(1);
  return s;
}

char upper(char c) { return c >= 'a' && c <= 'z' ? static_cast<char>(c - 'a' + 'A') : c; }

bool same(std::string_view a, std::string_view b, bool ci) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (ci ? upper(a[i]) != upper(b[i]) : a[i] != b[i]) return false;
  return true;
}

std::size_t find(std::string_view s, std::string_view what, std::size_t from, bool ci) {
  if (what.size() > s.size()) return std::string_view::npos;
  for (std::size_t i = from; i + what.size() <= s.size(); ++i)
    if (same(s.substr(i, what.size()), what, ci)) return i;
  return std::string_view::npos;
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
  if (s.front() == '+') s.remove_prefix(1);
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

std::string number(const Dialect& d, double v) {
  char buf[400];  // any double in fixed notation
  const auto [ptr, ec] = d.decimals ? std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, *d.decimals)
                                    : std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, ptr) : std::string("nan");
}

std::string time_text(const Dialect& d, std::int64_t time_us) {
  switch (d.time_unit) {
    case TimeUnit::us: return std::to_string(time_us);
    case TimeUnit::ms: return std::to_string(time_us / 1000);
    case TimeUnit::s: {
      char buf[48];
      std::snprintf(buf, sizeof buf, "%lld.%06lld", static_cast<long long>(time_us / 1'000'000),
                    static_cast<long long>(std::llabs(time_us % 1'000'000)));
      return buf;
    }
  }
  return "0";
}

bool parse_time(const Dialect& d, std::string_view s, std::int64_t& time_us) {
  if (d.time_unit == TimeUnit::s) {
    double v = 0;
    if (!parse_double(s, v) || std::fabs(v) > 9e12) return false;
    time_us = std::llround(v * 1e6);
    return true;
  }
  std::int64_t v = 0;
  if (!parse_int(s, v)) return false;
  if (d.time_unit == TimeUnit::ms) {
    if (v > INT64_MAX / 1000 || v < INT64_MIN / 1000) return false;
    v *= 1000;
  }
  time_us = v;
  return true;
}

template <std::size_t N>
int token_index(const std::array<std::string, N>& tokens, std::string_view s) {
  for (std::size_t i = 0; i < N; ++i)
    if (same(tokens[i], s, true)) return static_cast<int>(i);
  return -1;
}

// "1, 2 or 3".
template <std::size_t N>
std::string tokens_text(const std::array<std::string, N>& tokens) {
  std::string s;
  for (std::size_t i = 0; i < N; ++i) s += (i == 0 ? "" : i + 1 == N ? " or " : ", ") + tokens[i];
  return s;
}

// ------------------------------------------------------------------------------------------------
// Templates.

// The captures of `t`'s placeholders in `line`, in the order of the template, or nothing when the
// literal text does not match. A run of blanks in the literal matches any run of blanks (or none)
// in the line; a placeholder takes everything up to the next literal (its first word) or the end,
// trimmed.
std::optional<std::vector<std::string_view>> match(const Template& t, std::string_view line, bool ci) {
  line = trim(line);
  std::vector<std::string_view> captures;
  std::size_t pos = 0;
  for (std::size_t i = 0; i < t.parts.size(); ++i) {
    const Template::Part& p = t.parts[i];
    if (!p.placeholder) {
      for (std::size_t k = 0; k < p.text.size();) {
        if (blank(p.text[k])) {
          while (k < p.text.size() && blank(p.text[k])) ++k;
          while (pos < line.size() && blank(line[pos])) ++pos;
          continue;
        }
        if (pos >= line.size() || (ci ? upper(line[pos]) != upper(p.text[k]) : line[pos] != p.text[k])) return std::nullopt;
        ++pos;
        ++k;
      }
      continue;
    }
    while (pos < line.size() && blank(line[pos])) ++pos;
    std::size_t end = line.size();
    if (i + 1 < t.parts.size()) {
      std::string_view next = t.parts[i + 1].text;
      while (!next.empty() && blank(next.front())) next.remove_prefix(1);
      const std::size_t word_end = std::min(next.size(), static_cast<std::size_t>(
                                                             std::find_if(next.begin(), next.end(), blank) - next.begin()));
      if (word_end == 0) {
        end = pos;
        while (end < line.size() && !blank(line[end])) ++end;
      } else {
        end = find(line, next.substr(0, word_end), pos, ci);
        if (end == std::string_view::npos) return std::nullopt;
      }
    }
    captures.push_back(trim(line.substr(pos, end - pos)));
    pos = end;
  }
  if (pos != line.size()) return std::nullopt;
  return captures;
}

// The value of placeholder `name` among `t`'s captures (nothing when the template has none).
std::optional<std::string_view> capture(const Template& t, const std::vector<std::string_view>& caps,
                                        std::string_view name) {
  std::size_t k = 0;
  for (const Template::Part& p : t.parts) {
    if (!p.placeholder) continue;
    if (p.text == name) return caps[k];
    ++k;
  }
  return std::nullopt;
}

// The text of placeholder `name` in a matched line. The parsers below ask only for placeholders
// the dialect's template must have (parse_dialect refuses a template that lacks one); were one
// missing all the same, its text is empty, which every value parser refuses.
std::string_view placeholder_text(const Template& t, const std::vector<std::string_view>& caps, std::string_view name) {
  return capture(t, caps, name).value_or(std::string_view());
}

template <class Value>
std::string fill(const Template& t, Value value_of) {
  std::string out;
  for (const Template::Part& p : t.parts) out += p.placeholder ? value_of(p.text) : p.text;
  return out;
}

// The command keyword: the template's text before its first blank or placeholder.
std::string_view keyword(const Template& t) {
  if (t.parts.empty() || t.parts.front().placeholder) return {};
  std::string_view s = t.parts.front().text;
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  return s.substr(0, static_cast<std::size_t>(std::find_if(s.begin(), s.end(), blank) - s.begin()));
}

// ------------------------------------------------------------------------------------------------
// Reading a description.

class DialectReader {
 public:
  explicit DialectReader(std::vector<std::string>& problems) : problems_(problems) {}

  // A template at `path` with exactly the placeholders `required` plus any of `optional`.
  Template parse_template(const std::string& text, const std::string& path, const std::vector<std::string>& required,
                          const std::vector<std::string>& optional = {}) {
    Template t;
    t.text = text;
    if (text.empty()) problem(path + " is empty");
    if (text.find_first_of("\r\n") != std::string::npos) problem(path + " holds a line break");
    std::set<std::string> seen;
    std::size_t pos = 0;
    while (pos < text.size()) {
      const std::size_t open = text.find('{', pos);
      const std::size_t close_stray = text.find('}', pos);
      if (close_stray < open) {
        problem(path + ": '}' without '{' (braces only enclose placeholders)");
        return t;
      }
      if (open > pos) t.parts.push_back({false, text.substr(pos, open == std::string::npos ? std::string::npos : open - pos)});
      if (open == std::string::npos) break;
      const std::size_t close = text.find('}', open);
      if (close == std::string::npos) {
        problem(path + ": '{' without '}'");
        return t;
      }
      const std::string name = text.substr(open + 1, close - open - 1);
      const bool known = std::find(required.begin(), required.end(), name) != required.end() ||
                         std::find(optional.begin(), optional.end(), name) != optional.end();
      if (!known) problem(path + ": unknown placeholder {" + name + "}" + expected_text(required, optional));
      if (!seen.insert(name).second) problem(path + ": {" + name + "} twice");
      if (!t.parts.empty() && t.parts.back().placeholder)
        problem(path + ": {" + t.parts.back().text + "} and {" + name + "} need literal text between them");
      t.parts.push_back({true, name});
      pos = close + 1;
    }
    for (const std::string& r : required)
      if (!seen.contains(r)) problem(path + " lacks {" + r + "}");
    return t;
  }

  void problem(const std::string& text) { problems_.push_back(text); }

 private:
  static std::string expected_text(const std::vector<std::string>& required, const std::vector<std::string>& optional) {
    std::string s;
    for (const auto& n : required) s += (s.empty() ? "" : ", ") + ("{" + n + "}");
    for (const auto& n : optional) s += (s.empty() ? "" : ", ") + ("{" + n + "}");
    return s.empty() ? " (this one takes none)" : " (expected " + s + ")";
  }
  std::vector<std::string>& problems_;
};

// A token: non-empty printable ASCII without blanks (it must end where a capture ends).
bool good_token(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c > 0x20 && c < 0x7F; });
}

// Distinct tokens, one per key of `keys`, from the object `parent[key]`.
template <std::size_t N>
void read_tokens(ObjectReader& parent, const char* key, const std::array<const char*, N>& keys,
                 std::array<std::string, N>& out, std::size_t first, std::vector<std::string>& problems) {
  const json* v = parent.get(key, true);
  if (!v) return;
  ObjectReader r(*v, parent.at(key), problems);
  for (std::size_t i = first; i < N; ++i) {
    const auto t = r.string(keys[i], true);
    if (!t) continue;
    if (!good_token(*t)) r.problem(r.at(keys[i]) + " must be printable ASCII without blanks");
    for (std::size_t k = first; k < i; ++k)
      if (same(out[k], *t, true)) r.problem(r.at(keys[i]) + " is the same as " + r.at(keys[k]) + " (\"" + *t + "\")");
    out[i] = *t;
  }
}

// The pieces of parse_dialect, a few keys each (small functions also keep clang-tidy's
// optional-access analysis fast: it runs per function, and its cost grows steeply with the
// branches on optionals in one function).

// `format`, `name`, `source`, `line_end`, `commands_case_insensitive`.
void read_identity(ObjectReader& r, Dialect& d) {
  if (const auto f = r.string("format", true); f && *f != kFormat) r.problem(r.at("format") + " must be \"" + kFormat + "\"");
  d.name = r.string("name", true).value_or("");
  d.source = r.string("source", true).value_or("");
  if (const auto e = r.string("line_end")) {
    if (*e != "\n" && *e != "\r\n") r.problem(r.at("line_end") + " must be \"\\n\" or \"\\r\\n\"");
    d.line_end = *e;
  }
  d.commands_case_insensitive = r.boolean("commands_case_insensitive").value_or(true);
}

// `decimals` and `time_unit`: how numbers and time tags are written.
void read_number_format(ObjectReader& r, Dialect& d) {
  if (const auto n = r.integer("decimals", 0, 12)) d.decimals = static_cast<int>(*n);
  if (const auto u = r.string("time_unit", true)) {
    if (*u == "us") d.time_unit = TimeUnit::us;
    else if (*u == "ms") d.time_unit = TimeUnit::ms;
    else if (*u == "s") d.time_unit = TimeUnit::s;
    else r.problem(r.at("time_unit") + " is \"" + *u + "\", must be \"us\", \"ms\" or \"s\"");
  }
}

// `commands`: a template per operation (the checksum's is under reply_checksum).
void read_commands(const json& c, const std::string& where, DialectReader& dr, Dialect& d, std::vector<std::string>& problems) {
  ObjectReader cr(c, where, problems);
  for (const OpSpec& s : op_specs()) {
    if (s.op == Op::checksum) continue;
    if (const auto text = cr.string(s.key, true))
      d.commands[static_cast<std::size_t>(s.op)] = dr.parse_template(*text, cr.at(s.key), placeholders_of(s));
  }
}

// `replies`: a template per kind of reply.
void read_replies(const json& c, const std::string& where, DialectReader& dr, Dialect& d, std::vector<std::string>& problems) {
  ObjectReader rr(c, where, problems);
  auto reply = [&](const char* key, const std::vector<std::string>& required, const std::vector<std::string>& optional) {
    const auto text = rr.string(key, true);
    return text ? dr.parse_template(*text, rr.at(key), required, optional) : Template{};
  };
  auto joined = [](std::vector<std::string> a, const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  };
  d.reply_ok = reply("ok", {}, {});
  d.reply_error = reply("error", {"code"}, {"text"});
  d.reply_identity = reply("identity", {}, {"text"});
  d.reply_positions = reply("positions", joined(joined({"time"}, per_axis("angle_deg")), per_axis("rate_dps")), {});
  d.reply_status = reply("status", joined(joined({"interlock"}, per_axis("mode")), per_axis("flags")), {"time"});
}

// `status_flags`: the radix of the flags and each flag's bits (no two sharing one).
void read_status_flags(const json& f, const std::string& where, Dialect& d, std::vector<std::string>& problems) {
  ObjectReader fr(f, where, problems);
  if (const auto radix = fr.integer("radix", 2, 16, true)) {
    if (*radix != 2 && *radix != 10 && *radix != 16) fr.problem(fr.at("radix") + " must be 2, 10 or 16");
    d.flag_radix = static_cast<int>(*radix);
  }
  unsigned all = 0;
  for (auto [key, bit] : {std::pair{"at_limit", &d.flag_at_limit}, std::pair{"fault", &d.flag_fault},
                          std::pair{"watchdog_expired", &d.flag_watchdog}, std::pair{"moving", &d.flag_moving}}) {
    const auto v = fr.integer(key, 1, 0xFFFF, true);
    if (!v) continue;
    *bit = static_cast<unsigned>(*v);
    if (all & *bit) fr.problem(fr.at(key) + " shares bits with another flag");
    all |= *bit;
  }
}

// `reply_checksum`: the commands that switch it on and off, its kind and its separator.
void read_reply_checksum(const json& c, const std::string& where, DialectReader& dr, Dialect& d,
                         std::vector<std::string>& problems) {
  ObjectReader cr(c, where, problems);
  d.has_reply_checksum = true;
  if (const auto on = cr.string("on", true)) d.commands[static_cast<std::size_t>(Op::checksum)] = dr.parse_template(*on, cr.at("on"), {});
  if (const auto off = cr.string("off")) d.checksum_off = dr.parse_template(*off, cr.at("off"), {});
  if (const auto k = cr.string("kind", true); k && *k != "xor8-hex")
    cr.problem(cr.at("kind") + " is \"" + *k + "\"; the one kind known is \"xor8-hex\"");
  if (const auto sep = cr.string("separator", true)) {
    if (sep->size() != 1 || !good_token(*sep)) cr.problem(cr.at("separator") + " must be one printable character");
    else d.checksum_separator = sep->front();
  }
}

Dialect parse_dialect(const json& j, std::vector<std::string>& problems) {
  Dialect d;
  DialectReader dr(problems);
  ObjectReader r(j, "dialect", problems);
  if (!r.is_object()) return d;
  read_identity(r, d);
  read_tokens(r, "axes", kAxisKeys, d.axes, 0, problems);
  read_tokens(r, "modes", kModeKeys, d.modes, 0, problems);
  read_tokens(r, "interlock", kInterlockKeys, d.interlock, 0, problems);
  read_tokens(r, "errors", kRefusalKeys, d.error_codes, 1, problems);
  read_number_format(r, d);
  if (const json* c = r.get("commands", true)) read_commands(*c, r.at("commands"), dr, d, problems);
  if (const json* c = r.get("replies", true)) read_replies(*c, r.at("replies"), dr, d, problems);
  if (const json* f = r.get("status_flags", true)) read_status_flags(*f, r.at("status_flags"), d, problems);
  if (const json* c = r.get("reply_checksum")) read_reply_checksum(*c, r.at("reply_checksum"), dr, d, problems);
  return d;
}

}  // namespace

const char* refusal_name(Refusal r) noexcept { return kRefusalKeys[static_cast<std::size_t>(r)]; }

Dialect dialect_from_json(const std::string& json_text) {
  const json j = json::parse(json_text, nullptr, false);
  if (j.is_discarded()) throw std::invalid_argument("table dialect: not valid JSON");
  std::vector<std::string> problems;
  Dialect d = parse_dialect(j, problems);
  if (!problems.empty()) {
    std::string text = "table dialect" + (d.name.empty() ? std::string() : " '" + d.name + "'") + ": ";
    for (std::size_t i = 0; i < problems.size(); ++i) text += (i ? "; " : "") + problems[i];
    throw std::invalid_argument(text);
  }
  return d;
}

Dialect load_dialect(const std::string& name_or_path) {
  return dialect_from_json(embedded_or_file_text(builtin::kTableDialects, name_or_path, "table dialect"));
}

std::vector<std::string> builtin_dialect_names() { return embedded_names(builtin::kTableDialects); }

std::string builtin_dialect_json(const std::string& name) {
  return embedded_text(builtin::kTableDialects, name, "table dialect");
}

const Dialect& imucal_acl() {
  static const Dialect d = load_dialect("imucal-acl");
  return d;
}

Reply::Kind reply_kind_of(Op op) noexcept {
  switch (op) {
    case Op::identify: return Reply::Kind::identity;
    case Op::read_positions: return Reply::Kind::positions;
    case Op::read_status: return Reply::Kind::status;
    default: return Reply::Kind::ok;
  }
}

std::uint8_t xor_checksum(std::string_view body) noexcept {
  std::uint8_t x = 0;
  for (char c : body) x = static_cast<std::uint8_t>(x ^ static_cast<std::uint8_t>(c));
  return x;
}

std::string frame_line(const Dialect& d, std::string_view body, bool checksum) {
  std::string out(body);
  if (checksum && d.has_reply_checksum) {
    char buf[8];
    std::snprintf(buf, sizeof buf, "%c%02X", d.checksum_separator, static_cast<unsigned>(xor_checksum(body)));
    out += buf;
  }
  out += d.line_end;
  return out;
}

std::string format_command(const Dialect& d, const Command& c) {
  const Template& t = c.op == Op::checksum && !c.flag && d.checksum_off ? *d.checksum_off
                                                                        : d.commands[static_cast<std::size_t>(c.op)];
  const OpSpec& s = spec_of(c.op);
  return fill(t, [&](const std::string& name) -> std::string {
    if (name == "axis") return d.axes[static_cast<std::size_t>(std::clamp(c.axis, 0, 2))];
    if (name == "mode") return d.modes[static_cast<std::size_t>(c.mode)];
    for (std::size_t k = 0; k < s.numbers.size(); ++k)
      if (name == s.numbers[k]) return number(d, c.args[k]);
    return {};
  });
}

std::variant<Command, ParseError> parse_command(const Dialect& d, std::string_view line) {
  line = trim(line);
  if (line.size() > kMaxLineBytes) return ParseError{Refusal::syntax, "line too long"};
  const bool ci = d.commands_case_insensitive;
  std::optional<ParseError> bad_argument;
  auto try_template = [&](const Template& t, Op op, bool flag) -> std::optional<Command> {
    if (t.parts.empty()) return std::nullopt;  // a command the dialect does not have
    const auto caps = match(t, line, ci);
    if (!caps) return std::nullopt;
    const OpSpec& s = spec_of(op);
    Command c;
    c.op = op;
    c.flag = flag;
    auto fail = [&](std::string why) {
      if (!bad_argument) bad_argument = ParseError{Refusal::argument, std::move(why)};
      return std::nullopt;
    };
    if (s.has_axis) {
      const int a = token_index(d.axes, placeholder_text(t, *caps, "axis"));
      if (a < 0) return fail("axis must be " + tokens_text(d.axes));
      c.axis = a;
    }
    if (s.has_mode) {
      const int m = token_index(d.modes, placeholder_text(t, *caps, "mode"));
      if (m < 0) return fail("mode must be " + tokens_text(d.modes));
      c.mode = static_cast<TableMode>(m);
    }
    for (std::size_t k = 0; k < s.numbers.size(); ++k)
      if (!parse_double(placeholder_text(t, *caps, s.numbers[k]), c.args[k]))
        return fail(std::string("bad number for ") + s.numbers[k]);
    return c;
  };
  for (const OpSpec& s : op_specs())
    if (auto c = try_template(d.commands[static_cast<std::size_t>(s.op)], s.op, true)) return *c;
  if (d.checksum_off)
    if (auto c = try_template(*d.checksum_off, Op::checksum, false)) return *c;
  if (bad_argument) return *bad_argument;
  // A known keyword with the wrong arguments is an argument error; anything else is unknown.
  const std::string_view word = line.substr(0, static_cast<std::size_t>(std::find_if(line.begin(), line.end(), blank) - line.begin()));
  for (const OpSpec& s : op_specs()) {
    const Template& t = d.commands[static_cast<std::size_t>(s.op)];
    const std::string_view k = keyword(t);
    if (!k.empty() && same(k, word, ci)) return ParseError{Refusal::argument, "expected '" + t.text + "'"};
  }
  return ParseError{Refusal::syntax, "unknown command"};
}

std::string format_reply(const Dialect& d, const Reply& r) {
  const auto axis_index = [](std::string_view name) -> std::size_t {
    const std::string_view axis = name.substr(name.find('.') + 1);
    for (std::size_t k = 0; k < 3; ++k)
      if (axis == kAxisKeys[k]) return k;
    return 0;
  };
  const auto flags_text = [&](const StatusFlags& f) {
    const unsigned v = (f.at_limit ? d.flag_at_limit : 0u) | (f.fault ? d.flag_fault : 0u) |
                       (f.watchdog_expired ? d.flag_watchdog : 0u) | (f.moving ? d.flag_moving : 0u);
    char buf[24];
    auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v, d.flag_radix);
    std::string out(buf, ptr);
    for (char& c : out) c = upper(c);
    return out;
  };
  switch (r.kind) {
    case Reply::Kind::ok: return d.reply_ok.text;
    case Reply::Kind::error: {
      std::string text = r.text;
      // The text must not break the framing.
      std::replace_if(text.begin(), text.end(), [&](char ch) {
        return ch == '\n' || ch == '\r' || (d.has_reply_checksum && ch == d.checksum_separator);
      }, ' ');
      const std::string code = r.refusal == Refusal::none ? r.code : d.error_codes[static_cast<std::size_t>(r.refusal)];
      return fill(d.reply_error, [&](const std::string& name) { return name == "code" ? code : text; });
    }
    case Reply::Kind::identity: return fill(d.reply_identity, [&](const std::string&) { return r.text; });
    case Reply::Kind::positions:
      return fill(d.reply_positions, [&](const std::string& name) -> std::string {
        if (name == "time") return time_text(d, r.time_us);
        const std::size_t k = axis_index(name);
        return number(d, name.starts_with("angle_deg") ? r.angle_deg[k] : r.rate_dps[k]);
      });
    case Reply::Kind::status:
      return fill(d.reply_status, [&](const std::string& name) -> std::string {
        if (name == "time") return time_text(d, r.time_us);
        if (name == "interlock") return d.interlock[static_cast<std::size_t>(r.interlock)];
        const std::size_t k = axis_index(name);
        if (name.starts_with("mode")) return d.modes[static_cast<std::size_t>(r.modes[k])];
        return flags_text(r.flags[k]);
      });
  }
  return d.reply_error.text;
}

namespace {

// The replies of parse_reply, one function each: the values into `r`, or why the body is not that
// reply ("" when it is). Apart from parse_reply, whose switch over them with every capture made
// clang-tidy's optional-access analysis of it take minutes.

// The error reply of any command (true when `body` is one).
bool read_error_reply(const Dialect& d, std::string_view body, Reply& r) {
  const auto caps = match(d.reply_error, body, false);
  if (!caps) return false;
  r.kind = Reply::Kind::error;
  r.code = std::string(placeholder_text(d.reply_error, *caps, "code"));
  r.text = std::string(capture(d.reply_error, *caps, "text").value_or(""));
  for (std::size_t k = 1; k < kRefusals; ++k)
    if (same(d.error_codes[k], r.code, true)) r.refusal = static_cast<Refusal>(k);
  return true;
}

std::string read_identity_reply(const Dialect& d, std::string_view body, Reply& r) {
  const auto caps = match(d.reply_identity, body, false);
  if (!caps) return "unrecognised reply (expected '" + d.reply_identity.text + "')";
  r.text = std::string(capture(d.reply_identity, *caps, "text").value_or(""));
  return {};
}

std::string read_positions_reply(const Dialect& d, std::string_view body, Reply& r) {
  const Template& t = d.reply_positions;
  const auto caps = match(t, body, false);
  if (!caps) return "unrecognised reply (expected '" + t.text + "')";
  if (!parse_time(d, placeholder_text(t, *caps, "time"), r.time_us)) return "bad time tag";
  for (std::size_t k = 0; k < 3; ++k)
    if (!parse_double(placeholder_text(t, *caps, "angle_deg." + std::string(kAxisKeys[k])), r.angle_deg[k]) ||
        !parse_double(placeholder_text(t, *caps, "rate_dps." + std::string(kAxisKeys[k])), r.rate_dps[k]))
      return "bad number";
  return {};
}

std::string read_status_reply(const Dialect& d, std::string_view body, Reply& r) {
  const Template& t = d.reply_status;
  const auto caps = match(t, body, false);
  if (!caps) return "unrecognised reply (expected '" + t.text + "')";
  if (const auto time = capture(t, *caps, "time"); time && !parse_time(d, *time, r.time_us)) return "bad time tag";
  const int lock = token_index(d.interlock, placeholder_text(t, *caps, "interlock"));
  if (lock < 0) return "bad interlock state";
  r.interlock = static_cast<InterlockState>(lock);
  for (std::size_t k = 0; k < 3; ++k) {
    const int m = token_index(d.modes, placeholder_text(t, *caps, "mode." + std::string(kAxisKeys[k])));
    if (m < 0) return "bad mode";
    r.modes[k] = static_cast<TableMode>(m);
    const std::string_view f = placeholder_text(t, *caps, "flags." + std::string(kAxisKeys[k]));
    unsigned v = 0;
    if (f.empty() || f.size() > 16 || std::from_chars(f.data(), f.data() + f.size(), v, d.flag_radix).ptr != f.data() + f.size())
      return "bad flags";
    r.flags[k] = {(v & d.flag_at_limit) != 0, (v & d.flag_fault) != 0, (v & d.flag_watchdog) != 0, (v & d.flag_moving) != 0};
  }
  return {};
}

}  // namespace

Result<Reply> parse_reply(const Dialect& d, std::string_view line, Reply::Kind expected, bool checksum) {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  if (line.size() > kMaxLineBytes) return {DriverErrc::protocol_error, "reply longer than " + std::to_string(kMaxLineBytes) + " bytes"};
  for (char ch : line)
    if (static_cast<unsigned char>(ch) < 0x20 || static_cast<unsigned char>(ch) > 0x7E)
      return {checksum ? DriverErrc::crc_error : DriverErrc::protocol_error, "reply holds a non-printable byte"};
  std::string_view body = line;
  if (checksum && d.has_reply_checksum) {
    const std::size_t sep = line.rfind(d.checksum_separator);
    auto upper_hex = [](char ch) { return (ch >= '0' && ch <= '9') || (ch >= 'A' && ch <= 'F'); };
    // Exactly two upper-case hex digits: a case change of a digit is a corruption too.
    unsigned sum = 0;
    if (sep == std::string_view::npos || sep + 3 != line.size() || !upper_hex(line[sep + 1]) || !upper_hex(line[sep + 2]) ||
        std::from_chars(line.data() + sep + 1, line.data() + sep + 3, sum, 16).ec != std::errc())
      return {DriverErrc::crc_error, "reply without a valid checksum: '" + std::string(line) + "'"};
    body = line.substr(0, sep);
    if (sum != xor_checksum(body)) return {DriverErrc::crc_error, "reply checksum mismatch: '" + std::string(line) + "'"};
  }
  auto bad = [&](const std::string& why) {
    return Result<Reply>(DriverErrc::protocol_error, why + ": '" + std::string(line) + "'");
  };
  Reply r;
  if (read_error_reply(d, body, r)) return r;
  r.kind = expected;
  std::string why;
  switch (expected) {
    case Reply::Kind::ok:
      if (!match(d.reply_ok, body, false)) return bad("unrecognised reply (expected '" + d.reply_ok.text + "')");
      return r;
    case Reply::Kind::error: return bad("unrecognised reply");
    case Reply::Kind::identity: why = read_identity_reply(d, body, r); break;
    case Reply::Kind::positions: why = read_positions_reply(d, body, r); break;
    case Reply::Kind::status: why = read_status_reply(d, body, r); break;
    default: return bad("unrecognised reply");
  }
  if (!why.empty()) return bad(why);
  return r;
}

}  // namespace imucal::drivers::dialect
