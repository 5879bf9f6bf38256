// imucal-recording/1 import and export. The CSV side is hand-written around std::from_chars and
// std::to_chars (shortest round-trip form) because real files hold millions of lines and every
// double must survive the trip through text bit for bit.
#include "storage/bundle.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string_view>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"
#include "core/model_json.hpp"
#include "core/table_json.hpp"
#include "storage/sqlite.hpp"

namespace imucal::storage {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr std::array<const char*, 17> kRequiredColumns = {
    "t_s",       "dth_x_rad", "dth_y_rad",  "dth_z_rad", "dv_x_mps",  "dv_y_mps",
    "dv_z_mps",  "outer_deg", "middle_deg", "inner_deg", "temp_gx_C", "temp_gy_C",
    "temp_gz_C", "temp_ax_C", "temp_ay_C",  "temp_az_C", "temp_chamber_C"};
constexpr const char* kSetpointColumn = "chamber_setpoint_C";
constexpr const char* kCoilNames[3] = {"gx", "gy", "gz"};

// formats.md's optional columns of the individual coil sensors: temp_gx_1_C .. temp_gz_8_C.
std::string coil_column(std::size_t coil, std::size_t sensor) {
  return std::string("temp_") + kCoilNames[coil] + "_" + std::to_string(sensor + 1) + "_C";
}
constexpr std::int64_t kNsPerS = 1'000'000'000;

// Frames handed to RunDb::append at once: one transaction per 16 chunks.
constexpr std::size_t kImportBatchFrames = 16 * RunDb::kFramesPerChunk;

[[noreturn]] void fail_bundle(const std::string& dir, const std::string& reason) {
  throw StorageError("bundle '" + dir + "': " + reason);
}

struct FileCloser {
  void operator()(std::FILE* file) const noexcept { std::fclose(file); }
};
using FileHandle = std::unique_ptr<std::FILE, FileCloser>;

std::string read_text_file(const fs::path& path, const std::string& dir) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail_bundle(dir, "cannot read " + path.filename().string());
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Writes `text` to `path` via a temporary name, so that a reader never sees half a file.
void write_text_file(const fs::path& path, const std::string& text, const std::string& dir) {
  const fs::path partial = fs::path(path.string() + ".partial");
  {
    FileHandle file(std::fopen(partial.c_str(), "wb"));
    if (!file) fail_bundle(dir, "cannot write " + partial.filename().string() + ": " + std::strerror(errno));
    if (std::fwrite(text.data(), 1, text.size(), file.get()) != text.size()) {
      fail_bundle(dir, "cannot write " + partial.filename().string() + ": " + std::strerror(errno));
    }
    if (std::fclose(file.release()) != 0) {
      fail_bundle(dir, "cannot write " + partial.filename().string() + ": " + std::strerror(errno));
    }
  }
  std::error_code ec;
  fs::rename(partial, path, ec);
  if (ec) fail_bundle(dir, "cannot rename " + partial.filename().string() + ": " + ec.message());
}

// ---------------------------------------------------------------------------------------------
// Number formatting and parsing

// Shortest text that reads back to the same double (std::to_chars' guarantee).
char* put_double(char* out, char* end, double value) {
  return std::to_chars(out, end, value).ptr;
}

// Exact decimal seconds: "-12.05" for -12050000000 ns. Any reader that does llround(t_s * 1e9)
// on it gets t_ns back (for |t| below ~20 days, the double resolution limit).
char* put_time_s(char* out, std::int64_t t_ns) {
  std::uint64_t magnitude = static_cast<std::uint64_t>(t_ns);
  if (t_ns < 0) {
    *out++ = '-';
    magnitude = ~magnitude + 1;  // two's complement negation without overflow at INT64_MIN
  }
  constexpr auto kNsPerSUnsigned = static_cast<std::uint64_t>(kNsPerS);
  out = std::to_chars(out, out + 24, magnitude / kNsPerSUnsigned).ptr;
  *out++ = '.';
  auto fraction = static_cast<std::uint32_t>(magnitude % kNsPerSUnsigned);
  char digits[9];
  for (int i = 8; i >= 0; --i) {
    digits[i] = static_cast<char>('0' + fraction % 10);
    fraction /= 10;
  }
  int kept = 9;
  while (kept > 1 && digits[kept - 1] == '0') --kept;
  std::memcpy(out, digits, static_cast<std::size_t>(kept));
  return out + kept;
}

std::string_view trim(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t' || text.back() == '\r')) {
    text.remove_suffix(1);
  }
  return text;
}

// Why a field is not a usable number, or nullopt when it is.
std::optional<std::string> parse_double(std::string_view text, double& value) {
  text = trim(text);
  if (text.empty()) return std::string("empty field");
  std::string_view digits = text;
  if (digits.size() > 1 && digits.front() == '+') digits.remove_prefix(1);  // from_chars rejects '+'
  const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (ec == std::errc::result_out_of_range) return "'" + std::string(text) + "' is out of range";
  if (ec != std::errc() || ptr != digits.data() + digits.size()) {
    return "'" + std::string(text) + "' is not a number";
  }
  if (!std::isfinite(value)) return "'" + std::string(text) + "' is not a finite number";
  return std::nullopt;
}

// t_s to integer nanoseconds. A plain decimal is converted exactly (rounded at the 10th decimal),
// so that "1139.95" is 1139950000000 ns whatever the magnitude; other forms (exponents) go
// through a double.
std::optional<std::string> parse_time_ns(std::string_view text, std::int64_t& t_ns) {
  text = trim(text);
  std::string_view rest = text;
  bool negative = false;
  if (!rest.empty() && (rest.front() == '-' || rest.front() == '+')) {
    negative = rest.front() == '-';
    rest.remove_prefix(1);
  }
  std::uint64_t seconds = 0;
  std::uint64_t nanos = 0;
  int integer_digits = 0;
  int fraction_digits = 0;
  bool round_up = false;
  bool plain = true;
  std::size_t i = 0;
  for (; i < rest.size() && rest[i] >= '0' && rest[i] <= '9'; ++i, ++integer_digits) {
    seconds = seconds * 10 + static_cast<std::uint64_t>(rest[i] - '0');
    if (seconds > 9'000'000'000ULL) return "'" + std::string(text) + "' is out of range";
  }
  if (i < rest.size() && rest[i] == '.') {
    for (++i; i < rest.size() && rest[i] >= '0' && rest[i] <= '9'; ++i, ++fraction_digits) {
      if (fraction_digits < 9) {
        nanos = nanos * 10 + static_cast<std::uint64_t>(rest[i] - '0');
      } else if (fraction_digits == 9) {
        round_up = rest[i] >= '5';
      }
    }
  }
  if (i != rest.size() || integer_digits + fraction_digits == 0) plain = false;
  if (plain) {
    for (int d = fraction_digits; d < 9; ++d) nanos *= 10;
    const auto magnitude =
        static_cast<std::int64_t>(seconds * static_cast<std::uint64_t>(kNsPerS) + nanos + (round_up ? 1U : 0U));
    t_ns = negative ? -magnitude : magnitude;
    return std::nullopt;
  }
  double t_s = 0.0;
  if (auto error = parse_double(text, t_s)) return error;
  if (std::fabs(t_s) > 9.0e9) return "'" + std::string(text) + "' is out of range";
  t_ns = std::llround(t_s * 1e9);
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------
// Millimetres in the file, metres in the run. m = mm / 1000 on import; the export looks for the
// millimetre value that gives the metre value back exactly. A value that came from millimetres
// always has one; for the rare one that does not, the export adds the exact metres as well.
std::optional<double> exact_mm(double r_m) {
  const double guess_mm = r_m * 1000.0;
  double up = guess_mm;
  double down = guess_mm;
  for (int step = 0; step < 4; ++step) {
    if (std::bit_cast<std::uint64_t>(up / 1000.0) == std::bit_cast<std::uint64_t>(r_m)) return up;
    if (std::bit_cast<std::uint64_t>(down / 1000.0) == std::bit_cast<std::uint64_t>(r_m)) return down;
    up = std::nextafter(up, HUGE_VAL);
    down = std::nextafter(down, -HUGE_VAL);
  }
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------
// meta.json

// ordered_json keeps the keys in the order of formats.md, for the person reading the file.
nlohmann::ordered_json meta_to_bundle_json(const RecordingMeta& meta) {
  using ojson = nlohmann::ordered_json;
  ojson site = {{"latitude_deg", meta.site.latitude_deg},
               {"longitude_deg", meta.site.longitude_deg},
               {"height_m", meta.site.height_m}};
  if (meta.site.gravity_mps2) site["gravity_mps2"] = *meta.site.gravity_mps2;
  site["middle_axis_azimuth_deg"] = meta.site.middle_axis_azimuth_deg;

  ojson imu = {{"serial", meta.imu_serial}, {"rate_hz", meta.rate_hz}};
  if (meta.gyro_lsb_rad) imu["gyro_lsb_rad"] = *meta.gyro_lsb_rad;
  if (meta.accel_lsb_mps) imu["accel_lsb_mps"] = *meta.accel_lsb_mps;

  ojson c_o_p = ojson::array();
  for (int row = 0; row < 3; ++row) {
    c_o_p.push_back({meta.mount.C_o_p(row, 0), meta.mount.C_o_p(row, 1), meta.mount.C_o_p(row, 2)});
  }
  ojson r0_p_mm = ojson::array();
  bool mm_exact = true;
  for (int axis = 0; axis < 3; ++axis) {
    const auto mm = exact_mm(meta.mount.r0_p_m(axis));
    mm_exact = mm_exact && mm.has_value();
    r0_p_mm.push_back(mm.value_or(meta.mount.r0_p_m(axis) * 1000.0));
  }
  ojson mount = {{"C_o_p", c_o_p}, {"r0_p_mm", r0_p_mm}};
  if (!mm_exact) {
    mount["r0_p_m"] = {meta.mount.r0_p_m.x(), meta.mount.r0_p_m.y(), meta.mount.r0_p_m.z()};
  }

  ojson root = {{"format", kRecordingFormat}, {"site", site}, {"imu", imu}, {"mount", mount}};
  if (!meta.segments.empty()) {
    ojson segments = ojson::array();
    for (const auto& segment : meta.segments) {
      segments.push_back(
          {{"name", segment.name}, {"kind", segment.kind}, {"t0_s", segment.t0_s}, {"t1_s", segment.t1_s}});
    }
    root["segments"] = segments;
  }
  if (meta.table) root["table"] = table::table_certificate_to_json(*meta.table);
  return root;
}

// meta.json as the export writes it: the run's meta, and its faulted intervals when it has any.
nlohmann::ordered_json bundle_meta_json(const RunDb& run, const RecordingMeta& meta) {
  nlohmann::ordered_json root = meta_to_bundle_json(meta);
  if (const auto text = run.extra(kFaultedIntervalsKey)) {
    try {
      root[kFaultedIntervalsKey] = nlohmann::ordered_json::parse(*text);
    } catch (const json::exception& e) {
      throw StorageError("run database '" + run.path() + "': extra '" + kFaultedIntervalsKey + "' is damaged: " + e.what());
    }
  }
  return root;
}

// What meta.json holds: the recording's meta, and the faulted intervals (kFaultedIntervalsKey) as
// the JSON text to keep in the run, when it lists them.
struct BundleMeta {
  RecordingMeta meta;
  std::optional<std::string> faulted_intervals;
};

// The faulted intervals of meta.json, when it lists them: an array of objects, kept verbatim.
std::optional<std::string> read_faulted_intervals(ObjectReader& r) {
  const json* intervals = r.get(kFaultedIntervalsKey);
  if (intervals == nullptr) return std::nullopt;
  const auto is_object = [](const json& item) { return item.is_object(); };
  if (!intervals->is_array() || !std::all_of(intervals->begin(), intervals->end(), is_object))
    r.fail(kFaultedIntervalsKey, "must be an array of objects");
  return intervals->dump();
}

// meta.json through core's ObjectReader (path first: "site.height_m must be a number, not a
// string"). Keys another writer added are ignored (formats.md lets the format be extended); a
// near miss of a key of ours ("gravity_mps") is refused, or a typo would silently become normal
// gravity.
BundleMeta read_meta(const json& root) {
  const ObjectReader::ThrowAtFirst mode{};
  ObjectReader r(root, "", mode);
  const std::string format = r.required_string("format");
  if (format != kRecordingFormat) r.fail("unknown format '" + format + "' (this imucal reads " + kRecordingFormat + ")");

  BundleMeta bundle;
  RecordingMeta& meta = bundle.meta;
  {
    ObjectReader site(r.required("site"), "site", mode);
    meta.site.latitude_deg = site.required_number_in("latitude_deg", -90.0, 90.0);
    meta.site.longitude_deg = site.required_number_in("longitude_deg", -180.0, 360.0);
    meta.site.height_m = site.required_number("height_m");
    meta.site.middle_axis_azimuth_deg = site.required_number("middle_axis_azimuth_deg");
    meta.site.gravity_mps2 = site.number_in("gravity_mps2", 9.7, 9.9);
    site.finish_extensible();
  }
  {
    ObjectReader imu(r.required("imu"), "imu", mode);
    meta.imu_serial = imu.required_string("serial");
    meta.rate_hz = imu.required_number("rate_hz");
    if (!(meta.rate_hz > 0.0)) imu.fail(imu.at("rate_hz"), "must be positive");
    meta.gyro_lsb_rad = imu.number("gyro_lsb_rad");
    meta.accel_lsb_mps = imu.number("accel_lsb_mps");
    imu.finish_extensible();
  }
  {
    ObjectReader mount(r.required("mount"), "mount", mode);
    const json& c_o_p = mount.required("C_o_p");
    const auto is_row = [](const json& row) { return row.is_array() && row.size() == 3; };
    if (!c_o_p.is_array() || c_o_p.size() != 3 || !std::all_of(c_o_p.begin(), c_o_p.end(), is_row))
      mount.fail(mount.at("C_o_p"), "must be a 3x3 array of numbers");
    for (std::size_t row = 0; row < 3; ++row)
      for (std::size_t col = 0; col < 3; ++col)
        meta.mount.C_o_p(static_cast<Eigen::Index>(row), static_cast<Eigen::Index>(col)) = model_json::num(
            mount, c_o_p[row][col], mount.at("C_o_p") + "[" + std::to_string(row) + "][" + std::to_string(col) + "]");
    const Eigen::Vector3d r0_p_mm = model_json::vec3(mount, "r0_p_mm", 1.0, true);
    meta.mount.r0_p_m = r0_p_mm / 1000.0;
    if (mount.has("r0_p_m")) {
      // Exact metres written by our export; used only while they still agree with the millimetres
      // (someone may have edited r0_p_mm by hand).
      const Eigen::Vector3d r0_p_m = model_json::vec3(mount, "r0_p_m", 1.0);
      if (((r0_p_m * 1000.0 - r0_p_mm).array().abs() <= 1e-9 * (1.0 + r0_p_mm.array().abs())).all()) {
        meta.mount.r0_p_m = r0_p_m;
      }
    }
    mount.finish_extensible();
  }

  if (const json* segments = r.get("segments")) {
    if (!segments->is_array()) r.fail("segments", "must be an array, not " + json_type_name(*segments));
    static const std::array<std::string_view, 6> kKinds = {"static", "rate", "sine", "coning", "tilt", "move"};
    for (std::size_t i = 0; i < segments->size(); ++i) {
      ObjectReader sr((*segments)[i], "segments[" + std::to_string(i) + "]", mode);
      SegmentInfo segment;
      segment.name = sr.required_string("name");
      segment.kind = sr.required_string("kind");
      if (std::find(kKinds.begin(), kKinds.end(), segment.kind) == kKinds.end()) {
        sr.fail(sr.at("kind"), "is '" + segment.kind + "', not one of static, rate, sine, coning, tilt, move");
      }
      segment.t0_s = sr.required_number("t0_s");
      segment.t1_s = sr.required_number("t1_s");
      sr.finish_extensible();
      meta.segments.push_back(segment);
    }
  }
  if (const json* t = r.get("table")) {
    // Another writer may add keys beside ours here too; inside geometry and sigma core refuses
    // what it does not know (a term of the table's error dropped would be a wrong reference).
    ObjectReader tr(*t, "table", mode);
    meta.table = table::read_table_certificate(tr);
    tr.finish_extensible();
  }
  bundle.faulted_intervals = read_faulted_intervals(r);
  r.finish_extensible();
  return bundle;
}

BundleMeta meta_from_bundle(const std::string& dir) {
  const std::string text = read_text_file(fs::path(dir) / "meta.json", dir);
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    fail_bundle(dir, std::string("meta.json: ") + e.what());
  }
  BundleMeta bundle;
  try {
    bundle = read_meta(root);
  } catch (const std::invalid_argument& e) {
    fail_bundle(dir, std::string("meta.json: ") + e.what());
  }

  // Not part of the format: what a simulated run carries (see export_bundle).
  for (auto [file, target] : {std::pair{"program.json", &bundle.meta.program_json},
                              std::pair{"truth.json", &bundle.meta.truth_json}}) {
    const fs::path path = fs::path(dir) / file;
    if (fs::exists(path)) *target = read_text_file(path, dir);
  }
  return bundle;
}

// ---------------------------------------------------------------------------------------------
// frames.csv reading

// Streams a file line by line through one buffer; a line is valid until the next call.
class LineReader {
 public:
  LineReader(const fs::path& path, const std::string& dir)
      : file_(std::fopen(path.c_str(), "rb")), dir_(dir) {
    if (!file_) fail_bundle(dir, "cannot read frames.csv: " + std::string(std::strerror(errno)));
    buffer_.resize(1 << 20);
  }

  // False at the end of the file. Strips the '\n' (the '\r' of CRLF is left to trim()).
  bool next(std::string_view& line) {
    while (true) {
      const char* begin = buffer_.data() + begin_;
      if (const void* newline = std::memchr(begin, '\n', end_ - begin_)) {
        const auto length = static_cast<std::size_t>(static_cast<const char*>(newline) - begin);
        line = std::string_view(begin, length);
        begin_ += length + 1;
        return true;
      }
      if (eof_) {
        if (begin_ == end_) return false;
        line = std::string_view(begin, end_ - begin_);  // last line without a newline
        begin_ = end_;
        return true;
      }
      // Move the partial line to the front and read more; grow for a very long line.
      std::memmove(buffer_.data(), begin, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
      if (end_ == buffer_.size()) buffer_.resize(2 * buffer_.size());
      const std::size_t got = std::fread(buffer_.data() + end_, 1, buffer_.size() - end_, file_.get());
      if (got == 0) {
        if (std::ferror(file_.get())) fail_bundle(dir_, "frames.csv: read error");
        eof_ = true;
      }
      end_ += got;
    }
  }

 private:
  FileHandle file_;
  std::string dir_;
  std::vector<char> buffer_;
  std::size_t begin_ = 0;
  std::size_t end_ = 0;
  bool eof_ = false;
};

void split_fields(std::string_view line, std::vector<std::string_view>& fields) {
  fields.clear();
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    if (comma == std::string_view::npos) {
      fields.push_back(line.substr(start));
      return;
    }
    fields.push_back(line.substr(start, comma - start));
    start = comma + 1;
  }
}

// Walks one CSV line field by field.
class FieldCursor {
 public:
  explicit FieldCursor(std::string_view line) : p_(line.data()), end_(line.data() + line.size()) {}

  bool exhausted() const { return exhausted_; }
  std::size_t consumed() const { return consumed_; }  // fields taken so far

  std::string_view text() {
    const auto* comma = static_cast<const char*>(std::memchr(p_, ',', static_cast<std::size_t>(end_ - p_)));
    const char* stop = comma != nullptr ? comma : end_;
    const std::string_view field(p_, static_cast<std::size_t>(stop - p_));
    advance(stop);
    return field;
  }

  // The next field as a finite double. False when it is not one; then `field` is its whole text.
  bool number(double& value, std::string_view& field) {
    const char* start = p_;
    const char* q = p_;
    while (q < end_ && (*q == ' ' || *q == '\t')) ++q;
    if (end_ - q > 1 && *q == '+' && q[1] != '-') ++q;  // from_chars rejects a leading '+'
    auto [ptr, ec] = std::from_chars(q, end_, value);
    while (ptr < end_ && (*ptr == ' ' || *ptr == '\t' || *ptr == '\r')) ++ptr;
    if (ec == std::errc() && (ptr == end_ || *ptr == ',') && std::isfinite(value)) {
      field = std::string_view(start, static_cast<std::size_t>(ptr - start));
      advance(ptr);
      return true;
    }
    field = text();
    return false;
  }

 private:
  void advance(const char* stop) {
    ++consumed_;
    if (stop == end_) {
      exhausted_ = true;
      p_ = end_;
    } else {
      p_ = stop + 1;  // after a comma there is always one more field, maybe empty
    }
  }

  const char* p_;
  const char* end_;
  std::size_t consumed_ = 0;
  bool exhausted_ = false;
};

bool same_bits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }

bool same_temperatures(const TempSample& a, const TempSample& b) {
  for (int i = 0; i < 3; ++i) {
    if (!same_bits(a.gyro_C(i), b.gyro_C(i)) || !same_bits(a.accel_C(i), b.accel_C(i))) return false;
  }
  if (!same_bits(a.chamber_C, b.chamber_C)) return false;
  if (a.chamber_setpoint_C.has_value() != b.chamber_setpoint_C.has_value()) return false;
  if (a.chamber_setpoint_C && !same_bits(*a.chamber_setpoint_C, *b.chamber_setpoint_C)) return false;
  if (a.coil_sensors_C.has_value() != b.coil_sensors_C.has_value()) return false;
  if (a.coil_sensors_C)
    for (std::size_t c = 0; c < 3; ++c)
      for (std::size_t k = 0; k < 8; ++k)
        if (!same_bits((*a.coil_sensors_C)[c][k], (*b.coil_sensors_C)[c][k])) return false;
  return true;
}

// Parses frames.csv into `run`. Throws StorageError naming the line.
// The columns of frames.csv past the required ones that are kept: the set point's, and the coil
// sensors' when all 24 are there (a coil's mean needs its eight).
struct ExtraColumns {
  std::optional<std::size_t> setpoint;
  std::vector<std::pair<std::size_t, std::size_t>> coil_of_column;  // {coil, sensor}; coil 3: none
  bool with_coils = false;

  bool is_coil(std::size_t column) const { return with_coils && coil_of_column[column].first < 3; }
};

// The kept columns of `header`; the others are listed in the report as ignored.
ExtraColumns extra_columns(const std::vector<std::string>& header, ImportReport& report) {
  ExtraColumns x;
  x.coil_of_column.assign(header.size(), {3, 0});
  int coil_columns = 0;
  for (std::size_t c = 0; c < 3; ++c)
    for (std::size_t k = 0; k < 8; ++k) {
      const auto found = std::find(header.begin() + static_cast<std::ptrdiff_t>(kRequiredColumns.size()),
                                   header.end(), coil_column(c, k));
      if (found == header.end()) continue;
      x.coil_of_column[static_cast<std::size_t>(found - header.begin())] = {c, k};
      ++coil_columns;
    }
  x.with_coils = coil_columns == 24;
  for (std::size_t i = kRequiredColumns.size(); i < header.size(); ++i) {
    if (header[i] == kSetpointColumn && !x.setpoint) {
      x.setpoint = i;
    } else if (!x.is_coil(i)) {
      report.ignored_columns.push_back(header[i]);
    }
  }
  return x;
}

// A line's fields past the required ones: the set point and the coil sensors into `temp` (empty:
// none at this line; `coil_fields` counts those given), the rest skipped. Returns what is wrong
// with them ("" when nothing is). Apart from read_frames_csv, whose loop with it made clang-tidy's
// optional-access analysis take minutes.
std::string read_extra_columns(FieldCursor& cursor, const ExtraColumns& extra, const std::vector<std::string>& header,
                               TempSample& temp, int& coil_fields) {
  while (!cursor.exhausted()) {
    const std::size_t column = cursor.consumed();
    if (column >= header.size()) return "too many fields";
    const bool is_coil = extra.is_coil(column);
    if (column != extra.setpoint && !is_coil) {
      cursor.text();
      continue;
    }
    const std::string_view field = cursor.text();
    if (trim(field).empty()) continue;
    double value_C = 0.0;
    if (auto error = parse_double(field, value_C)) return "column '" + header[column] + "': " + *error;
    if (is_coil) {
      const std::pair<std::size_t, std::size_t>& coil_sensor = extra.coil_of_column[column];
      if (!temp.coil_sensors_C) temp.coil_sensors_C.emplace();
      (*temp.coil_sensors_C)[coil_sensor.first][coil_sensor.second] = value_C;
      ++coil_fields;
    } else {
      temp.chamber_setpoint_C = value_C;
    }
  }
  return {};
}

// Why a field is not a number, and why a time field is not a time ("" when it is): the optionals
// of parse_double and parse_time_ns are read here, so that read_frames_csv has none of its own
// (clang-tidy's optional analysis of that function, loops and all, took over 40 s).
std::string number_problem(std::string_view field) {
  double ignored = 0.0;
  return parse_double(field, ignored).value_or("not a number");
}

std::string time_problem(std::string_view field, std::int64_t& t_ns) { return parse_time_ns(field, t_ns).value_or(""); }

// Whether a line's temperatures differ from the last ones kept (none yet: they do); then they are
// the last ones kept.
bool temperatures_changed(std::optional<TempSample>& last, const TempSample& temp) {
  if (last && same_temperatures(temp, *last)) return false;
  last = temp;
  return true;
}

ImportReport read_frames_csv(const std::string& dir, double rate_hz, RunDb& run) {
  ImportReport report;
  LineReader reader(fs::path(dir) / "frames.csv", dir);
  std::int64_t line_number = 0;
  auto fail_line = [&](const std::string& reason) {
    fail_bundle(dir, "frames.csv line " + std::to_string(line_number) + ": " + reason);
  };

  // Header.
  std::string_view line;
  std::vector<std::string_view> fields;
  ++line_number;
  if (!reader.next(line)) fail_line("empty file, no header");
  if (line.starts_with("\xEF\xBB\xBF")) line.remove_prefix(3);  // UTF-8 byte order mark
  split_fields(line, fields);
  std::vector<std::string> header;
  for (auto field : fields) header.emplace_back(trim(field));
  for (std::size_t i = 0; i < kRequiredColumns.size(); ++i) {
    if (i < header.size() && header[i] == kRequiredColumns[i]) continue;
    const auto found = std::find(header.begin(), header.end(), kRequiredColumns[i]);
    if (found == header.end()) fail_line(std::string("missing column '") + kRequiredColumns[i] + "'");
    fail_line(std::string("column '") + kRequiredColumns[i] + "' is column " +
              std::to_string(found - header.begin() + 1) + ", expected as column " + std::to_string(i + 1));
  }
  const ExtraColumns extra = extra_columns(header, report);

  const double gap_threshold_ns = 1.5e9 / rate_hz;
  std::vector<ImuFrame> frames;
  frames.reserve(kImportBatchFrames);
  std::vector<TempSample> temps;
  std::optional<TempSample> last_temp;
  // The previous frame's time (none before the first): a flag and a value, not an optional, in
  // this loop (its optionals made clang-tidy's optional analysis of the function take minutes).
  bool have_previous = false;
  std::int64_t previous_t_ns = 0;
  std::int64_t previous_line = 0;
  std::array<double, 3> previous_raw_deg{};
  std::array<double, 3> unwrap_offset_deg{};

  while (reader.next(line)) {
    ++line_number;
    if (trim(line).empty()) continue;  // blank lines carry nothing
    // Fields are parsed straight from the line (std::from_chars stops at the comma), so each byte
    // is scanned once; the field count is only worked out when something is wrong, because a
    // wrong count is then the likelier cause (a truncated or merged line).
    FieldCursor cursor(line);
    auto fail_field = [&](const std::string& reason) {
      const std::size_t count = static_cast<std::size_t>(std::count(line.begin(), line.end(), ',')) + 1;
      if (count != header.size()) {
        fail_line(std::string(count < header.size() ? "too few" : "too many") + " fields (" +
                  std::to_string(count) + ", the header has " + std::to_string(header.size()) + ")");
      }
      fail_line(reason);
    };
    auto number = [&](std::size_t column) {
      if (cursor.exhausted()) fail_field("too few fields");
      double value = 0.0;
      std::string_view field;
      if (!cursor.number(value, field)) {
        fail_field("column '" + header[column] + "': " + number_problem(field));
      }
      return value;
    };

    ImuFrame frame;
    const std::string_view t_s_field = cursor.text();
    if (const std::string error = time_problem(t_s_field, frame.t_ns); !error.empty()) fail_field("column 't_s': " + error);
    if (have_previous) {
      if (frame.t_ns <= previous_t_ns) {
        fail_line("time does not increase (t_s " + std::string(trim(t_s_field)) + " after line " +
                  std::to_string(previous_line) + ")");
      }
      if (static_cast<double>(frame.t_ns - previous_t_ns) > gap_threshold_ns) {
        report.gaps.push_back({static_cast<double>(previous_t_ns) / 1e9, static_cast<double>(frame.t_ns) / 1e9,
                               line_number, previous_t_ns, frame.t_ns});
      }
    }
    // The cursor reads in column order.
    std::array<double, kRequiredColumns.size()> value{};
    for (std::size_t column = 1; column < kRequiredColumns.size(); ++column) value[column] = number(column);
    for (std::size_t axis = 0; axis < 3; ++axis) {
      frame.dtheta_rad(static_cast<Eigen::Index>(axis)) = value[1 + axis];
      frame.dv_mps(static_cast<Eigen::Index>(axis)) = value[4 + axis];
    }
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const double raw_deg = value[7 + axis];
      // A jump of more than half a turn between two samples is a wrap of the encoder reading,
      // not motion (it would take > 3600 deg/s at 20 Hz).
      if (have_previous) {
        const double jump_deg = raw_deg - previous_raw_deg[axis];
        if (std::fabs(jump_deg) > 180.0) unwrap_offset_deg[axis] -= 360.0 * std::round(jump_deg / 360.0);
      }
      previous_raw_deg[axis] = raw_deg;
      frame.table_deg(static_cast<Eigen::Index>(axis)) =
          unwrap_offset_deg[axis] == 0.0 ? raw_deg : raw_deg + unwrap_offset_deg[axis];
    }

    TempSample temp;
    temp.t_ns = frame.t_ns;
    for (std::size_t axis = 0; axis < 3; ++axis) {
      temp.gyro_C(static_cast<Eigen::Index>(axis)) = value[10 + axis];
      temp.accel_C(static_cast<Eigen::Index>(axis)) = value[13 + axis];
    }
    temp.chamber_C = value[16];
    int coil_fields = 0;
    if (const std::string problem = read_extra_columns(cursor, extra, header, temp, coil_fields); !problem.empty())
      fail_field(problem);
    if (cursor.consumed() != header.size()) fail_field("too few fields");
    if (coil_fields != 0 && coil_fields != 24)
      fail_line(std::to_string(coil_fields) + " of the 24 coil sensors (temp_gx_1_C .. temp_gz_8_C) given: all or none");
    // Run-length: the export's sample-and-hold gives every frame its values back.
    if (temperatures_changed(last_temp, temp)) temps.push_back(temp);

    frames.push_back(frame);
    previous_t_ns = frame.t_ns;
    have_previous = true;
    previous_line = line_number;
    if (frames.size() == kImportBatchFrames) {
      run.append(frames);
      run.append_temps(temps);
      report.frames += static_cast<std::int64_t>(frames.size());
      report.temp_samples += static_cast<std::int64_t>(temps.size());
      frames.clear();
      temps.clear();
    }
  }
  run.append(frames);
  run.append_temps(temps);
  report.frames += static_cast<std::int64_t>(frames.size());
  report.temp_samples += static_cast<std::int64_t>(temps.size());
  return report;
}

json gaps_to_json(const std::vector<Gap>& gaps) {
  json list = json::array();
  for (const auto& gap : gaps) {
    list.push_back({{"t0_s", gap.t0_s}, {"t1_s", gap.t1_s}, {"line", gap.line},
                    {"t0_ns", gap.t0_ns}, {"t1_ns", gap.t1_ns}});
  }
  return list;
}

}  // namespace

// -----------------------------------------------------------------------------------------------

void export_bundle(const RunDb& run, const std::string& dir, const ExportProgress& progress) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail_bundle(dir, "cannot create the folder: " + ec.message());

  const RecordingMeta meta = run.meta();
  std::vector<TempSample> temps = run.temps();
  if (temps.empty()) temps.emplace_back();  // documented: defaults when the run has none
  const bool with_setpoint = std::any_of(temps.begin(), temps.end(),
                                         [](const TempSample& t) { return t.chamber_setpoint_C.has_value(); });
  const bool with_coils =
      std::any_of(temps.begin(), temps.end(), [](const TempSample& t) { return t.coil_sensors_C.has_value(); });

  const fs::path csv_path = fs::path(dir) / "frames.csv";
  const fs::path partial = fs::path(csv_path.string() + ".partial");
  {
    FileHandle file(std::fopen(partial.c_str(), "wb"));
    auto write_error = [&] {
      fail_bundle(dir, "cannot write frames.csv: " + std::string(std::strerror(errno)));
    };
    if (!file) write_error();

    std::vector<char> buffer(1 << 20);
    std::size_t used = 0;
    auto drain = [&] {
      if (std::fwrite(buffer.data(), 1, used, file.get()) != used) write_error();
      used = 0;
    };
    auto append_text = [&](std::string_view text) {
      std::memcpy(buffer.data() + used, text.data(), text.size());
      used += text.size();
    };
    for (std::size_t i = 0; i < kRequiredColumns.size(); ++i) {
      if (i > 0) append_text(",");
      append_text(kRequiredColumns[i]);
    }
    if (with_setpoint) {
      append_text(",");
      append_text(kSetpointColumn);
    }
    if (with_coils)
      for (std::size_t c = 0; c < 3; ++c)
        for (std::size_t k = 0; k < 8; ++k) {
          append_text(",");
          append_text(coil_column(c, k));
        }
    append_text("\n");

    // One line is at most 42 doubles of <= 24 chars plus a time: far below this margin.
    constexpr std::size_t kMaxLine = 2048;
    std::size_t temp_index = 0;
    const double total_frames = static_cast<double>(std::max<std::int64_t>(1, run.frame_count()));
    std::size_t written = 0;
    run.for_each_frame([&](const ImuFrame& frame) {
      // Told once a chunk's worth of frames: often enough for a person, rare beside the formatting.
      if (progress && written++ % RunDb::kFramesPerChunk == 0) progress(static_cast<double>(written) / total_frames);
      while (temp_index + 1 < temps.size() && temps[temp_index + 1].t_ns <= frame.t_ns) ++temp_index;
      const TempSample& temp = temps[temp_index];
      if (buffer.size() - used < kMaxLine) drain();
      char* out = buffer.data() + used;
      char* const end = buffer.data() + buffer.size();
      out = put_time_s(out, frame.t_ns);
      auto field = [&](double value) {
        *out++ = ',';
        out = put_double(out, end, value);
      };
      for (int axis = 0; axis < 3; ++axis) field(frame.dtheta_rad(axis));
      for (int axis = 0; axis < 3; ++axis) field(frame.dv_mps(axis));
      for (int axis = 0; axis < 3; ++axis) field(frame.table_deg(axis));
      for (int axis = 0; axis < 3; ++axis) field(temp.gyro_C(axis));
      for (int axis = 0; axis < 3; ++axis) field(temp.accel_C(axis));
      field(temp.chamber_C);
      if (with_setpoint) {
        if (temp.chamber_setpoint_C) {
          field(*temp.chamber_setpoint_C);
        } else {
          *out++ = ',';  // no set point at this time: empty field
        }
      }
      if (with_coils)
        for (std::size_t c = 0; c < 3; ++c)
          for (std::size_t k = 0; k < 8; ++k) {
            if (temp.coil_sensors_C) {
              field((*temp.coil_sensors_C)[c][k]);
            } else {
              *out++ = ',';  // a sample without the eight sensors: empty fields
            }
          }
      *out++ = '\n';
      used = static_cast<std::size_t>(out - buffer.data());
    });
    drain();
    if (std::fclose(file.release()) != 0) write_error();
  }
  fs::rename(partial, csv_path, ec);
  if (ec) fail_bundle(dir, "cannot rename frames.csv.partial: " + ec.message());

  // Beyond the format: the texts a simulated run carries, verbatim.
  for (auto [file, text] : {std::pair{"program.json", &meta.program_json},
                            std::pair{"truth.json", &meta.truth_json}}) {
    const fs::path path = fs::path(dir) / file;
    if (!text->empty()) {
      write_text_file(path, *text, dir);
    } else {
      fs::remove(path, ec);  // a stale file from an earlier export would be read back
    }
  }
  // Last, so that a folder with meta.json is complete.
  write_text_file(fs::path(dir) / "meta.json", bundle_meta_json(run, meta).dump(1) + "\n", dir);
  if (progress) progress(1.0);
}

ImportReport import_bundle(const std::string& dir, const std::string& db_path) {
  const BundleMeta bundle = meta_from_bundle(dir);
  const RecordingMeta& meta = bundle.meta;
  std::error_code ec;
  if (fs::exists(db_path, ec)) fail_bundle(dir, "cannot import into '" + db_path + "': file already exists");

  // Import under a temporary name and rename at the end: a reader never sees a half-imported run,
  // and a failed import leaves nothing behind.
  const std::string partial = db_path + ".importing";
  sql::remove_database_files(partial);  // left over from a crashed import
  ImportReport report;
  try {
    {
      RunDb run = RunDb::create(partial, meta);
      report = read_frames_csv(dir, meta.rate_hz, run);
      run.set_extra(kGapsExtraKey, gaps_to_json(report.gaps).dump());
      if (bundle.faulted_intervals) run.set_extra(kFaultedIntervalsKey, *bundle.faulted_intervals);
      run.flush();
    }  // closed here: the last connection's close checkpoints and removes the -wal file
    if (fs::exists(partial + "-wal", ec)) {
      fail_bundle(dir, "'" + partial + "-wal' is still there; is the file open elsewhere?");
    }
    fs::rename(partial, db_path, ec);
    if (ec) fail_bundle(dir, "cannot rename '" + partial + "' to '" + db_path + "': " + ec.message());
  } catch (...) {
    sql::remove_database_files(partial);
    throw;
  }
  sql::remove_database_files(partial);  // only -shm can remain
  return report;
}

std::vector<Gap> stored_gaps(const RunDb& run) {
  std::vector<Gap> gaps;
  const auto text = run.extra(kGapsExtraKey);
  if (!text) return gaps;
  try {
    for (const auto& item : json::parse(*text)) {
      gaps.push_back({item.at("t0_s").get<double>(), item.at("t1_s").get<double>(),
                      item.at("line").get<std::int64_t>(), item.at("t0_ns").get<std::int64_t>(),
                      item.at("t1_ns").get<std::int64_t>()});
    }
  } catch (const json::exception& e) {
    throw StorageError("run database '" + run.path() + "': extra '" + kGapsExtraKey + "' is damaged: " + e.what());
  }
  return gaps;
}

}  // namespace imucal::storage
