// RunDb implementation: SQLite schema, RAII handles, the frame chunk codec.
//
// Schema (PRAGMA user_version = 1, PRAGMA application_id = kApplicationId):
//   run_meta(id = 1, json)                 RecordingMeta without the segments, as JSON
//   imu_chunk(id, t0_ns, t1_ns, n, codec, data)   up to kFramesPerChunk frames per row
//   temp_sample(t_ns, gyro_*_C, accel_*_C, chamber_C, chamber_setpoint_C)
//   segment(idx, name, kind, t0_s, t1_s)
//   extra(key, json)                       results of later stages, import gaps, reports
//
// Chunk payload `data` (little-endian, no padding, n = frames in the chunk):
//   u8 time_encoding
//      1: i64 t_ns of the first frame, then (n - 1) x i32 delta to the previous frame
//      2: n x i64 t_ns (used when a delta does not fit an i32, i.e. a gap > 2.1 s)
//   codec 1 (integer counts):
//      f64 gyro_lsb_rad, f64 accel_lsb_mps (the chunk decodes without the meta)
//      n x {i32 dth_x, dth_y, dth_z, dv_x, dv_y, dv_z}    value = double(count) * lsb,
//      except count = INT32_MIN, which stands for -0.0 (a simulator rounding a small negative
//      value with nearbyint makes -0.0; without this every such chunk would fall back to doubles)
//   codec 2 (doubles):
//      n x {f64 dth_x, dth_y, dth_z, dv_x, dv_y, dv_z}
//   n x {f64 outer_deg, middle_deg, inner_deg}
// Codec 1 costs 4 + 24 + 24 = 52 bytes per frame, codec 2 76. A chunk uses codec 1 only when
// every value is exactly double(count) * lsb (bit for bit) or -0.0, so decoding never changes a
// value (a tolerance such as 1e-6 LSB would).
#include "storage/run_db.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <utility>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

namespace imucal::storage {

namespace {

static_assert(std::endian::native == std::endian::little,
              "the chunk codec memcpy's little-endian values; add byte swapping for this target");

// 'IMUC': lets open() tell an imucal run from any other SQLite file.
constexpr std::int32_t kApplicationId = 0x494D5543;

constexpr int kCodecCounts = 1;
constexpr int kCodecDoubles = 2;
// Counts span +-(2^31 - 1); the one value left over encodes -0.0.
constexpr std::int32_t kNegativeZeroCount = std::numeric_limits<std::int32_t>::min();
constexpr std::uint8_t kTimeDeltas32 = 1;
constexpr std::uint8_t kTimeAbsolute64 = 2;

[[noreturn]] void fail(const std::string& path, const std::string& reason) {
  throw StorageError("run database '" + path + "': " + reason);
}

// ---------------------------------------------------------------------------------------------
// RAII handles

struct DbCloser {
  void operator()(sqlite3* db) const noexcept { sqlite3_close_v2(db); }
};
using DbHandle = std::unique_ptr<sqlite3, DbCloser>;

struct StmtFinalizer {
  void operator()(sqlite3_stmt* stmt) const noexcept { sqlite3_finalize(stmt); }
};

// A statement prepared once and reused; errors carry the file name and SQLite's message.
class Statement {
 public:
  Statement() = default;
  Statement(sqlite3* db, const std::string* path, const char* sql) : db_(db), path_(path) {
    sqlite3_stmt* raw = nullptr;
    if (sqlite3_prepare_v3(db, sql, -1, SQLITE_PREPARE_PERSISTENT, &raw, nullptr) != SQLITE_OK) {
      fail(*path, std::string("cannot prepare '") + sql + "': " + sqlite3_errmsg(db));
    }
    stmt_.reset(raw);
  }

  void bind(int index, std::int64_t value) {
    check(sqlite3_bind_int64(stmt_.get(), index, static_cast<sqlite3_int64>(value)), "bind");
  }
  void bind(int index, double value) { check(sqlite3_bind_double(stmt_.get(), index, value), "bind"); }
  void bind(int index, const std::string& text) {
    // SQLITE_STATIC: every caller steps the statement while `text` is alive.
    check(sqlite3_bind_text64(stmt_.get(), index, text.data(), text.size(), SQLITE_STATIC,
                              SQLITE_UTF8),
          "bind");
  }
  void bind_blob(int index, const void* data, std::size_t size) {
    check(sqlite3_bind_blob64(stmt_.get(), index, data, size, SQLITE_STATIC), "bind");
  }
  void bind_null(int index) { check(sqlite3_bind_null(stmt_.get(), index), "bind"); }
  void bind(int index, const std::optional<double>& value) {
    if (value) {
      bind(index, *value);
    } else {
      bind_null(index);
    }
  }

  // True while a row is available.
  bool step() {
    const int rc = sqlite3_step(stmt_.get());
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    fail(*path_, std::string("'") + sqlite3_sql(stmt_.get()) + "' failed: " + sqlite3_errmsg(db_));
  }
  // For statements without result rows.
  void run() {
    Reset reset(*this);
    while (step()) {
    }
  }
  void reset() noexcept {
    sqlite3_reset(stmt_.get());
    sqlite3_clear_bindings(stmt_.get());
  }

  std::int64_t column_int64(int col) const { return sqlite3_column_int64(stmt_.get(), col); }
  double column_double(int col) const { return sqlite3_column_double(stmt_.get(), col); }
  bool column_is_null(int col) const { return sqlite3_column_type(stmt_.get(), col) == SQLITE_NULL; }
  std::optional<double> column_optional_double(int col) const {
    if (column_is_null(col)) return std::nullopt;
    return column_double(col);
  }
  std::string column_text(int col) const {
    const auto* text = sqlite3_column_text(stmt_.get(), col);
    const int size = sqlite3_column_bytes(stmt_.get(), col);
    if (text == nullptr) return {};
    return std::string(reinterpret_cast<const char*>(text), static_cast<std::size_t>(size));
  }
  std::span<const unsigned char> column_blob(int col) const {
    const void* data = sqlite3_column_blob(stmt_.get(), col);
    const int size = sqlite3_column_bytes(stmt_.get(), col);  // after column_blob, as documented
    if (data == nullptr) return {};
    return {static_cast<const unsigned char*>(data), static_cast<std::size_t>(size)};
  }

  // Resets the statement when a use ends, also by an exception, so that it never holds a read
  // transaction open or keeps stale bindings.
  class Reset {
   public:
    explicit Reset(Statement& stmt) : stmt_(stmt) {}
    ~Reset() { stmt_.reset(); }
    Reset(const Reset&) = delete;
    Reset& operator=(const Reset&) = delete;

   private:
    Statement& stmt_;
  };

 private:
  void check(int rc, const char* what) const {
    if (rc != SQLITE_OK) {
      fail(*path_, std::string(what) + " '" + sqlite3_sql(stmt_.get()) + "': " + sqlite3_errmsg(db_));
    }
  }

  sqlite3* db_ = nullptr;
  const std::string* path_ = nullptr;  // owned by RunDb::Impl, which outlives its statements
  std::unique_ptr<sqlite3_stmt, StmtFinalizer> stmt_;
};

void exec(sqlite3* db, const std::string& path, const char* sql) {
  char* message = nullptr;
  if (sqlite3_exec(db, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    std::string reason = message != nullptr ? message : sqlite3_errmsg(db);
    sqlite3_free(message);
    fail(path, std::string("'") + sql + "' failed: " + reason);
  }
}

std::int64_t pragma_int(sqlite3* db, const std::string& path, const char* sql) {
  Statement stmt(db, &path, sql);
  Statement::Reset reset(stmt);
  if (!stmt.step()) fail(path, std::string("'") + sql + "' returned nothing");
  return stmt.column_int64(0);
}

DbHandle open_handle(const std::string& path, int flags) {
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &raw, flags, nullptr);
  DbHandle db(raw);  // sqlite3_open_v2 may hand out a handle even when it fails
  if (rc != SQLITE_OK) {
    fail(path, std::string("cannot open: ") + (raw != nullptr ? sqlite3_errmsg(raw) : sqlite3_errstr(rc)));
  }
  sqlite3_extended_result_codes(db.get(), 1);
  // A reader (the web UI, `imucal calibrate`) may hold the file briefly; wait instead of failing.
  sqlite3_busy_timeout(db.get(), 5000);
  return db;
}

void use_wal(sqlite3* db, const std::string& path) {
  // WAL lets readers work during recording; NORMAL is durable up to the last checkpointed commit
  // on power loss and never corrupts the file (rosbag2's "OFF" can).
  exec(db, path, "PRAGMA journal_mode=WAL");
  exec(db, path, "PRAGMA synchronous=NORMAL");
}

const char* const kSchemaSql = R"sql(
CREATE TABLE run_meta(id INTEGER PRIMARY KEY CHECK (id = 1), json TEXT NOT NULL);
CREATE TABLE imu_chunk(
  id INTEGER PRIMARY KEY,
  t0_ns INTEGER NOT NULL,
  t1_ns INTEGER NOT NULL,
  n INTEGER NOT NULL,
  codec INTEGER NOT NULL,
  data BLOB NOT NULL);
CREATE INDEX imu_chunk_t0 ON imu_chunk(t0_ns);
-- Value columns are declared without a type on purpose: a REAL column stores -0.0 as the
-- integer 0 and loses the sign, and the run must come back bit for bit.
CREATE TABLE temp_sample(
  t_ns INTEGER PRIMARY KEY,
  gyro_x_C NOT NULL, gyro_y_C NOT NULL, gyro_z_C NOT NULL,
  accel_x_C NOT NULL, accel_y_C NOT NULL, accel_z_C NOT NULL,
  chamber_C NOT NULL,
  chamber_setpoint_C);
CREATE TABLE segment(
  idx INTEGER PRIMARY KEY,
  name TEXT NOT NULL,
  kind TEXT NOT NULL,
  t0_s NOT NULL,
  t1_s NOT NULL);
CREATE TABLE extra(key TEXT PRIMARY KEY, json TEXT NOT NULL);
)sql";

// ---------------------------------------------------------------------------------------------
// Meta as JSON inside the database (not the bundle's meta.json: this one keeps metres, the LSBs
// and the program/truth texts exactly).

std::string meta_to_json(const RecordingMeta& meta) {
  using nlohmann::json;
  json site = {{"latitude_deg", meta.site.latitude_deg},
               {"longitude_deg", meta.site.longitude_deg},
               {"height_m", meta.site.height_m},
               {"middle_axis_azimuth_deg", meta.site.middle_axis_azimuth_deg}};
  if (meta.site.gravity_mps2) site["gravity_mps2"] = *meta.site.gravity_mps2;
  json imu = {{"serial", meta.imu_serial}, {"rate_hz", meta.rate_hz}};
  if (meta.gyro_lsb_rad) imu["gyro_lsb_rad"] = *meta.gyro_lsb_rad;
  if (meta.accel_lsb_mps) imu["accel_lsb_mps"] = *meta.accel_lsb_mps;
  json c_o_p = json::array();
  for (int row = 0; row < 3; ++row) {
    c_o_p.push_back({meta.mount.C_o_p(row, 0), meta.mount.C_o_p(row, 1), meta.mount.C_o_p(row, 2)});
  }
  json mount = {{"C_o_p", c_o_p},
                {"r0_p_m", {meta.mount.r0_p_m.x(), meta.mount.r0_p_m.y(), meta.mount.r0_p_m.z()}}};
  json root = {{"site", site},
               {"imu", imu},
               {"mount", mount},
               {"program_json", meta.program_json},
               {"truth_json", meta.truth_json}};
  return root.dump();
}

RecordingMeta meta_from_json(const std::string& text, const std::string& path) {
  RecordingMeta meta;
  try {
    const auto root = nlohmann::json::parse(text);
    const auto& site = root.at("site");
    meta.site.latitude_deg = site.at("latitude_deg").get<double>();
    meta.site.longitude_deg = site.at("longitude_deg").get<double>();
    meta.site.height_m = site.at("height_m").get<double>();
    meta.site.middle_axis_azimuth_deg = site.at("middle_axis_azimuth_deg").get<double>();
    if (site.contains("gravity_mps2")) meta.site.gravity_mps2 = site["gravity_mps2"].get<double>();
    const auto& imu = root.at("imu");
    meta.imu_serial = imu.at("serial").get<std::string>();
    meta.rate_hz = imu.at("rate_hz").get<double>();
    if (imu.contains("gyro_lsb_rad")) meta.gyro_lsb_rad = imu["gyro_lsb_rad"].get<double>();
    if (imu.contains("accel_lsb_mps")) meta.accel_lsb_mps = imu["accel_lsb_mps"].get<double>();
    const auto& mount = root.at("mount");
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) {
        meta.mount.C_o_p(row, col) = mount.at("C_o_p").at(static_cast<std::size_t>(row))
                                         .at(static_cast<std::size_t>(col)).get<double>();
      }
      meta.mount.r0_p_m(row) = mount.at("r0_p_m").at(static_cast<std::size_t>(row)).get<double>();
    }
    meta.program_json = root.at("program_json").get<std::string>();
    meta.truth_json = root.at("truth_json").get<std::string>();
  } catch (const nlohmann::json::exception& e) {
    fail(path, std::string("run_meta is damaged: ") + e.what());
  }
  return meta;
}

void validate_meta(const RecordingMeta& meta, const std::string& path) {
  if (!(meta.rate_hz > 0.0) || !std::isfinite(meta.rate_hz)) {
    fail(path, "meta.rate_hz must be a positive number");
  }
  for (const auto& lsb : {meta.gyro_lsb_rad, meta.accel_lsb_mps}) {
    if (lsb && (!(*lsb > 0.0) || !std::isfinite(*lsb))) fail(path, "an LSB must be a positive number");
  }
  // JSON cannot carry NaN or infinity; catch them here rather than as a damaged run_meta later.
  const bool finite = std::isfinite(meta.site.latitude_deg) && std::isfinite(meta.site.longitude_deg) &&
                      std::isfinite(meta.site.height_m) &&
                      std::isfinite(meta.site.middle_axis_azimuth_deg) &&
                      std::isfinite(meta.site.gravity_mps2.value_or(0.0)) &&
                      meta.mount.C_o_p.allFinite() && meta.mount.r0_p_m.allFinite();
  if (!finite) fail(path, "meta holds a non-finite number");
}

// ---------------------------------------------------------------------------------------------
// Chunk codec

template <class T>
void put(unsigned char*& out, T value) {
  std::memcpy(out, &value, sizeof(T));
  out += sizeof(T);
}

template <class T>
T get(const unsigned char*& in) {
  T value;
  std::memcpy(&value, in, sizeof(T));
  in += sizeof(T);
  return value;
}

// The integer count that reproduces `value` exactly as double(count) * lsb, if there is one.
std::optional<std::int32_t> exact_count(double value, double lsb) {
  if (std::bit_cast<std::uint64_t>(value) == std::bit_cast<std::uint64_t>(-0.0)) return kNegativeZeroCount;
  const double quotient = value / lsb;
  // |count| >= 2^31 does not fit; the comparison also rejects NaN.
  if (!(std::fabs(quotient) < 2147483647.5)) return std::nullopt;
  const auto count = static_cast<std::int32_t>(std::llround(quotient));
  // Bitwise: -0.0 must not come back as +0.0.
  if (std::bit_cast<std::uint64_t>(static_cast<double>(count) * lsb) != std::bit_cast<std::uint64_t>(value)) {
    return std::nullopt;
  }
  return count;
}

struct EncodedChunk {
  int codec = kCodecDoubles;
  std::vector<unsigned char> data;
};

// `frames` is non-empty with strictly increasing times (append() checks).
void encode_chunk(std::span<const ImuFrame> frames, std::optional<double> gyro_lsb_rad,
                  std::optional<double> accel_lsb_mps, EncodedChunk& out,
                  std::vector<std::int32_t>& counts_scratch) {
  const std::size_t n = frames.size();

  bool deltas_fit = true;
  for (std::size_t i = 1; i < n && deltas_fit; ++i) {
    deltas_fit = frames[i].t_ns - frames[i - 1].t_ns <= std::numeric_limits<std::int32_t>::max();
  }

  bool counts_fit = gyro_lsb_rad.has_value() && accel_lsb_mps.has_value();
  if (counts_fit) {
    counts_scratch.resize(6 * n);
    for (std::size_t i = 0; i < n && counts_fit; ++i) {
      for (int axis = 0; axis < 3 && counts_fit; ++axis) {
        const auto gyro = exact_count(frames[i].dtheta_rad(axis), *gyro_lsb_rad);
        const auto accel = exact_count(frames[i].dv_mps(axis), *accel_lsb_mps);
        counts_fit = gyro.has_value() && accel.has_value();
        if (counts_fit) {
          counts_scratch[6 * i + static_cast<std::size_t>(axis)] = *gyro;
          counts_scratch[6 * i + 3 + static_cast<std::size_t>(axis)] = *accel;
        }
      }
    }
  }
  out.codec = counts_fit ? kCodecCounts : kCodecDoubles;

  const std::size_t time_bytes = deltas_fit ? 8 + 4 * (n - 1) : 8 * n;
  const std::size_t value_bytes = counts_fit ? 16 + 6 * 4 * n : 6 * 8 * n;
  out.data.resize(1 + time_bytes + value_bytes + 3 * 8 * n);

  unsigned char* p = out.data.data();
  put<std::uint8_t>(p, deltas_fit ? kTimeDeltas32 : kTimeAbsolute64);
  put<std::int64_t>(p, frames[0].t_ns);
  for (std::size_t i = 1; i < n; ++i) {
    if (deltas_fit) {
      put<std::int32_t>(p, static_cast<std::int32_t>(frames[i].t_ns - frames[i - 1].t_ns));
    } else {
      put<std::int64_t>(p, frames[i].t_ns);
    }
  }
  if (counts_fit) {
    put<double>(p, *gyro_lsb_rad);
    put<double>(p, *accel_lsb_mps);
    std::memcpy(p, counts_scratch.data(), 6 * 4 * n);
    p += 6 * 4 * n;
  } else {
    for (const auto& frame : frames) {
      for (int axis = 0; axis < 3; ++axis) put<double>(p, frame.dtheta_rad(axis));
      for (int axis = 0; axis < 3; ++axis) put<double>(p, frame.dv_mps(axis));
    }
  }
  for (const auto& frame : frames) {
    for (int axis = 0; axis < 3; ++axis) put<double>(p, frame.table_deg(axis));
  }
}

// Decodes a whole chunk into `out` (resized to n). The size is checked up front, so a damaged row
// gives an error instead of a read past the blob.
void decode_chunk(std::int64_t chunk_id, std::int64_t n_frames, int codec,
                  std::span<const unsigned char> data, std::vector<ImuFrame>& out,
                  const std::string& path) {
  auto damaged = [&](const std::string& why) {
    fail(path, "imu_chunk id " + std::to_string(chunk_id) + " is damaged: " + why);
  };
  if (n_frames <= 0 || n_frames > static_cast<std::int64_t>(RunDb::kFramesPerChunk)) {
    damaged("frame count " + std::to_string(n_frames));
  }
  if (codec != kCodecCounts && codec != kCodecDoubles) damaged("unknown codec " + std::to_string(codec));
  if (data.empty()) damaged("empty payload");
  const auto n = static_cast<std::size_t>(n_frames);
  const std::uint8_t time_encoding = data[0];
  if (time_encoding != kTimeDeltas32 && time_encoding != kTimeAbsolute64) {
    damaged("unknown time encoding " + std::to_string(time_encoding));
  }
  const std::size_t time_bytes = time_encoding == kTimeDeltas32 ? 8 + 4 * (n - 1) : 8 * n;
  const std::size_t value_bytes = codec == kCodecCounts ? 16 + 6 * 4 * n : 6 * 8 * n;
  if (data.size() != 1 + time_bytes + value_bytes + 3 * 8 * n) {
    damaged("payload of " + std::to_string(data.size()) + " bytes for " + std::to_string(n) + " frames");
  }

  out.resize(n);
  const unsigned char* p = data.data() + 1;
  std::int64_t t_ns = get<std::int64_t>(p);
  out[0].t_ns = t_ns;
  for (std::size_t i = 1; i < n; ++i) {
    if (time_encoding == kTimeDeltas32) {
      t_ns += get<std::int32_t>(p);
    } else {
      t_ns = get<std::int64_t>(p);
    }
    out[i].t_ns = t_ns;
  }
  if (codec == kCodecCounts) {
    const double gyro_lsb_rad = get<double>(p);
    const double accel_lsb_mps = get<double>(p);
    auto value = [](std::int32_t count, double lsb) {
      return count == kNegativeZeroCount ? -0.0 : static_cast<double>(count) * lsb;
    };
    for (auto& frame : out) {
      for (int axis = 0; axis < 3; ++axis) frame.dtheta_rad(axis) = value(get<std::int32_t>(p), gyro_lsb_rad);
      for (int axis = 0; axis < 3; ++axis) frame.dv_mps(axis) = value(get<std::int32_t>(p), accel_lsb_mps);
    }
  } else {
    for (auto& frame : out) {
      for (int axis = 0; axis < 3; ++axis) frame.dtheta_rad(axis) = get<double>(p);
      for (int axis = 0; axis < 3; ++axis) frame.dv_mps(axis) = get<double>(p);
    }
  }
  for (auto& frame : out) {
    for (int axis = 0; axis < 3; ++axis) frame.table_deg(axis) = get<double>(p);
  }
}

void remove_db_files(const std::string& path) noexcept {
  std::error_code ignored;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::filesystem::remove(path + suffix, ignored);
  }
}

}  // namespace

// -----------------------------------------------------------------------------------------------

struct RunDb::Impl {
  // Declared first so that it is destroyed last: the statements below finalize before the close.
  std::string path;
  DbHandle db;

  Statement begin, commit, rollback;
  Statement insert_chunk, update_chunk, select_chunks, count_frames, storage_stats;
  Statement insert_temp, select_temps;
  Statement delete_segments, insert_segment, select_segments;
  Statement upsert_extra, select_extra;
  Statement select_meta;

  RecordingMeta meta;  // cached: the codec needs the LSBs on every chunk

  // Frames not yet in a full chunk. buffer[0, persisted_in_open) are already stored in the row
  // open_chunk_id (written by flush()); the next write of the chunk updates that row.
  std::vector<ImuFrame> buffer;
  std::optional<std::int64_t> open_chunk_id;
  std::size_t persisted_in_open = 0;
  std::optional<std::int64_t> last_frame_t_ns;
  std::optional<std::int64_t> last_temp_t_ns;

  EncodedChunk encoded;  // reused between chunks
  std::vector<std::int32_t> counts_scratch;
  bool select_chunks_busy = false;  // for_each_frame called from inside its own callback

  Impl(std::string path_in, DbHandle db_in) : path(std::move(path_in)), db(std::move(db_in)) {
    auto prepare = [&](const char* sql) { return Statement(db.get(), &path, sql); };
    begin = prepare("BEGIN IMMEDIATE");
    commit = prepare("COMMIT");
    rollback = prepare("ROLLBACK");
    insert_chunk = prepare("INSERT INTO imu_chunk(t0_ns, t1_ns, n, codec, data) VALUES (?1, ?2, ?3, ?4, ?5)");
    update_chunk = prepare("UPDATE imu_chunk SET t0_ns = ?1, t1_ns = ?2, n = ?3, codec = ?4, data = ?5 WHERE id = ?6");
    select_chunks = prepare(
        "SELECT id, n, codec, data FROM imu_chunk WHERE t0_ns <= ?2 AND t1_ns >= ?1 ORDER BY t0_ns");
    count_frames = prepare("SELECT COALESCE(SUM(n), 0) FROM imu_chunk");
    storage_stats = prepare(
        "SELECT COUNT(*), COALESCE(SUM(codec = 1), 0), COALESCE(SUM(codec = 2), 0), "
        "COALESCE(SUM(n), 0), COALESCE(SUM(LENGTH(data)), 0) FROM imu_chunk");
    insert_temp = prepare(
        "INSERT INTO temp_sample(t_ns, gyro_x_C, gyro_y_C, gyro_z_C, accel_x_C, accel_y_C, accel_z_C, "
        "chamber_C, chamber_setpoint_C) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
    select_temps = prepare(
        "SELECT t_ns, gyro_x_C, gyro_y_C, gyro_z_C, accel_x_C, accel_y_C, accel_z_C, chamber_C, "
        "chamber_setpoint_C FROM temp_sample ORDER BY t_ns");
    delete_segments = prepare("DELETE FROM segment");
    insert_segment = prepare("INSERT INTO segment(idx, name, kind, t0_s, t1_s) VALUES (?1, ?2, ?3, ?4, ?5)");
    select_segments = prepare("SELECT name, kind, t0_s, t1_s FROM segment ORDER BY idx");
    upsert_extra = prepare("INSERT OR REPLACE INTO extra(key, json) VALUES (?1, ?2)");
    select_extra = prepare("SELECT json FROM extra WHERE key = ?1");
    select_meta = prepare("SELECT json FROM run_meta WHERE id = 1");
  }

  // BEGIN IMMEDIATE .. COMMIT; rolls back when left without commit().
  class Transaction {
   public:
    explicit Transaction(Impl& impl) : impl_(impl) { impl_.begin.run(); }
    void commit() {
      impl_.commit.run();
      committed_ = true;
    }
    ~Transaction() {
      if (!committed_) {
        try {
          impl_.rollback.run();
        } catch (const StorageError&) {
          // The original error is more useful than this one; SQLite has rolled back anyway
          // when the commit itself failed.
        }
      }
    }
    Transaction(const Transaction&) = delete;
    Transaction& operator=(const Transaction&) = delete;

   private:
    Impl& impl_;
    bool committed_ = false;
  };

  // Writes `frames` as one chunk: into the row `id` if given, else a new row. Returns the row id.
  std::int64_t write_chunk(std::span<const ImuFrame> frames, std::optional<std::int64_t> id) {
    encode_chunk(frames, meta.gyro_lsb_rad, meta.accel_lsb_mps, encoded, counts_scratch);
    Statement& stmt = id ? update_chunk : insert_chunk;
    stmt.bind(1, frames.front().t_ns);
    stmt.bind(2, frames.back().t_ns);
    stmt.bind(3, static_cast<std::int64_t>(frames.size()));
    stmt.bind(4, static_cast<std::int64_t>(encoded.codec));
    stmt.bind_blob(5, encoded.data.data(), encoded.data.size());
    if (id) stmt.bind(6, *id);
    stmt.run();
    return id ? *id : static_cast<std::int64_t>(sqlite3_last_insert_rowid(db.get()));
  }

  void load_state() {
    meta = [&] {
      Statement::Reset reset(select_meta);
      if (!select_meta.step()) fail(path, "run_meta is missing");
      return meta_from_json(select_meta.column_text(0), path);
    }();
    {
      Statement stmt(db.get(), &path, "SELECT MAX(t1_ns) FROM imu_chunk");
      Statement::Reset reset(stmt);
      if (stmt.step() && !stmt.column_is_null(0)) last_frame_t_ns = stmt.column_int64(0);
    }
    {
      Statement stmt(db.get(), &path, "SELECT MAX(t_ns) FROM temp_sample");
      Statement::Reset reset(stmt);
      if (stmt.step() && !stmt.column_is_null(0)) last_temp_t_ns = stmt.column_int64(0);
    }
  }
};

RunDb::RunDb(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RunDb::RunDb(RunDb&&) noexcept = default;

RunDb& RunDb::operator=(RunDb&& other) noexcept {
  if (this != &other) {
    RunDb old(std::move(*this));  // flushes and closes the current run
    impl_ = std::move(other.impl_);
  }
  return *this;
}

RunDb::~RunDb() {
  if (!impl_) return;
  try {
    flush();
  } catch (const std::exception& e) {
    spdlog::error("{} (frames buffered since the last flush are lost)", e.what());
  }
}

RunDb::Impl& RunDb::impl() const {
  if (!impl_) throw StorageError("run database: use of a moved-from RunDb");
  return *impl_;
}

const std::string& RunDb::path() const { return impl().path; }

RunDb RunDb::create(const std::string& path, const RecordingMeta& meta) {
  validate_meta(meta, path);
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) fail(path, "file already exists (a run is never overwritten)");
  try {
    auto db = open_handle(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
    use_wal(db.get(), path);
    exec(db.get(), path, "BEGIN IMMEDIATE");
    exec(db.get(), path, kSchemaSql);
    exec(db.get(), path, ("PRAGMA application_id = " + std::to_string(kApplicationId)).c_str());
    exec(db.get(), path, ("PRAGMA user_version = " + std::to_string(kSchemaVersion)).c_str());
    {
      const std::string json = meta_to_json(meta);
      Statement stmt(db.get(), &path, "INSERT INTO run_meta(id, json) VALUES (1, ?1)");
      stmt.bind(1, json);
      stmt.run();
    }
    exec(db.get(), path, "COMMIT");
    auto impl = std::make_unique<Impl>(path, std::move(db));
    impl->meta = meta;
    RunDb run(std::move(impl));
    run.set_segments(meta.segments);
    return run;
  } catch (...) {
    remove_db_files(path);  // a half-made run file would block the next attempt
    throw;
  }
}

RunDb RunDb::open(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail(path, "no such file");
  auto db = open_handle(path, SQLITE_OPEN_READWRITE);
  // SQLite silently falls back to read-only; say so now rather than at the first append.
  if (sqlite3_db_readonly(db.get(), "main") == 1) fail(path, "the file is read-only");

  // Any SQLite file opens; the first read tells whether it is a database at all.
  const std::int64_t application_id = pragma_int(db.get(), path, "PRAGMA application_id");
  if (application_id != kApplicationId) fail(path, "not an imucal run database (wrong application_id)");
  const std::int64_t version = pragma_int(db.get(), path, "PRAGMA user_version");
  if (version > kSchemaVersion) {
    fail(path, "schema version " + std::to_string(version) + " is newer than this imucal supports (" +
                   std::to_string(kSchemaVersion) + "); open it with a newer imucal");
  }
  if (version < kSchemaVersion) {
    // Migrations from older versions go here once there is an older version.
    fail(path, "unknown schema version " + std::to_string(version));
  }
  {
    Statement stmt(db.get(), &path, "PRAGMA quick_check");
    Statement::Reset reset(stmt);
    std::string problems;
    while (stmt.step()) {
      const std::string row = stmt.column_text(0);
      if (row != "ok") problems += (problems.empty() ? "" : "; ") + row;
    }
    if (!problems.empty()) fail(path, "quick_check failed: " + problems);
  }
  use_wal(db.get(), path);

  auto impl = std::make_unique<Impl>(path, std::move(db));
  impl->load_state();
  return RunDb(std::move(impl));
}

// ---- writing ----

void RunDb::append(std::span<const ImuFrame> frames) {
  Impl& d = impl();
  if (frames.empty()) return;
  // Check the whole batch before buffering any of it, so that a rejected call changes nothing.
  std::optional<std::int64_t> previous = d.last_frame_t_ns;
  for (const auto& frame : frames) {
    if (previous && frame.t_ns <= *previous) {
      fail(d.path, "frame time " + std::to_string(frame.t_ns) + " ns does not increase (previous " +
                       std::to_string(*previous) + " ns)");
    }
    previous = frame.t_ns;
  }
  d.buffer.insert(d.buffer.end(), frames.begin(), frames.end());
  d.last_frame_t_ns = previous;

  const std::size_t full_chunks = d.buffer.size() / kFramesPerChunk;
  if (full_chunks == 0) return;
  // The buffer is trimmed only after the commit: on an error the frames stay buffered and
  // the next append or flush writes them again.
  Impl::Transaction txn(d);
  for (std::size_t k = 0; k < full_chunks; ++k) {
    const std::span<const ImuFrame> chunk(d.buffer.data() + k * kFramesPerChunk, kFramesPerChunk);
    d.write_chunk(chunk, k == 0 ? d.open_chunk_id : std::nullopt);
  }
  txn.commit();
  d.buffer.erase(d.buffer.begin(),
                 d.buffer.begin() + static_cast<std::ptrdiff_t>(full_chunks * kFramesPerChunk));
  d.open_chunk_id.reset();
  d.persisted_in_open = 0;
}

void RunDb::flush() {
  Impl& d = impl();
  if (d.buffer.size() == d.persisted_in_open) return;
  Impl::Transaction txn(d);
  const std::int64_t id = d.write_chunk(d.buffer, d.open_chunk_id);
  txn.commit();
  d.open_chunk_id = id;
  d.persisted_in_open = d.buffer.size();
}

void RunDb::append_temps(std::span<const TempSample> temps) {
  Impl& d = impl();
  if (temps.empty()) return;
  std::optional<std::int64_t> previous = d.last_temp_t_ns;
  for (const auto& sample : temps) {
    if (previous && sample.t_ns <= *previous) {
      fail(d.path, "temperature time " + std::to_string(sample.t_ns) +
                       " ns does not increase (previous " + std::to_string(*previous) + " ns)");
    }
    previous = sample.t_ns;
  }
  Impl::Transaction txn(d);
  for (const auto& sample : temps) {
    Statement& stmt = d.insert_temp;
    stmt.bind(1, sample.t_ns);
    for (int axis = 0; axis < 3; ++axis) {
      stmt.bind(2 + axis, sample.gyro_C(axis));
      stmt.bind(5 + axis, sample.accel_C(axis));
    }
    stmt.bind(8, sample.chamber_C);
    stmt.bind(9, sample.chamber_setpoint_C);
    stmt.run();
  }
  txn.commit();
  d.last_temp_t_ns = previous;
}

void RunDb::set_segments(const std::vector<SegmentInfo>& segments) {
  Impl& d = impl();
  Impl::Transaction txn(d);
  d.delete_segments.run();
  std::int64_t index = 0;
  for (const auto& segment : segments) {
    Statement& stmt = d.insert_segment;
    stmt.bind(1, index++);
    stmt.bind(2, segment.name);
    stmt.bind(3, segment.kind);
    stmt.bind(4, segment.t0_s);
    stmt.bind(5, segment.t1_s);
    stmt.run();
  }
  txn.commit();
  d.meta.segments = segments;
}

void RunDb::set_extra(const std::string& key, const std::string& json_text) {
  Impl& d = impl();
  if (!nlohmann::json::accept(json_text)) fail(d.path, "extra '" + key + "' is not valid JSON");
  d.upsert_extra.bind(1, key);
  d.upsert_extra.bind(2, json_text);
  d.upsert_extra.run();
}

// ---- reading ----

std::optional<std::string> RunDb::extra(const std::string& key) const {
  Impl& d = impl();
  Statement::Reset reset(d.select_extra);
  d.select_extra.bind(1, key);
  if (!d.select_extra.step()) return std::nullopt;
  return d.select_extra.column_text(0);
}

RecordingMeta RunDb::meta() const {
  Impl& d = impl();
  RecordingMeta meta = d.meta;
  meta.segments.clear();
  Statement::Reset reset(d.select_segments);
  while (d.select_segments.step()) {
    meta.segments.push_back({d.select_segments.column_text(0), d.select_segments.column_text(1),
                             d.select_segments.column_double(2), d.select_segments.column_double(3)});
  }
  return meta;
}

std::int64_t RunDb::frame_count() const {
  Impl& d = impl();
  Statement::Reset reset(d.count_frames);
  d.count_frames.step();
  return d.count_frames.column_int64(0) + static_cast<std::int64_t>(d.buffer.size() - d.persisted_in_open);
}

void RunDb::for_each_frame(const std::function<void(const ImuFrame&)>& fn, std::int64_t t0_ns,
                           std::int64_t t1_ns) const {
  Impl& d = impl();
  if (t0_ns > t1_ns) return;
  // Copied first: the buffer may change if `fn` misbehaves and appends.
  std::vector<ImuFrame> unstored;
  for (std::size_t i = d.persisted_in_open; i < d.buffer.size(); ++i) {
    if (d.buffer[i].t_ns >= t0_ns && d.buffer[i].t_ns <= t1_ns) unstored.push_back(d.buffer[i]);
  }

  // A nested call (from inside `fn`) gets its own statement; the shared one is mid-iteration.
  std::optional<Statement> nested;
  Statement* stmt = &d.select_chunks;
  if (d.select_chunks_busy) {
    nested.emplace(d.db.get(), &d.path,
                   "SELECT id, n, codec, data FROM imu_chunk WHERE t0_ns <= ?2 AND t1_ns >= ?1 "
                   "ORDER BY t0_ns");
    stmt = &*nested;
  }
  struct BusyFlag {
    bool& flag;
    bool was;
    ~BusyFlag() { flag = was; }
  } busy{d.select_chunks_busy, d.select_chunks_busy};
  d.select_chunks_busy = true;

  Statement::Reset reset(*stmt);
  stmt->bind(1, t0_ns);
  stmt->bind(2, t1_ns);
  std::vector<ImuFrame> decoded;
  decoded.reserve(kFramesPerChunk);
  while (stmt->step()) {
    decode_chunk(stmt->column_int64(0), stmt->column_int64(1), static_cast<int>(stmt->column_int64(2)),
                 stmt->column_blob(3), decoded, d.path);
    // Chunks overlapping the range only at one end: skip to the first frame inside.
    auto first = decoded.begin();
    if (first->t_ns < t0_ns) {
      first = std::lower_bound(decoded.begin(), decoded.end(), t0_ns,
                               [](const ImuFrame& f, std::int64_t t) { return f.t_ns < t; });
    }
    for (auto it = first; it != decoded.end() && it->t_ns <= t1_ns; ++it) fn(*it);
  }
  for (const auto& frame : unstored) fn(frame);
}

std::vector<ImuFrame> RunDb::read_frames(std::int64_t t0_ns, std::int64_t t1_ns) const {
  std::vector<ImuFrame> frames;
  for_each_frame([&](const ImuFrame& frame) { frames.push_back(frame); }, t0_ns, t1_ns);
  return frames;
}

std::vector<TempSample> RunDb::temps() const {
  Impl& d = impl();
  std::vector<TempSample> temps;
  Statement& stmt = d.select_temps;
  Statement::Reset reset(stmt);
  while (stmt.step()) {
    TempSample sample;
    sample.t_ns = stmt.column_int64(0);
    for (int axis = 0; axis < 3; ++axis) {
      sample.gyro_C(axis) = stmt.column_double(1 + axis);
      sample.accel_C(axis) = stmt.column_double(4 + axis);
    }
    sample.chamber_C = stmt.column_double(7);
    sample.chamber_setpoint_C = stmt.column_optional_double(8);
    temps.push_back(sample);
  }
  return temps;
}

FrameStorageStats RunDb::frame_storage_stats() const {
  Impl& d = impl();
  Statement::Reset reset(d.storage_stats);
  d.storage_stats.step();
  FrameStorageStats stats;
  stats.chunks = d.storage_stats.column_int64(0);
  stats.codec1_chunks = d.storage_stats.column_int64(1);
  stats.codec2_chunks = d.storage_stats.column_int64(2);
  stats.frames = d.storage_stats.column_int64(3);
  stats.blob_bytes = d.storage_stats.column_int64(4);
  return stats;
}

}  // namespace imucal::storage
