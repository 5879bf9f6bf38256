// RunDb implementation: SQLite schema and migrations, RAII handles, the frame chunk codec, the
// writer session and recovery.
//
// Schema (PRAGMA user_version = 3, PRAGMA application_id = kApplicationId):
//   run_meta(id = 1, json)                 RecordingMeta without the segments, as JSON
//   imu_chunk(id, t0_ns, t1_ns, n, codec, summary, data)   up to kFramesPerChunk frames per row
//   temp_sample(t_ns, gyro_*_C, accel_*_C, chamber_C, chamber_setpoint_C, coil_sensors_C)
//                                          coil_sensors_C: NULL, or the 24 coil sensors as
//                                          f64 [coil x y z][sensor 1..8] (192 bytes)
//   segment(idx, name, kind, t0_s, t1_s)
//   extra(key, json)                       results of later stages, import gaps, reports
//   recorder_session(...)                  one row per writer session; closed_unix_ms IS NULL
//                                          while writing -- after a crash, the unclean marker
//   dropped_span(session, t0_ns, t1_ns, frames)   frames the recorder had to drop
// Version 1 lacked summary, recorder_session and dropped_span; open() migrates it (a v1 chunk
// keeps a NULL summary and is decoded when a plot needs it). Version 2 lacked coil_sensors_C
// (its samples read as without the eight sensors).
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
// Chunk `summary`: 9 x f64 minimum then 9 x f64 maximum of the channels dtheta xyz, dv xyz,
// table xyz, so that plots of long ranges need no decoding.
#include "storage/run_db.hpp"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <utility>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "core/json_reader.hpp"
#include "core/table_json.hpp"
#include "storage/sqlite.hpp"

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
constexpr std::size_t kSummaryBytes = 2 * RunDb::kPlotChannels * sizeof(double);

// 16 KiB pages: a chunk of ~213 kB spans 13 overflow pages instead of 53, so SQLite makes a
// quarter of the page writes, WAL frame headers and checksums per frame; the half page left
// unused at a chunk's end costs ~2 bytes per frame.
constexpr int kPageSizeBytes = 16384;

[[noreturn]] void fail(const std::string& path, const std::string& reason) {
  throw StorageError("run database '" + path + "': " + reason);
}

using sql::Connection;
using sql::Statement;

void use_wal(Connection& db) {
  // WAL lets readers work during recording; NORMAL is durable up to the last checkpointed commit
  // on power loss and never corrupts the file (rosbag2's "OFF" can).
  db.exec("PRAGMA journal_mode=WAL");
  db.exec("PRAGMA synchronous=NORMAL");
  // A burst (a benchmark, a backlog) can grow the WAL to a few hundred MB; give the space back
  // once a checkpoint has emptied it.
  db.exec("PRAGMA journal_size_limit=67108864");
}

// Version 2, as create() makes it. `summary` precedes `data` on purpose: SQLite stores columns in
// order and a large blob spills into a chain of overflow pages, so a column after it could only
// be read by walking that chain.
const char* const kSchemaSql = R"sql(
CREATE TABLE run_meta(id INTEGER PRIMARY KEY CHECK (id = 1), json TEXT NOT NULL);
CREATE TABLE imu_chunk(
  id INTEGER PRIMARY KEY,
  t0_ns INTEGER NOT NULL,
  t1_ns INTEGER NOT NULL,
  n INTEGER NOT NULL,
  codec INTEGER NOT NULL,
  summary BLOB,
  data BLOB NOT NULL);
CREATE INDEX imu_chunk_t0 ON imu_chunk(t0_ns);
-- Value columns are declared without a type on purpose: a REAL column stores -0.0 as the
-- integer 0 and loses the sign, and the run must come back bit for bit.
CREATE TABLE temp_sample(
  t_ns INTEGER PRIMARY KEY,
  gyro_x_C NOT NULL, gyro_y_C NOT NULL, gyro_z_C NOT NULL,
  accel_x_C NOT NULL, accel_y_C NOT NULL, accel_z_C NOT NULL,
  chamber_C NOT NULL,
  chamber_setpoint_C,
  coil_sensors_C BLOB);
CREATE TABLE segment(
  idx INTEGER PRIMARY KEY,
  name TEXT NOT NULL,
  kind TEXT NOT NULL,
  t0_s NOT NULL,
  t1_s NOT NULL);
CREATE TABLE extra(key TEXT PRIMARY KEY, json TEXT NOT NULL);
)sql";

// Tables that version 2 added to version 1 (also part of a fresh version 2 file).
const char* const kSessionTablesSql = R"sql(
CREATE TABLE recorder_session(
  id INTEGER PRIMARY KEY,
  opened_unix_ms INTEGER NOT NULL,
  closed_unix_ms INTEGER,
  pid INTEGER NOT NULL,
  host TEXT NOT NULL,
  frames_at_open INTEGER NOT NULL,
  committed_frames INTEGER NOT NULL DEFAULT 0,
  committed_t_ns INTEGER,
  commits INTEGER NOT NULL DEFAULT 0,
  queue_high_water_frames INTEGER NOT NULL DEFAULT 0,
  dropped_frames INTEGER NOT NULL DEFAULT 0,
  unclean INTEGER NOT NULL DEFAULT 0,
  lost_uncommitted_frames INTEGER,
  integrity TEXT NOT NULL DEFAULT '');
CREATE TABLE dropped_span(
  id INTEGER PRIMARY KEY,
  session INTEGER NOT NULL,
  t0_ns INTEGER NOT NULL,
  t1_ns INTEGER NOT NULL,
  frames INTEGER NOT NULL);
)sql";

// Turns version `from` into version `from` + 1. The caller runs every step and the new
// user_version in one transaction, so that a failed migration leaves the old version intact.
void migrate_one_step(Connection& db, std::int64_t from) {
  switch (from) {
    case 1:
      // Chunk summaries for plots (NULL for the chunks already written; they are decoded when a
      // plot needs them) and the writer sessions with their unclean-shutdown marker.
      db.exec("ALTER TABLE imu_chunk ADD COLUMN summary BLOB");
      db.exec(kSessionTablesSql);
      return;
    case 2:
      // The eight sensors of each FOG coil (NULL for the samples already written).
      db.exec("ALTER TABLE temp_sample ADD COLUMN coil_sensors_C BLOB");
      return;
    default:
      db.fail("no migration from schema version " + std::to_string(from));
  }
}

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
  // The table's certificate as meta.json has it (arc seconds: its values round-trip to an ulp).
  if (meta.table) root["table"] = json(table::table_certificate_to_json(*meta.table));
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
    if (const auto t = root.find("table"); t != root.end()) {
      ObjectReader r(*t, "table", ObjectReader::ThrowAtFirst{});
      meta.table = table::read_table_certificate(r);
      r.finish();
    }
  } catch (const nlohmann::json::exception& e) {
    fail(path, std::string("run_meta is damaged: ") + e.what());
  } catch (const std::invalid_argument& e) {
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
// `inv_lsb` = 1 / lsb: a multiplication instead of a division on the recorder's hot path; the
// bitwise check below makes the result exact whatever rounding the reciprocal adds, and a value
// the reciprocal misses by one count is retried with the division.
std::optional<std::int32_t> exact_count(double value, double lsb, double inv_lsb) {
  if (std::bit_cast<std::uint64_t>(value) == std::bit_cast<std::uint64_t>(-0.0)) return kNegativeZeroCount;
  for (const double quotient : {value * inv_lsb, value / lsb}) {
    // |count| >= 2^31 does not fit; the comparison also rejects NaN.
    if (!(std::fabs(quotient) < 2147483647.5)) return std::nullopt;
    // Round half away from zero by hand: std::llround is a library call on baseline x86-64,
    // and this runs six times per frame.
    const auto count = static_cast<std::int32_t>(quotient + (quotient >= 0.0 ? 0.5 : -0.5));
    // Bitwise: -0.0 must not come back as +0.0.
    if (std::bit_cast<std::uint64_t>(static_cast<double>(count) * lsb) == std::bit_cast<std::uint64_t>(value)) {
      return count;
    }
  }
  return std::nullopt;
}

struct EncodedChunk {
  int codec = kCodecDoubles;
  std::vector<unsigned char> data;
  std::array<double, 2 * RunDb::kPlotChannels> summary{};  // min of each channel, then max
};

// Min and max of every plot channel over `frames` (non-empty).
void summarize(std::span<const ImuFrame> frames, std::array<double, 2 * RunDb::kPlotChannels>& out) {
  constexpr int kC = RunDb::kPlotChannels;
  std::array<double, kC> lo{}, hi{};
  auto channels = [](const ImuFrame& f, std::array<double, kC>& v) {
    for (int axis = 0; axis < 3; ++axis) {
      v[static_cast<std::size_t>(axis)] = f.dtheta_rad(axis);
      v[static_cast<std::size_t>(3 + axis)] = f.dv_mps(axis);
      v[static_cast<std::size_t>(6 + axis)] = f.table_deg(axis);
    }
  };
  channels(frames[0], lo);
  hi = lo;
  std::array<double, kC> v{};
  for (const auto& frame : frames.subspan(1)) {
    channels(frame, v);
    for (std::size_t k = 0; k < kC; ++k) {
      lo[k] = v[k] < lo[k] ? v[k] : lo[k];
      hi[k] = v[k] > hi[k] ? v[k] : hi[k];
    }
  }
  std::copy(lo.begin(), lo.end(), out.begin());
  std::copy(hi.begin(), hi.end(), out.begin() + kC);
}

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
    const double gyro_inv = 1.0 / *gyro_lsb_rad, accel_inv = 1.0 / *accel_lsb_mps;
    for (std::size_t i = 0; i < n && counts_fit; ++i) {
      for (int axis = 0; axis < 3 && counts_fit; ++axis) {
        const auto gyro = exact_count(frames[i].dtheta_rad(axis), *gyro_lsb_rad, gyro_inv);
        const auto accel = exact_count(frames[i].dv_mps(axis), *accel_lsb_mps, accel_inv);
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
  summarize(frames, out.summary);
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

std::string host_name() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "?";
  return name;
}

// Finds the first chunk that may hold ?1 (chunks never overlap in time, so it is the last one
// starting at or before ?1) through the t0 index, instead of testing t1_ns on every earlier row.
#define IMUCAL_CHUNK_RANGE                                                                       \
  " FROM imu_chunk WHERE t0_ns >= (SELECT COALESCE(MAX(t0_ns), ?1) FROM imu_chunk WHERE t0_ns <= ?1)" \
  " AND t0_ns <= ?2 AND t1_ns >= ?1 ORDER BY t0_ns"
constexpr const char* kSelectChunksSql = "SELECT id, n, codec, data" IMUCAL_CHUNK_RANGE;
constexpr const char* kSelectSummariesSql = "SELECT id, t0_ns, t1_ns, n, summary" IMUCAL_CHUNK_RANGE;
#undef IMUCAL_CHUNK_RANGE

}  // namespace

// -----------------------------------------------------------------------------------------------

struct RunDb::Impl {
  // Declared first so that it is destroyed last: the statements below finalize before the close.
  std::string path;
  Connection db;
  OpenMode mode = OpenMode::Auto;

  Statement begin, commit, rollback;
  Statement insert_chunk, update_chunk, select_chunks, select_summaries, select_chunk_data;
  Statement count_frames, last_frame_time, storage_stats;
  Statement insert_temp, select_temps;
  Statement delete_segments, insert_segment, select_segments;
  Statement upsert_extra, select_extra;
  Statement select_meta;
  Statement insert_session, update_session, select_sessions, insert_dropped, select_dropped;

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

  // ---- the writer session (only while `lease` is held) ----
  std::unique_ptr<WriterLease> lease;
  std::int64_t session_id = 0;
  std::int64_t frames_at_open = 0;
  std::int64_t frames_in_db = 0;              // frames in chunk rows, written by this connection
  std::optional<std::int64_t> db_last_t_ns;   // time of the last frame in a chunk row
  std::int64_t high_water_frames = 0, dropped_frames = 0;
  bool accepted_counted_by_caller = false;
  bool batch_open = false;
  // What this handle knew at begin_batch(), when it matched the committed file: a batch that is
  // rolled back puts it back, so that the writer may write the same data again (a full disk that
  // gets space back) without reopening the run.
  struct Committed {
    std::vector<ImuFrame> buffer;
    std::optional<std::int64_t> open_chunk_id;
    std::size_t persisted_in_open = 0;
    std::optional<std::int64_t> last_frame_t_ns, last_temp_t_ns;
    std::int64_t frames_in_db = 0;
    std::optional<std::int64_t> db_last_t_ns;
    std::vector<SegmentInfo> segments;
  } at_begin;
  std::optional<std::string> poisoned;  // why writes are refused after a batch that could not be undone
  std::vector<DroppedSpan> pending_drops;
  std::optional<RecoveryReport> recovery;

  Impl(std::string path_in, Connection db_in) : path(std::move(path_in)), db(std::move(db_in)) {
    auto prepare = [&](const char* sql) { return Statement(db, sql, true); };
    begin = prepare("BEGIN IMMEDIATE");
    commit = prepare("COMMIT");
    rollback = prepare("ROLLBACK");
    insert_chunk = prepare(
        "INSERT INTO imu_chunk(t0_ns, t1_ns, n, codec, summary, data) VALUES (?1, ?2, ?3, ?4, ?5, ?6)");
    update_chunk = prepare(
        "UPDATE imu_chunk SET t0_ns = ?1, t1_ns = ?2, n = ?3, codec = ?4, summary = ?5, data = ?6 WHERE id = ?7");
    select_chunks = prepare(kSelectChunksSql);
    select_summaries = prepare(kSelectSummariesSql);
    select_chunk_data = prepare("SELECT n, codec, data FROM imu_chunk WHERE id = ?1");
    count_frames = prepare("SELECT COALESCE(SUM(n), 0) FROM imu_chunk");
    last_frame_time = prepare("SELECT MAX(t1_ns) FROM imu_chunk");
    storage_stats = prepare(
        "SELECT COUNT(*), COALESCE(SUM(codec = 1), 0), COALESCE(SUM(codec = 2), 0), "
        "COALESCE(SUM(n), 0), COALESCE(SUM(LENGTH(data)), 0) FROM imu_chunk");
    insert_temp = prepare(
        "INSERT INTO temp_sample(t_ns, gyro_x_C, gyro_y_C, gyro_z_C, accel_x_C, accel_y_C, accel_z_C, "
        "chamber_C, chamber_setpoint_C, coil_sensors_C) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)");
    select_temps = prepare(
        "SELECT t_ns, gyro_x_C, gyro_y_C, gyro_z_C, accel_x_C, accel_y_C, accel_z_C, chamber_C, "
        "chamber_setpoint_C, coil_sensors_C FROM temp_sample WHERE t_ns >= ?1 AND t_ns <= ?2 ORDER BY t_ns");
    delete_segments = prepare("DELETE FROM segment");
    insert_segment = prepare("INSERT INTO segment(idx, name, kind, t0_s, t1_s) VALUES (?1, ?2, ?3, ?4, ?5)");
    select_segments = prepare("SELECT name, kind, t0_s, t1_s FROM segment ORDER BY idx");
    upsert_extra = prepare("INSERT OR REPLACE INTO extra(key, json) VALUES (?1, ?2)");
    select_extra = prepare("SELECT json FROM extra WHERE key = ?1");
    select_meta = prepare("SELECT json FROM run_meta WHERE id = 1");
    insert_session = prepare(
        "INSERT INTO recorder_session(opened_unix_ms, pid, host, frames_at_open) VALUES (?1, ?2, ?3, ?4)");
    update_session = prepare(
        "UPDATE recorder_session SET committed_frames = ?2, committed_t_ns = ?3, commits = commits + ?4, "
        "queue_high_water_frames = ?5, dropped_frames = ?6, closed_unix_ms = ?7 WHERE id = ?1");
    select_sessions = prepare(
        "SELECT id, opened_unix_ms, closed_unix_ms, pid, host, frames_at_open, committed_frames, committed_t_ns, "
        "commits, queue_high_water_frames, dropped_frames, unclean, lost_uncommitted_frames, integrity "
        "FROM recorder_session ORDER BY id");
    insert_dropped = prepare("INSERT INTO dropped_span(session, t0_ns, t1_ns, frames) VALUES (?1, ?2, ?3, ?4)");
    select_dropped = prepare("SELECT session, t0_ns, t1_ns, frames FROM dropped_span ORDER BY t0_ns");
  }

  std::int64_t query_int(Statement& stmt) {
    Statement::Reset reset(stmt);
    if (!stmt.step() || stmt.column_is_null(0)) return 0;
    return stmt.column_int64(0);
  }

  std::optional<std::int64_t> query_optional_int(Statement& stmt) {
    Statement::Reset reset(stmt);
    if (!stmt.step()) return std::nullopt;
    return stmt.column_optional_int64(0);
  }

  // BEGIN IMMEDIATE .. COMMIT; rolls back when left without commit(). Inside a batch it only
  // marks a unit of work: the batch's transaction holds it, and a failure aborts the batch.
  class Transaction {
   public:
    explicit Transaction(Impl& impl) : impl_(impl), nested_(impl.batch_open) {
      if (!nested_) impl_.begin.run();
    }
    void commit() {
      if (!nested_) impl_.commit.run();
      committed_ = true;
    }
    ~Transaction() {
      if (committed_) return;
      if (nested_) {
        impl_.abort_batch();
        return;
      }
      try {
        impl_.rollback.run();
      } catch (const StorageError&) {
        // The original error is more useful than this one; SQLite has rolled back anyway
        // when the commit itself failed.
      }
    }
    Transaction(const Transaction&) = delete;
    Transaction& operator=(const Transaction&) = delete;

   private:
    Impl& impl_;
    bool nested_;
    bool committed_ = false;
  };

  void remember_committed() {
    at_begin.buffer.assign(buffer.begin(), buffer.end());
    at_begin.open_chunk_id = open_chunk_id;
    at_begin.persisted_in_open = persisted_in_open;
    at_begin.last_frame_t_ns = last_frame_t_ns;
    at_begin.last_temp_t_ns = last_temp_t_ns;
    at_begin.frames_in_db = frames_in_db;
    at_begin.db_last_t_ns = db_last_t_ns;
    at_begin.segments = meta.segments;
  }

  // Rolls the open batch back and puts this handle back where the file is, at the last commit:
  // everything written since begin_batch() is gone from both, and the caller may write it again.
  // Only when SQLite cannot roll back (the transaction still open) does the handle refuse writes
  // from then on. Idempotent, never throws.
  void abort_batch() noexcept {
    if (!batch_open) return;
    batch_open = false;
    try {
      rollback.run();
    } catch (const StorageError&) {
      // SQLite may have rolled back by itself (a full disk at COMMIT does).
    }
    pending_drops.clear();
    if (db.in_transaction()) {
      poisoned = "a write of the batch failed and the batch could not be rolled back";
      buffer.clear();
      persisted_in_open = 0;
      open_chunk_id.reset();
      return;
    }
    buffer.swap(at_begin.buffer);
    open_chunk_id = at_begin.open_chunk_id;
    persisted_in_open = at_begin.persisted_in_open;
    last_frame_t_ns = at_begin.last_frame_t_ns;
    last_temp_t_ns = at_begin.last_temp_t_ns;
    frames_in_db = at_begin.frames_in_db;
    db_last_t_ns = at_begin.db_last_t_ns;
    meta.segments.swap(at_begin.segments);
  }

  // Writes `frames` as one chunk: into the row `id` if given, else a new row. Returns the row id.
  std::int64_t write_chunk(std::span<const ImuFrame> frames, std::optional<std::int64_t> id) {
    encode_chunk(frames, meta.gyro_lsb_rad, meta.accel_lsb_mps, encoded, counts_scratch);
    Statement& stmt = id ? update_chunk : insert_chunk;
    stmt.bind(1, frames.front().t_ns);
    stmt.bind(2, frames.back().t_ns);
    stmt.bind(3, static_cast<std::int64_t>(frames.size()));
    stmt.bind(4, static_cast<std::int64_t>(encoded.codec));
    stmt.bind_blob(5, encoded.summary.data(), kSummaryBytes);
    stmt.bind_blob(6, encoded.data.data(), encoded.data.size());
    if (id) stmt.bind(7, *id);
    stmt.run();
    return id ? *id : db.last_insert_rowid();
  }

  void load_state() {
    meta = [&] {
      Statement::Reset reset(select_meta);
      if (!select_meta.step()) fail(path, "run_meta is missing");
      return meta_from_json(select_meta.column_text(0), path);
    }();
    last_frame_t_ns = query_optional_int(last_frame_time);
    {
      Statement stmt(db, "SELECT MAX(t_ns) FROM temp_sample");
      last_temp_t_ns = query_optional_int(stmt);
    }
  }

  // ---- writer session ----

  void publish_committed() {
    if (lease) lease->set_committed(frames_in_db - frames_at_open, db_last_t_ns.value_or(0));
  }

  void ensure_writable() {
    if (poisoned) {
      fail(path, "an earlier write failed (" + *poisoned +
                     "); this handle accepts no more writes: reopen the run to continue");
    }
    claim();
  }

  void claim() {
    if (lease) return;
    if (mode == OpenMode::Read) fail(path, "opened for reading only");
    // A reader recovering a dead writer's run holds the lease for a moment: wait that out (the
    // daemon resuming a run after a crash while a viewer opens it failed the run, issue 33).
    auto new_lease = WriterLease::acquire(path, std::chrono::seconds(3));
    recover(*new_lease);
    start_session(std::move(new_lease));
  }

  void start_session(std::unique_ptr<WriterLease> new_lease) {
    // Another writer may have appended since this handle opened: continue from the file.
    load_state();
    buffer.clear();
    persisted_in_open = 0;
    open_chunk_id.reset();
    frames_in_db = query_int(count_frames);
    db_last_t_ns = last_frame_t_ns;
    {
      const std::string host = host_name();
      insert_session.bind(1, unix_ms_now());
      insert_session.bind(2, static_cast<std::int64_t>(::getpid()));
      insert_session.bind(3, host);
      insert_session.bind(4, frames_in_db);
      insert_session.run();  // its own transaction: the marker must be on disk before any frame
    }
    session_id = db.last_insert_rowid();
    frames_at_open = frames_in_db;
    high_water_frames = 0;
    dropped_frames = 0;
    new_lease->begin_session(session_id, frames_at_open);
    lease = std::move(new_lease);
    publish_committed();
  }

  // Closes the sessions that a writer left open when it died: checks the whole file first, then
  // records what the dead writer's lease page says it lost. Needs the lease (no writer is alive).
  void recover(const WriterLease& held) {
    struct Open {
      std::int64_t id, pid, frames_at_open;
    };
    std::vector<Open> open_sessions;
    {
      Statement stmt(db,
                     "SELECT id, pid, frames_at_open FROM recorder_session WHERE closed_unix_ms IS NULL ORDER BY id");
      Statement::Reset reset(stmt);
      while (stmt.step()) open_sessions.push_back({stmt.column_int64(0), stmt.column_int64(1), stmt.column_int64(2)});
    }
    if (open_sessions.empty()) return;
    const Open& last = open_sessions.back();
    {
      Statement stmt(db, "PRAGMA integrity_check");
      Statement::Reset reset(stmt);
      std::string problems;
      int shown = 0;
      while (stmt.step()) {
        const std::string row = stmt.column_text(0);
        if (row != "ok" && shown++ < 5) problems += (problems.empty() ? "" : "; ") + row;
      }
      if (!problems.empty()) {
        fail(path, "the last writer (process " + std::to_string(last.pid) +
                       ") ended without closing the run, and PRAGMA integrity_check reports: " + problems +
                       "; the file is left as it is (copy it before trying to repair it)");
      }
    }
    const std::int64_t frames_now = query_int(count_frames);
    const std::optional<std::int64_t> last_t = query_optional_int(last_frame_time);
    RecoveryReport report;
    report.session_id = last.id;
    report.pid = last.pid;
    report.committed_frames = frames_now - last.frames_at_open;
    report.committed_t_ns = last_t;
    const auto& page = held.previous();
    std::int64_t high_water = 0, dropped = 0;
    if (page && page->session_id == last.id) {
      report.lost_uncommitted_frames = std::max<std::int64_t>(0, page->frames_at_open + page->accepted_frames - frames_now);
      if (page->accepted_frames > 0) report.accepted_t_ns = page->accepted_t_ns;
      high_water = page->high_water_frames;
      dropped = page->dropped_frames;
    }
    Transaction txn(*this);
    for (const auto& session : open_sessions) {
      const bool is_last = session.id == last.id;
      Statement stmt(db,
                     "UPDATE recorder_session SET closed_unix_ms = ?2, unclean = 1, integrity = 'ok', "
                     "lost_uncommitted_frames = ?3, committed_frames = ?4, committed_t_ns = ?5, "
                     "queue_high_water_frames = MAX(queue_high_water_frames, ?6), "
                     "dropped_frames = MAX(dropped_frames, ?7) WHERE id = ?1");
      stmt.bind(1, session.id);
      stmt.bind(2, unix_ms_now());
      stmt.bind(3, is_last ? report.lost_uncommitted_frames : std::nullopt);
      stmt.bind(4, is_last ? report.committed_frames : std::int64_t{0});
      stmt.bind(5, is_last ? last_t : std::nullopt);
      stmt.bind(6, is_last ? high_water : std::int64_t{0});
      stmt.bind(7, is_last ? dropped : std::int64_t{0});
      stmt.run();
    }
    txn.commit();
    spdlog::warn("run '{}': the last writer (process {}) ended without closing the run; integrity_check ok, "
                 "{} frames of its session committed, {} accepted frames lost",
                 path, last.pid, report.committed_frames,
                 report.lost_uncommitted_frames ? std::to_string(*report.lost_uncommitted_frames) : "an unknown number of");
    recovery = report;
  }

  void write_session_row(std::int64_t commits_added, std::optional<std::int64_t> closed_ms) {
    update_session.bind(1, session_id);
    update_session.bind(2, frames_in_db - frames_at_open);
    update_session.bind(3, db_last_t_ns);
    update_session.bind(4, commits_added);
    update_session.bind(5, high_water_frames);
    update_session.bind(6, dropped_frames);
    update_session.bind(7, closed_ms);
    update_session.run();
  }

  void write_pending_drops() {
    for (const auto& span : pending_drops) {
      insert_dropped.bind(1, session_id);
      insert_dropped.bind(2, span.t0_ns);
      insert_dropped.bind(3, span.t1_ns);
      insert_dropped.bind(4, span.frames);
      insert_dropped.run();
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
    close();
  } catch (const std::exception& e) {
    spdlog::error("{} (frames buffered since the last commit are lost; the next open recovers the run)", e.what());
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
  auto lease = WriterLease::acquire(path);  // two processes creating the same run: one wins
  if (std::filesystem::exists(path, ec)) fail(path, "file already exists (a run is never overwritten)");
  // Made under a temporary name and renamed when complete, so that a crash while creating never
  // leaves a file at `path` that is not a run.
  const std::string making = path + ".creating";
  try {
    sql::remove_database_files(making);
    {
      Connection db(making, Connection::Open::create, "run database");
      db.exec(("PRAGMA page_size = " + std::to_string(kPageSizeBytes)).c_str());
      use_wal(db);
      db.exec("BEGIN IMMEDIATE");
      db.exec(kSchemaSql);
      db.exec(kSessionTablesSql);
      db.exec(("PRAGMA application_id = " + std::to_string(kApplicationId)).c_str());
      db.exec(("PRAGMA user_version = " + std::to_string(kSchemaVersion)).c_str());
      {
        const std::string json = meta_to_json(meta);
        Statement stmt(db, "INSERT INTO run_meta(id, json) VALUES (1, ?1)");
        stmt.bind(1, json);
        stmt.run();
      }
      db.exec("COMMIT");
    }  // closing the only connection checkpoints the WAL into the file and removes it
    std::filesystem::rename(making, path);
  } catch (const std::filesystem::filesystem_error& e) {
    sql::remove_database_files(making);
    lease->release(true);
    fail(path, std::string("cannot create: ") + e.what());
  } catch (...) {
    sql::remove_database_files(making);
    lease->release(true);
    throw;
  }
  try {
    Connection db(path, Connection::Open::read_write, "run database");
    use_wal(db);
    auto impl = std::make_unique<Impl>(path, std::move(db));
    impl->mode = OpenMode::Write;
    impl->start_session(std::move(lease));
    RunDb run(std::move(impl));
    run.set_segments(meta.segments);
    return run;
  } catch (...) {
    sql::remove_database_files(path);  // a half-made run file would block the next attempt
    if (lease) lease->release(true);
    throw;
  }
}

RunDb RunDb::open(const std::string& path, OpenMode mode) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail(path, "no such file");
  Connection db(path, Connection::Open::read_write, "run database");
  // SQLite silently falls back to read-only; say so now rather than at the first append.
  if (db.read_only()) fail(path, "the file is read-only");

  // Any SQLite file opens; the first read tells whether it is a database at all.
  const std::int64_t application_id = db.query_int("PRAGMA application_id");
  if (application_id != kApplicationId) fail(path, "not an imucal run database (wrong application_id)");
  const std::int64_t version = db.query_int("PRAGMA user_version");
  if (version > kSchemaVersion) {
    fail(path, "schema version " + std::to_string(version) + " is newer than this imucal supports (" +
                   std::to_string(kSchemaVersion) + "); open it with a newer imucal");
  }
  if (version < 1) fail(path, "unknown schema version " + std::to_string(version));
  use_wal(db);
  if (version < kSchemaVersion) {
    // BEGIN IMMEDIATE: two processes opening an old file at once migrate it once, one after the
    // other (the second sees the new version and does nothing).
    db.exec("BEGIN IMMEDIATE");
    try {
      const std::int64_t now = db.query_int("PRAGMA user_version");
      for (std::int64_t v = now; v < kSchemaVersion; ++v) migrate_one_step(db, v);
      db.exec(("PRAGMA user_version = " + std::to_string(kSchemaVersion)).c_str());
      db.exec("COMMIT");
    } catch (...) {
      sql::rollback_quietly(db);
      throw;
    }
    spdlog::info("run '{}': schema migrated from version {} to {}", path, version, kSchemaVersion);
  }

  auto impl = std::make_unique<Impl>(path, std::move(db));
  impl->mode = mode;
  impl->load_state();
  if (mode == OpenMode::Write) {
    impl->claim();
  } else {
    Statement stmt(impl->db,
                   "SELECT EXISTS(SELECT 1 FROM recorder_session WHERE closed_unix_ms IS NULL)");
    if (impl->query_int(stmt) != 0 && !WriterLease::probe(path).held) {
      // The marker without a live writer: the writer died. Recover now, under the lease, so
      // that readers (plots, estimators) see a checked file and the loss is on record.
      std::unique_ptr<WriterLease> lease;
      try {
        lease = WriterLease::acquire(path);
      } catch (const StorageError&) {
        // A writer started meanwhile; it recovers the run itself.
      }
      if (lease) {
        impl->recover(*lease);
        lease->release(true);
        impl->load_state();
      }
    }
  }
  return RunDb(std::move(impl));
}

// ---- writing ----

void RunDb::append(std::span<const ImuFrame> frames) {
  Impl& d = impl();
  if (frames.empty()) return;
  d.ensure_writable();
  const bool in_batch = d.batch_open;
  // Check the whole batch before buffering any of it, so that a rejected call changes nothing.
  std::optional<std::int64_t> previous = d.last_frame_t_ns;
  for (const auto& frame : frames) {
    if (previous && frame.t_ns <= *previous) {
      fail(d.path, "frame time " + std::to_string(frame.t_ns) + " ns does not increase (previous " +
                       std::to_string(*previous) + " ns)");
    }
    previous = frame.t_ns;
  }
  d.last_frame_t_ns = previous;
  if (!d.accepted_counted_by_caller) d.lease->add_accepted(static_cast<std::int64_t>(frames.size()), *previous);
  if (d.buffer.size() + frames.size() < kFramesPerChunk) {
    d.buffer.insert(d.buffer.end(), frames.begin(), frames.end());
    return;
  }

  // The open chunk is topped up from `frames`, then whole chunks are encoded straight from
  // `frames` (no copy through the buffer); only the remainder is buffered.
  const std::size_t head = d.buffer.empty() ? 0 : kFramesPerChunk - d.buffer.size();
  std::size_t used = 0;
  bool head_buffered = false;
  try {
    Impl::Transaction txn(d);
    if (head > 0) {
      d.buffer.insert(d.buffer.end(), frames.begin(), frames.begin() + static_cast<std::ptrdiff_t>(head));
      head_buffered = true;
      d.write_chunk(d.buffer, d.open_chunk_id);
      used = head;
    }
    while (frames.size() - used >= kFramesPerChunk) {
      d.write_chunk(frames.subspan(used, kFramesPerChunk), std::nullopt);
      used += kFramesPerChunk;
    }
    txn.commit();
  } catch (...) {
    // Outside a batch the frames stay buffered and the next append or flush writes them again;
    // inside one the batch is rolled back with the handle (abort_batch) and the caller has them.
    if (!in_batch && !d.poisoned) {
      d.buffer.insert(d.buffer.end(), frames.begin() + static_cast<std::ptrdiff_t>(head_buffered ? head : 0),
                      frames.end());
    }
    throw;
  }
  d.frames_in_db += static_cast<std::int64_t>((head > 0 ? kFramesPerChunk - d.persisted_in_open : 0) + (used - head));
  d.db_last_t_ns = frames[used - 1].t_ns;
  d.buffer.assign(frames.begin() + static_cast<std::ptrdiff_t>(used), frames.end());
  d.open_chunk_id.reset();
  d.persisted_in_open = 0;
  if (!d.batch_open) d.publish_committed();
}

void RunDb::flush() {
  Impl& d = impl();
  if (d.buffer.size() == d.persisted_in_open) return;
  d.ensure_writable();
  Impl::Transaction txn(d);
  const std::int64_t id = d.write_chunk(d.buffer, d.open_chunk_id);
  txn.commit();
  d.frames_in_db += static_cast<std::int64_t>(d.buffer.size() - d.persisted_in_open);
  d.db_last_t_ns = d.buffer.back().t_ns;
  d.open_chunk_id = id;
  d.persisted_in_open = d.buffer.size();
  if (!d.batch_open) d.publish_committed();
}

void RunDb::append_temps(std::span<const TempSample> temps) {
  Impl& d = impl();
  if (temps.empty()) return;
  d.ensure_writable();
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
    if (sample.coil_sensors_C) {
      stmt.bind_blob(10, sample.coil_sensors_C->data(), sizeof *sample.coil_sensors_C);  // bound until run()
    } else {
      stmt.bind_null(10);
    }
    stmt.run();
  }
  txn.commit();
  d.last_temp_t_ns = previous;
}

void RunDb::set_segments(const std::vector<SegmentInfo>& segments) {
  Impl& d = impl();
  d.ensure_writable();
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
  d.ensure_writable();
  Impl::Transaction txn(d);
  d.upsert_extra.bind(1, key);
  d.upsert_extra.bind(2, json_text);
  d.upsert_extra.run();
  txn.commit();
}

void RunDb::begin_batch() {
  Impl& d = impl();
  d.ensure_writable();
  if (d.batch_open) fail(d.path, "begin_batch() inside a batch");
  d.begin.run();
  d.remember_committed();
  d.batch_open = true;
}

void RunDb::commit_batch() {
  Impl& d = impl();
  if (!d.batch_open) fail(d.path, "commit_batch() without begin_batch()");
  try {
    flush();
    d.write_pending_drops();
    d.write_session_row(1, std::nullopt);
    d.commit.run();
  } catch (...) {
    d.abort_batch();
    throw;
  }
  d.batch_open = false;
  d.pending_drops.clear();
  d.publish_committed();
}

bool RunDb::in_batch() const { return impl().batch_open; }

void RunDb::close() {
  Impl& d = impl();
  try {
    if (d.batch_open) commit_batch();
    flush();
    if (!d.lease) return;
    if (d.poisoned) {
      fail(d.path, "the writer session ends after a failed write (" + *d.poisoned +
                       "); the next open recovers the run");
    }
    Impl::Transaction txn(d);
    d.write_pending_drops();
    d.pending_drops.clear();
    d.write_session_row(0, unix_ms_now());
    txn.commit();
    d.lease->release(true);
    d.lease.reset();
    d.session_id = 0;
  } catch (...) {
    if (d.lease) {
      d.lease->release(false);  // keep the page: the next open counts what was lost
      d.lease.reset();
    }
    throw;
  }
}

void RunDb::abandon(const std::string& why) noexcept {
  if (!impl_) return;
  Impl& d = *impl_;
  d.abort_batch();
  d.poisoned = why;
  d.buffer.clear();
  d.persisted_in_open = 0;
  d.open_chunk_id.reset();
  d.pending_drops.clear();
  if (d.lease) {
    d.lease->release(false);  // the page stays: the next open counts what was accepted and lost
    d.lease.reset();
  }
}

void RunDb::claim_writer() { impl().ensure_writable(); }

void RunDb::checkpoint() {
  Impl& d = impl();
  if (d.batch_open) fail(d.path, "checkpoint() inside a batch");
  d.db.checkpoint();
}

bool RunDb::is_writer() const { return impl().lease != nullptr; }

WriterLease* RunDb::lease() { return impl().lease.get(); }

void RunDb::set_accepted_counted_by_caller(bool by_caller) { impl().accepted_counted_by_caller = by_caller; }

void RunDb::set_queue_counters(std::int64_t high_water_frames, std::int64_t dropped_frames) {
  Impl& d = impl();
  d.high_water_frames = high_water_frames;
  d.dropped_frames = dropped_frames;
}

void RunDb::record_dropped(std::int64_t t0_ns, std::int64_t t1_ns, std::int64_t frames) {
  Impl& d = impl();
  d.ensure_writable();
  d.pending_drops.push_back({d.session_id, t0_ns, t1_ns, frames});
  if (d.batch_open) return;
  Impl::Transaction txn(d);
  d.write_pending_drops();
  txn.commit();
  d.pending_drops.clear();
}

void RunDb::set_size_limit_bytes(std::int64_t bytes) {
  Impl& d = impl();
  const std::int64_t page_bytes = d.db.query_int("PRAGMA page_size");
  const std::int64_t pages = std::max<std::int64_t>(1, bytes / page_bytes);
  d.db.query_int(("PRAGMA max_page_count = " + std::to_string(pages)).c_str());
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
  return d.query_int(d.count_frames) + static_cast<std::int64_t>(d.buffer.size() - d.persisted_in_open);
}

std::optional<std::int64_t> RunDb::last_frame_t_ns() const { return impl().last_frame_t_ns; }

std::optional<std::int64_t> RunDb::last_temperature_t_ns() const { return impl().last_temp_t_ns; }

void RunDb::for_each_block(const std::function<void(std::span<const ImuFrame>)>& fn, std::int64_t t0_ns,
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
    nested.emplace(d.db, kSelectChunksSql);
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
    // Chunks overlapping the range only at one end: trim to the frames inside.
    auto first = decoded.begin();
    if (first->t_ns < t0_ns) {
      first = std::lower_bound(decoded.begin(), decoded.end(), t0_ns,
                               [](const ImuFrame& f, std::int64_t t) { return f.t_ns < t; });
    }
    auto last = decoded.end();
    if (decoded.back().t_ns > t1_ns) {
      last = std::upper_bound(first, decoded.end(), t1_ns,
                              [](std::int64_t t, const ImuFrame& f) { return t < f.t_ns; });
    }
    if (first != last) fn(std::span<const ImuFrame>(&*first, static_cast<std::size_t>(last - first)));
  }
  if (!unstored.empty()) fn(unstored);
}

void RunDb::for_each_frame(const std::function<void(const ImuFrame&)>& fn, std::int64_t t0_ns,
                           std::int64_t t1_ns) const {
  for_each_block(
      [&](std::span<const ImuFrame> block) {
        for (const auto& frame : block) fn(frame);
      },
      t0_ns, t1_ns);
}

std::vector<ImuFrame> RunDb::read_frames(std::int64_t t0_ns, std::int64_t t1_ns) const {
  std::vector<ImuFrame> frames;
  for_each_block([&](std::span<const ImuFrame> block) { frames.insert(frames.end(), block.begin(), block.end()); },
                 t0_ns, t1_ns);
  return frames;
}

std::vector<PlotColumn> RunDb::decimate(std::int64_t t0_ns, std::int64_t t1_ns, int columns) const {
  Impl& d = impl();
  if (columns <= 0) fail(d.path, "decimate: the number of columns must be positive");
  std::int64_t span_ns = 0;
  if (t1_ns <= t0_ns || __builtin_sub_overflow(t1_ns, t0_ns, &span_ns)) {
    fail(d.path, "decimate: the range must be non-empty and shorter than 292 years");
  }
  const auto n_columns = static_cast<std::size_t>(columns);
  // Column k is [edge[k], edge[k + 1]); long double holds any int64 exactly.
  std::vector<std::int64_t> edge(n_columns + 1);
  for (std::size_t k = 0; k <= n_columns; ++k) {
    edge[k] = t0_ns + static_cast<std::int64_t>(static_cast<long double>(span_ns) * static_cast<long double>(k) /
                                                static_cast<long double>(columns));
  }
  edge[n_columns] = t1_ns;
  std::vector<PlotColumn> out(n_columns);
  for (std::size_t k = 0; k < n_columns; ++k) {
    out[k].t0_ns = edge[k];
    out[k].t1_ns = edge[k + 1];
    out[k].min.fill(std::numeric_limits<double>::infinity());
    out[k].max.fill(-std::numeric_limits<double>::infinity());
  }
  auto column_of = [&](std::int64_t t) {
    return static_cast<std::size_t>(std::upper_bound(edge.begin(), edge.end(), t) - edge.begin() - 1);
  };
  auto merge_frames = [&](std::span<const ImuFrame> frames) {
    std::size_t k = 0;
    bool located = false;
    for (const auto& f : frames) {
      if (f.t_ns < t0_ns || f.t_ns >= t1_ns) continue;
      if (!located) {
        k = column_of(f.t_ns);
        located = true;
      }
      while (f.t_ns >= edge[k + 1]) ++k;
      PlotColumn& c = out[k];
      const std::array<double, kPlotChannels> v = {f.dtheta_rad.x(), f.dtheta_rad.y(), f.dtheta_rad.z(),
                                                   f.dv_mps.x(),     f.dv_mps.y(),     f.dv_mps.z(),
                                                   f.table_deg.x(),  f.table_deg.y(),  f.table_deg.z()};
      for (std::size_t ch = 0; ch < v.size(); ++ch) {
        c.min[ch] = v[ch] < c.min[ch] ? v[ch] : c.min[ch];
        c.max[ch] = v[ch] > c.max[ch] ? v[ch] : c.max[ch];
      }
      ++c.frames;
    }
  };

  std::vector<ImuFrame> decoded;
  {
    Statement& stmt = d.select_summaries;
    Statement::Reset reset(stmt);
    stmt.bind(1, t0_ns);
    stmt.bind(2, t1_ns - 1);
    while (stmt.step()) {
      const std::int64_t id = stmt.column_int64(0), c0 = stmt.column_int64(1), c1 = stmt.column_int64(2);
      const std::int64_t n = stmt.column_int64(3);
      const auto summary = stmt.column_blob(4);
      // A chunk inside one column needs only its summary; a chunk that an open, partial chunk row
      // is about to grow is read from the buffer below.
      if (summary.size() == kSummaryBytes && c0 >= t0_ns && c1 < t1_ns && column_of(c0) == column_of(c1)) {
        PlotColumn& c = out[column_of(c0)];
        std::array<double, 2 * kPlotChannels> s{};
        std::memcpy(s.data(), summary.data(), kSummaryBytes);
        for (std::size_t ch = 0; ch < kPlotChannels; ++ch) {
          c.min[ch] = std::min(c.min[ch], s[ch]);
          c.max[ch] = std::max(c.max[ch], s[kPlotChannels + ch]);
        }
        c.frames += n;
        continue;
      }
      Statement& data = d.select_chunk_data;
      Statement::Reset data_reset(data);
      data.bind(1, id);
      if (!data.step()) continue;
      decode_chunk(id, data.column_int64(0), static_cast<int>(data.column_int64(1)), data.column_blob(2), decoded,
                   d.path);
      merge_frames(decoded);
    }
  }
  if (d.buffer.size() > d.persisted_in_open) {
    merge_frames(std::span<const ImuFrame>(d.buffer).subspan(d.persisted_in_open));
  }
  for (auto& c : out) {
    if (c.frames == 0) {
      c.min.fill(0.0);
      c.max.fill(0.0);
    }
  }
  return out;
}

std::vector<TempSample> RunDb::temps(std::int64_t t0_ns, std::int64_t t1_ns) const {
  Impl& d = impl();
  std::vector<TempSample> temps;
  Statement& stmt = d.select_temps;
  Statement::Reset reset(stmt);
  stmt.bind(1, t0_ns);
  stmt.bind(2, t1_ns);
  while (stmt.step()) {
    TempSample sample;
    sample.t_ns = stmt.column_int64(0);
    for (int axis = 0; axis < 3; ++axis) {
      sample.gyro_C(axis) = stmt.column_double(1 + axis);
      sample.accel_C(axis) = stmt.column_double(4 + axis);
    }
    sample.chamber_C = stmt.column_double(7);
    sample.chamber_setpoint_C = stmt.column_optional_double(8);
    if (!stmt.column_is_null(9)) {
      const auto blob = stmt.column_blob(9);
      auto& coils = sample.coil_sensors_C.emplace();
      if (blob.size() != sizeof coils)
        fail(d.path, "temperature sample at " + std::to_string(sample.t_ns) + " ns: coil sensors of " +
                         std::to_string(blob.size()) + " bytes, expected " + std::to_string(sizeof coils));
      std::memcpy(coils.data(), blob.data(), sizeof coils);
    }
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

std::vector<RecorderSession> RunDb::sessions() const {
  Impl& d = impl();
  std::vector<RecorderSession> out;
  Statement& stmt = d.select_sessions;
  Statement::Reset reset(stmt);
  while (stmt.step()) {
    RecorderSession s;
    s.id = stmt.column_int64(0);
    s.opened_unix_ms = stmt.column_int64(1);
    s.closed_unix_ms = stmt.column_optional_int64(2);
    s.pid = stmt.column_int64(3);
    s.host = stmt.column_text(4);
    s.frames_at_open = stmt.column_int64(5);
    s.committed_frames = stmt.column_int64(6);
    s.committed_t_ns = stmt.column_optional_int64(7);
    s.commits = stmt.column_int64(8);
    s.queue_high_water_frames = stmt.column_int64(9);
    s.dropped_frames = stmt.column_int64(10);
    s.unclean = stmt.column_int64(11) != 0;
    s.lost_uncommitted_frames = stmt.column_optional_int64(12);
    s.integrity = stmt.column_text(13);
    out.push_back(std::move(s));
  }
  return out;
}

std::vector<DroppedSpan> RunDb::dropped_spans() const {
  Impl& d = impl();
  std::vector<DroppedSpan> out;
  Statement& stmt = d.select_dropped;
  Statement::Reset reset(stmt);
  while (stmt.step()) {
    out.push_back({stmt.column_int64(0), stmt.column_int64(1), stmt.column_int64(2), stmt.column_int64(3)});
  }
  return out;
}

const std::optional<RecoveryReport>& RunDb::recovery() const { return impl().recovery; }

int encode_chunk_payload(std::span<const ImuFrame> frames, const RecordingMeta& meta,
                         std::vector<unsigned char>& out) {
  if (frames.empty() || frames.size() > RunDb::kFramesPerChunk) {
    throw StorageError("encode_chunk_payload: a chunk holds 1 to " + std::to_string(RunDb::kFramesPerChunk) +
                       " frames");
  }
  EncodedChunk encoded;
  encoded.data = std::move(out);
  std::vector<std::int32_t> scratch;
  encode_chunk(frames, meta.gyro_lsb_rad, meta.accel_lsb_mps, encoded, scratch);
  out = std::move(encoded.data);
  return encoded.codec;
}

void decode_chunk_payload(std::span<const unsigned char> data, std::int64_t n_frames, int codec,
                          std::vector<ImuFrame>& out) {
  decode_chunk(0, n_frames, codec, data, out, "(payload)");
}

}  // namespace imucal::storage
