// Tests of storage/: the chunked frame codec (both codecs, bit for bit), the run database's
// bookkeeping (buffer, flush, schema version), and the imucal-recording/1 bundle: the real example,
// export/import round trips, rejection of malformed files with the line number, unwrapping, gaps.
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <optional>
#include <span>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/table.hpp"
#include "core/units.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

namespace imucal::storage {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const std::string kExampleDir = imucaltest::test_data_dir() + "/example-direct";

// Scratch files live in one folder per test, IMUCAL_TEST_TMP/storage/<suite>.<test>.<pid>, which
// the fixture removes when the test passed (and keeps for inspection when it failed).
fs::path scratch_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return fs::path(imucaltest::test_tmp_dir()) / "storage" /
         (std::string(info->test_suite_name()) + "." + info->name() + "." + std::to_string(::getpid()));
}

// A fresh path, unique per call, so that tests may run in parallel.
std::string temp_path(const std::string& name) {
  static std::atomic<int> counter{0};
  const fs::path dir = scratch_dir();
  fs::create_directories(dir);
  const fs::path path = dir / (std::to_string(counter++) + "." + name);
  fs::remove_all(path);
  return path.string();
}

class ScratchTest : public ::testing::Test {
 protected:
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(scratch_dir());
  }
};
class RunDbTest : public ScratchTest {};
class BundleTest : public ScratchTest {};

std::uint64_t bits(double value) { return std::bit_cast<std::uint64_t>(value); }

void expect_same_bits(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const std::string& what) {
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(bits(a(i)), bits(b(i))) << what << "(" << i << "): " << a(i) << " vs " << b(i);
  }
}

// Stops at the first differing frame so that a failure does not print a million lines.
void expect_frames_identical(const std::vector<ImuFrame>& expected, const std::vector<ImuFrame>& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const ImuFrame& e = expected[i];
    const ImuFrame& a = actual[i];
    bool same = e.t_ns == a.t_ns;
    for (int k = 0; k < 3; ++k) {
      same = same && bits(e.dtheta_rad(k)) == bits(a.dtheta_rad(k)) && bits(e.dv_mps(k)) == bits(a.dv_mps(k)) &&
             bits(e.table_deg(k)) == bits(a.table_deg(k));
    }
    if (!same) {
      ADD_FAILURE() << "frame " << i << " differs: t_ns " << e.t_ns << " vs " << a.t_ns;
      expect_same_bits(e.dtheta_rad, a.dtheta_rad, "dtheta_rad");
      expect_same_bits(e.dv_mps, a.dv_mps, "dv_mps");
      expect_same_bits(e.table_deg, a.table_deg, "table_deg");
      return;
    }
  }
}

void expect_temps_identical(const TempSample& e, const TempSample& a, const std::string& where) {
  EXPECT_EQ(e.t_ns, a.t_ns) << where;
  expect_same_bits(e.gyro_C, a.gyro_C, where + " gyro_C");
  expect_same_bits(e.accel_C, a.accel_C, where + " accel_C");
  EXPECT_EQ(bits(e.chamber_C), bits(a.chamber_C)) << where;
  ASSERT_EQ(e.chamber_setpoint_C.has_value(), a.chamber_setpoint_C.has_value()) << where;
  if (e.chamber_setpoint_C && a.chamber_setpoint_C) {
    EXPECT_EQ(bits(*e.chamber_setpoint_C), bits(*a.chamber_setpoint_C)) << where;
  }
  ASSERT_EQ(e.coil_sensors_C.has_value(), a.coil_sensors_C.has_value()) << where;
  if (e.coil_sensors_C && a.coil_sensors_C) {
    for (std::size_t c = 0; c < 3; ++c) {
      for (std::size_t k = 0; k < 8; ++k) {
        EXPECT_EQ(bits((*e.coil_sensors_C)[c][k]), bits((*a.coil_sensors_C)[c][k])) << where << " coil " << c << k;
      }
    }
  }
}

// The temperatures each frame sees: sample and hold, the first sample before it starts.
std::vector<TempSample> temps_per_frame(const std::vector<ImuFrame>& frames, const std::vector<TempSample>& temps) {
  std::vector<TempSample> out;
  std::size_t k = 0;
  for (const auto& frame : frames) {
    while (k + 1 < temps.size() && temps[k + 1].t_ns <= frame.t_ns) ++k;
    TempSample sample = temps.at(k);
    sample.t_ns = 0;  // compare the values only
    out.push_back(sample);
  }
  return out;
}

// The pieces of expect_meta_equal (one function with them all made clang-tidy's optional-access
// analysis run past 90 s of CPU).

// Both absent, or both present with the same bits.
void expect_same_optional_bits(const std::optional<double>& e, const std::optional<double>& a, const char* what) {
  ASSERT_EQ(e.has_value(), a.has_value()) << what;
  if (e && a) {
    EXPECT_EQ(bits(*e), bits(*a)) << what;
  }
}

// A table geometry as meta.json gives it back: radians inside, arc seconds in meta.json and in
// the run database, so a value comes back to within an ulp of the conversion, not bit for bit.
void expect_geometry_near(const table::TableGeometry& x, const table::TableGeometry& y) {
  const auto near = [](double u, double v) { EXPECT_NEAR(u, v, 1e-15 * std::abs(u) + 1e-300) << u << " vs " << v; };
  for (std::size_t i = 0; i < 2; ++i) {
    near(x.outer_tilt_rad[i], y.outer_tilt_rad[i]);
    near(x.middle_axis_rad[i], y.middle_axis_rad[i]);
    near(x.inner_axis_rad[i], y.inner_axis_rad[i]);
  }
  for (std::size_t axis = 0; axis < 3; ++axis) {
    ASSERT_EQ(x.encoder_error[axis].size(), y.encoder_error[axis].size());
    for (std::size_t k = 0; k < x.encoder_error[axis].size(); ++k) {
      EXPECT_EQ(x.encoder_error[axis][k].k, y.encoder_error[axis][k].k);
      near(x.encoder_error[axis][k].amplitude_rad, y.encoder_error[axis][k].amplitude_rad);
      near(x.encoder_error[axis][k].phase_rad, y.encoder_error[axis][k].phase_rad);
    }
  }
}

void expect_optional_geometry_near(const std::optional<table::TableGeometry>& e,
                                   const std::optional<table::TableGeometry>& a) {
  ASSERT_EQ(e.has_value(), a.has_value());
  if (e && a) expect_geometry_near(*e, *a);
}

// The table's certificate: its text, its geometry and that geometry's sigma.
void expect_table_near(const std::optional<table::TableCertificate>& e, const std::optional<table::TableCertificate>& a) {
  ASSERT_EQ(e.has_value(), a.has_value());
  if (!e || !a) return;
  EXPECT_EQ(e->certificate, a->certificate);
  expect_optional_geometry_near(e->geometry, a->geometry);
  expect_optional_geometry_near(e->sigma, a->sigma);
}

void expect_meta_equal(const RecordingMeta& e, const RecordingMeta& a) {
  EXPECT_EQ(bits(e.site.latitude_deg), bits(a.site.latitude_deg));
  EXPECT_EQ(bits(e.site.longitude_deg), bits(a.site.longitude_deg));
  EXPECT_EQ(bits(e.site.height_m), bits(a.site.height_m));
  EXPECT_EQ(bits(e.site.middle_axis_azimuth_deg), bits(a.site.middle_axis_azimuth_deg));
  expect_same_optional_bits(e.site.gravity_mps2, a.site.gravity_mps2, "site.gravity_mps2");
  EXPECT_EQ(e.imu_serial, a.imu_serial);
  EXPECT_EQ(bits(e.rate_hz), bits(a.rate_hz));
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(bits(e.mount.C_o_p(r, c)), bits(a.mount.C_o_p(r, c)));
  }
  expect_same_bits(e.mount.r0_p_m, a.mount.r0_p_m, "r0_p_m");
  ASSERT_EQ(e.segments.size(), a.segments.size());
  for (std::size_t i = 0; i < e.segments.size(); ++i) {
    EXPECT_EQ(e.segments[i].name, a.segments[i].name);
    EXPECT_EQ(e.segments[i].kind, a.segments[i].kind);
    EXPECT_EQ(bits(e.segments[i].t0_s), bits(a.segments[i].t0_s));
    EXPECT_EQ(bits(e.segments[i].t1_s), bits(a.segments[i].t1_s));
  }
  expect_same_optional_bits(e.gyro_lsb_rad, a.gyro_lsb_rad, "gyro_lsb_rad");
  expect_same_optional_bits(e.accel_lsb_mps, a.accel_lsb_mps, "accel_lsb_mps");
  EXPECT_EQ(e.program_json, a.program_json);
  EXPECT_EQ(e.truth_json, a.truth_json);
  expect_table_near(e.table, a.table);
}

constexpr double kGyroLsbRad = 1e-11;
constexpr double kAccelLsbMps = 1e-10;

RecordingMeta simulated_meta() {
  RecordingMeta meta;
  meta.imu_serial = "SIM-7";
  meta.rate_hz = 1000.0;
  meta.gyro_lsb_rad = kGyroLsbRad;
  meta.accel_lsb_mps = kAccelLsbMps;
  meta.site.gravity_mps2 = 9.8192;
  meta.site.middle_axis_azimuth_deg = 20.0;
  meta.mount.C_o_p << 0, 1, 0, -1, 0, 0, 0, 0, 1;
  // 0.04141247279349658 m has no millimetre double that divides back to it exactly.
  meta.mount.r0_p_m = {0.0125, -1.0 / 3.0, 0.04141247279349658};
  meta.segments = {{"pos-01", "static", 0.0, 2.5}, {"rate-x+", "rate", 3.0, 9.75}};
  meta.program_json = R"({"segments": [ {"kind": "hold", "duration_s": 2.5} ]})";
  meta.truth_json = "{\n \"format\": \"imucal-imu-model/1\"\n}\n";
  // An imperfect table's certificate (formats.md `table`), values and 1-sigma.
  table::TableGeometry g, sigma;
  g.outer_tilt_rad = {2.0 * units::kArcsecToRad, -1.0 / 3.0 * units::kArcsecToRad};
  g.middle_axis_rad = {3.0 * units::kArcsecToRad, 0.0};
  g.inner_axis_rad = {0.0, -2.5 * units::kArcsecToRad};
  g.encoder_error[0] = {{1, 1.0 * units::kArcsecToRad, 0.3}, {2, 0.5 * units::kArcsecToRad, 1.7}};
  g.encoder_error[2] = {{4, 0.25 * units::kArcsecToRad, -0.4}};
  sigma.outer_tilt_rad = {0.2 * units::kArcsecToRad, 0.2 * units::kArcsecToRad};
  sigma.encoder_error[0] = {{1, 0.1 * units::kArcsecToRad, 0.0}};
  meta.table = table::TableCertificate{g, sigma, "TBL-7, 2026-03-01"};
  return meta;
}

// Frames as the simulator makes them: integer counts times the LSB, 1 kHz with jitter, one gap
// longer than an int32 of nanoseconds (2.1 s) and one short gap.
std::vector<ImuFrame> simulated_frames(std::size_t n, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::int32_t> gyro_counts(-2'000'000, 2'000'000);
  std::uniform_int_distribution<std::int32_t> accel_counts(-2'000'000'000, 2'000'000'000);
  std::uniform_int_distribution<std::int64_t> jitter_ns(-300, 300);
  std::uniform_real_distribution<double> start_deg(-720.0, 720.0);
  std::uniform_real_distribution<double> step_deg(-5.0, 5.0);  // the table moves < 180 deg per sample
  std::vector<ImuFrame> frames(n);
  Eigen::Vector3d table_deg(start_deg(rng), start_deg(rng), start_deg(rng));
  std::int64_t t_ns = 1'000'000;
  for (std::size_t i = 0; i < n; ++i) {
    if (i == n / 2) t_ns += 3'000'000'000;  // gap > 2^31 ns: forces 64-bit times in that chunk
    if (i == 3 * n / 4) t_ns += 20'000'000;
    t_ns += 1'000'000 + jitter_ns(rng);
    frames[i].t_ns = t_ns;
    for (int k = 0; k < 3; ++k) {
      frames[i].dtheta_rad(k) = static_cast<double>(gyro_counts(rng)) * kGyroLsbRad;
      frames[i].dv_mps(k) = static_cast<double>(accel_counts(rng)) * kAccelLsbMps;
      table_deg(k) += step_deg(rng);
      frames[i].table_deg(k) = table_deg(k);
    }
  }
  return frames;
}

// Appends in uneven batches, as a recorder does.
void append_unevenly(RunDb& run, const std::vector<ImuFrame>& frames) {
  const std::span<const ImuFrame> all(frames);
  std::size_t done = 0;
  for (std::size_t batch : {std::size_t{1}, std::size_t{7}, std::size_t{3000}, std::size_t{5000}}) {
    batch = std::min(batch, frames.size() - done);
    run.append(all.subspan(done, batch));
    done += batch;
  }
  run.append(all.subspan(done));
}

template <class Fn>
std::string error_message(Fn&& fn) {
  try {
    fn();
  } catch (const StorageError& e) {
    return e.what();
  }
  return "(no StorageError thrown)";
}

// ---------------------------------------------------------------------------------------------
// RunDb

TEST_F(RunDbTest, Codec1RoundTripIsBitExactAndCompact) {
  const std::string path = temp_path("run.db");
  auto frames = simulated_frames(200'000, 1);
  frames[10].table_deg.z() = -0.0;  // the angles are doubles in both codecs, sign of zero included
  {
    RunDb run = RunDb::create(path, simulated_meta());
    append_unevenly(run, frames);
    run.flush();
    expect_frames_identical(frames, run.read_frames());

    const FrameStorageStats stats = run.frame_storage_stats();
    EXPECT_EQ(stats.frames, 200'000);
    EXPECT_EQ(stats.chunks, (200'000 + 4095) / 4096);
    EXPECT_EQ(stats.codec1_chunks, stats.chunks);
    EXPECT_EQ(stats.codec2_chunks, 0);
    const double blob_bytes_per_frame = static_cast<double>(stats.blob_bytes) / 200'000.0;
    EXPECT_LE(blob_bytes_per_frame, 52.5);
    RecordProperty("codec1_blob_bytes_per_frame", std::to_string(blob_bytes_per_frame));
  }
  // Closed: the WAL is checkpointed into the file, whose size is what a run costs on disk.
  const double file_bytes_per_frame = static_cast<double>(fs::file_size(path)) / 200'000.0;
  RecordProperty("codec1_file_bytes_per_frame", std::to_string(file_bytes_per_frame));
  std::printf("codec 1: %.2f bytes per frame in the file\n", file_bytes_per_frame);
  EXPECT_LE(file_bytes_per_frame, 64.0);

  const RunDb reopened = RunDb::open(path);
  EXPECT_EQ(reopened.frame_count(), 200'000);
  expect_frames_identical(frames, reopened.read_frames());
}

// The full disk on demand (storage::disk_fault): every write of every connection fails as a
// full file system fails it, reads go on, and writes work again once it is switched off; a batch
// that failed for it is rolled back to the last commit and can be written again through the same
// handle (what the recorder does when space returns).
TEST_F(RunDbTest, TheDiskFullSwitchFailsWritesOnlyAndABatchCanBeWrittenAgainAfterIt) {
  struct Restore {
    ~Restore() { disk_fault::set_full(false); }
  } restore;
  const std::string path = temp_path("run.db");
  const auto frames = simulated_frames(30'000, 3);
  const std::span<const ImuFrame> all(frames);
  RunDb run = RunDb::create(path, simulated_meta());
  run.begin_batch();
  run.append(all.first(10'000));
  run.commit_batch();

  disk_fault::set_full(true);
  EXPECT_TRUE(disk_fault::full());
  run.begin_batch();
  run.append(all.subspan(10'000, 10'000));  // chunks go to SQLite's cache; the WAL write fails
  try {
    run.commit_batch();
    ADD_FAILURE() << "a commit on a full disk succeeded";
  } catch (const sql::SqliteError& e) {
    EXPECT_EQ(e.kind(), sql::SqliteError::Kind::full);
    EXPECT_THAT(e.what(), HasSubstr("disk is full"));
  }
  // Rolled back to the last commit, for this handle and for a reader alike.
  EXPECT_EQ(run.frame_count(), 10'000);
  EXPECT_EQ(run.last_frame_t_ns(), frames[9'999].t_ns);
  EXPECT_EQ(RunDb::open(path, OpenMode::Read).frame_count(), 10'000);

  disk_fault::set_full(false);
  run.begin_batch();
  run.append(all.subspan(10'000, 10'000));  // the same frames again
  run.commit_batch();
  // A budget: the disk fills after that many bytes, in the middle of the next batch.
  disk_fault::fill_after_bytes(100'000);
  run.begin_batch();
  run.append(all.subspan(20'000));
  EXPECT_THROW(run.commit_batch(), sql::SqliteError);
  EXPECT_TRUE(disk_fault::full());
  disk_fault::set_full(false);
  run.begin_batch();
  run.append(all.subspan(20'000));
  run.commit_batch();
  run.close();
  expect_frames_identical(frames, RunDb::open(path, OpenMode::Read).read_frames());
}

TEST_F(RunDbTest, Codec2RoundTripIsBitExactForAnyDouble) {
  const std::string path = temp_path("run.db");
  RecordingMeta meta = simulated_meta();
  meta.gyro_lsb_rad.reset();
  meta.accel_lsb_mps.reset();
  auto frames = simulated_frames(10'000, 2);
  std::mt19937_64 rng(3);
  for (auto& frame : frames) {
    for (int k = 0; k < 3; ++k) {
      // Arbitrary finite bit patterns: subnormals, huge values, every mantissa bit.
      auto random_double = [&] {
        double value = 0.0;
        do {
          value = std::bit_cast<double>(rng());
        } while (!std::isfinite(value));
        return value;
      };
      frame.dtheta_rad(k) = random_double();
      frame.dv_mps(k) = random_double();
    }
  }
  frames[5].dv_mps.y() = -0.0;
  frames[6].dtheta_rad.x() = 4.9406564584124654e-324;

  RunDb run = RunDb::create(path, meta);
  append_unevenly(run, frames);
  run.flush();
  const FrameStorageStats stats = run.frame_storage_stats();
  EXPECT_EQ(stats.codec1_chunks, 0);
  EXPECT_EQ(stats.codec2_chunks, stats.chunks);
  expect_frames_identical(frames, run.read_frames());
  expect_frames_identical(frames, RunDb::open(path).read_frames());
}

TEST_F(RunDbTest, Codec1FallsBackToDoublesPerChunk) {
  const std::string path = temp_path("run.db");
  auto frames = simulated_frames(4 * 4096 + 100, 4);
  // Chunk 1: one value that is not a whole number of LSBs (1 ulp off).
  frames[4096 + 17].dv_mps.x() = std::nextafter(frames[4096 + 17].dv_mps.x(), 1.0);
  // Chunk 2: a count that does not fit 31 bits.
  frames[2 * 4096 + 5].dtheta_rad.z() = 3e9 * kGyroLsbRad;
  // Chunks 0 and 3 stay codec 1, negative zeros (nearbyint(-0.3) * lsb) and +-(2^31 - 1) included.
  frames[3].dtheta_rad.y() = -0.0;
  frames[3 * 4096 + 1].dv_mps.z() = -0.0;
  frames[3 * 4096 + 2].dv_mps.z() = 0.0;
  frames[3 * 4096 + 3].dtheta_rad.x() = 2147483647.0 * kGyroLsbRad;
  frames[3 * 4096 + 4].dtheta_rad.x() = -2147483647.0 * kGyroLsbRad;

  RunDb run = RunDb::create(path, simulated_meta());
  run.append(frames);
  run.flush();
  const FrameStorageStats stats = run.frame_storage_stats();
  EXPECT_EQ(stats.chunks, 5);
  EXPECT_EQ(stats.codec2_chunks, 2);
  EXPECT_EQ(stats.codec1_chunks, 3);
  expect_frames_identical(frames, run.read_frames());
}

TEST_F(RunDbTest, RangeReadsAreInclusiveAndCrossChunksAndGaps) {
  const std::string path = temp_path("run.db");
  const auto frames = simulated_frames(10'000, 5);
  RunDb run = RunDb::create(path, simulated_meta());
  run.append(frames);  // 2 chunks written, 1808 frames still buffered: both must be read

  auto slice = [&](std::size_t first, std::size_t last) {
    return std::vector<ImuFrame>(frames.begin() + static_cast<std::ptrdiff_t>(first),
                                 frames.begin() + static_cast<std::ptrdiff_t>(last) + 1);
  };
  expect_frames_identical(slice(100, 200), run.read_frames(frames[100].t_ns, frames[200].t_ns));
  expect_frames_identical(slice(4000, 9000), run.read_frames(frames[4000].t_ns, frames[9000].t_ns));
  expect_frames_identical(slice(4096, 4096), run.read_frames(frames[4096].t_ns, frames[4096].t_ns));
  // Between two samples: from the next one; inside the 3 s gap: nothing.
  expect_frames_identical(slice(101, 200), run.read_frames(frames[100].t_ns + 1, frames[200].t_ns));
  EXPECT_TRUE(run.read_frames(frames[4999].t_ns + 1, frames[5000].t_ns - 1).empty());
  EXPECT_TRUE(run.read_frames(frames[200].t_ns, frames[100].t_ns).empty());

  std::int64_t count = 0;
  std::int64_t previous = std::numeric_limits<std::int64_t>::min();
  run.for_each_frame([&](const ImuFrame& f) {
    EXPECT_GT(f.t_ns, previous);
    previous = f.t_ns;
    ++count;
  });
  EXPECT_EQ(count, 10'000);

  // A callback may read the run again (its own query runs beside the outer one).
  count = 0;
  run.for_each_frame(
      [&](const ImuFrame& f) {
        const auto again = run.read_frames(f.t_ns, f.t_ns);
        ASSERT_EQ(again.size(), 1U);
        EXPECT_EQ(again[0].t_ns, f.t_ns);
        ++count;
      },
      frames[4090].t_ns, frames[4100].t_ns);
  EXPECT_EQ(count, 11);
}

TEST_F(RunDbTest, FlushKeepsFillingTheOpenChunkAndDestructorFlushes) {
  const std::string path = temp_path("run.db");
  const auto frames = simulated_frames(4200, 6);
  const std::span<const ImuFrame> all(frames);
  {
    RunDb run = RunDb::create(path, simulated_meta());
    run.append(all.subspan(0, 100));
    EXPECT_EQ(run.frame_count(), 100);  // buffered frames count and read
    EXPECT_EQ(run.read_frames().size(), 100U);
    EXPECT_EQ(run.frame_storage_stats().chunks, 0);
    run.flush();
    EXPECT_EQ(run.frame_storage_stats().chunks, 1);
    run.append(all.subspan(100, 100));
    run.flush();
    EXPECT_EQ(run.frame_storage_stats().chunks, 1);  // the same row, now with 200 frames
    EXPECT_EQ(run.frame_storage_stats().frames, 200);
    EXPECT_EQ(run.frame_count(), 200);
    run.append(all.subspan(200));
    EXPECT_EQ(run.frame_storage_stats().chunks, 1);
    EXPECT_EQ(run.frame_storage_stats().frames, 4096);
    EXPECT_EQ(run.frame_count(), 4200);
    expect_frames_identical(frames, run.read_frames());
  }  // no flush(): the destructor writes the last 104 frames
  const RunDb reopened = RunDb::open(path);
  EXPECT_EQ(reopened.frame_count(), 4200);
  expect_frames_identical(frames, reopened.read_frames());
}

TEST_F(RunDbTest, RejectsTimeThatDoesNotIncrease) {
  RunDb run = RunDb::create(temp_path("run.db"), simulated_meta());
  std::vector<ImuFrame> frames(3);
  frames[0].t_ns = 10;
  frames[1].t_ns = 20;
  frames[2].t_ns = 20;
  EXPECT_THAT(error_message([&] { run.append(frames); }), HasSubstr("does not increase"));
  EXPECT_EQ(run.frame_count(), 0);  // a rejected batch changes nothing
  run.append(std::span(frames).first(2));
  EXPECT_THAT(error_message([&] { run.append(std::span(frames).subspan(2)); }), HasSubstr("does not increase"));
  EXPECT_EQ(run.frame_count(), 2);

  std::vector<TempSample> temps(2);
  temps[0].t_ns = 5;
  temps[1].t_ns = 5;
  EXPECT_THAT(error_message([&] { run.append_temps(temps); }), HasSubstr("does not increase"));
  EXPECT_TRUE(run.temps().empty());
}

TEST_F(RunDbTest, TempsSegmentsExtrasAndMetaPersist) {
  const std::string path = temp_path("run.db");
  const RecordingMeta meta = simulated_meta();
  std::vector<TempSample> temps(3);
  temps[0].t_ns = 0;
  temps[1].t_ns = 1'000'000'000;
  temps[1].gyro_C.y() = -0.0;  // a REAL column would turn this into +0.0
  temps[1].chamber_setpoint_C = 40.0;
  temps[2].t_ns = 2'000'000'000;
  temps[2].accel_C.z() = 25.123456789012345;
  temps[2].chamber_C = -40.0;
  auto& coils = temps[2].coil_sensors_C.emplace();  // the eight sensors of each coil
  for (std::size_t c = 0; c < 3; ++c)
    for (std::size_t k = 0; k < 8; ++k) coils[c][k] = 20.0 + static_cast<double>(c) + 0.1 * static_cast<double>(k);
  coils[1][7] = -0.0;
  const std::vector<SegmentInfo> segments = {{"a", "static", 0.0, 1.0}, {"b", "sine", 1.5, 2.0}};
  {
    RunDb run = RunDb::create(path, meta);
    run.append_temps(temps);
    run.set_segments(segments);
    run.set_extra("stage1", R"({"bias_dph": [1, 2, 3]})");
    run.set_extra("stage1", R"({"bias_dph": [4, 5, 6]})");  // replaced
    EXPECT_THAT(error_message([&] { run.set_extra("bad", "{not json"); }), HasSubstr("not valid JSON"));
  }
  const RunDb run = RunDb::open(path);
  const auto stored = run.temps();
  ASSERT_EQ(stored.size(), temps.size());
  for (std::size_t i = 0; i < temps.size(); ++i) expect_temps_identical(temps[i], stored[i], "temp " + std::to_string(i));
  RecordingMeta expected = meta;
  expected.segments = segments;
  expect_meta_equal(expected, run.meta());
  EXPECT_EQ(run.extra("stage1"), std::optional<std::string>(R"({"bias_dph": [4, 5, 6]})"));
  EXPECT_FALSE(run.extra("bad").has_value());
  EXPECT_FALSE(run.extra("missing").has_value());
}

TEST_F(RunDbTest, CreateAndOpenReportTheFileAndTheReason) {
  const std::string path = temp_path("run.db");
  { RunDb run = RunDb::create(path, simulated_meta()); }
  const std::string exists = error_message([&] { RunDb::create(path, simulated_meta()); });
  EXPECT_THAT(exists, HasSubstr(path));
  EXPECT_THAT(exists, HasSubstr("already exists"));

  const std::string missing_path = temp_path("missing.db");
  const std::string missing = error_message([&] { RunDb::open(missing_path); });
  EXPECT_THAT(missing, HasSubstr(missing_path));
  EXPECT_THAT(missing, HasSubstr("no such file"));

  const std::string text_path = temp_path("not-a-db.db");
  std::ofstream(text_path) << "t_s,dth_x_rad\n0.1,0.2\n";
  const std::string not_db = error_message([&] { RunDb::open(text_path); });
  EXPECT_THAT(not_db, HasSubstr(text_path));
  EXPECT_THAT(not_db, HasSubstr("not a database"));

  RecordingMeta bad = simulated_meta();
  bad.rate_hz = 0.0;
  EXPECT_THAT(error_message([&] { RunDb::create(temp_path("bad.db"), bad); }), HasSubstr("rate_hz"));
}

TEST_F(RunDbTest, MigratesAVersion2FileToTheCoilSensors) {
  // What imucal wrote before version 3: no coil_sensors_C column.
  const std::string path = temp_path("v2.db");
  TempSample old;
  old.gyro_C.x() = 21.5;
  {
    RunDb run = RunDb::create(path, simulated_meta());
    run.append_temps(std::vector<TempSample>{old});
  }
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(raw, "ALTER TABLE temp_sample DROP COLUMN coil_sensors_C; PRAGMA user_version = 2;", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(raw);
  TempSample later;
  later.t_ns = 1'000'000'000;
  later.coil_sensors_C.emplace()[2][3] = 30.25;
  {
    RunDb run = RunDb::open(path);
    run.append_temps(std::vector<TempSample>{later});
  }
  const auto temps = RunDb::open(path).temps();
  ASSERT_EQ(temps.size(), 2U);
  expect_temps_identical(old, temps[0], "sample from version 2");
  expect_temps_identical(later, temps[1], "sample after the migration");
}

TEST_F(RunDbTest, NewerSchemaVersionIsRejected) {
  const std::string path = temp_path("run.db");
  { RunDb run = RunDb::create(path, simulated_meta()); }
  EXPECT_NO_THROW(RunDb::open(path));
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const std::string newer = std::to_string(RunDb::kSchemaVersion + 1);
  ASSERT_EQ(sqlite3_exec(db, ("PRAGMA user_version = " + newer).c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);

  const std::string message = error_message([&] { RunDb::open(path); });
  EXPECT_THAT(message, HasSubstr(path));
  EXPECT_THAT(message, HasSubstr("schema version " + newer + " is newer"));
}

// ---------------------------------------------------------------------------------------------
// Bundle import/export

TEST_F(BundleTest, ImportsTheExampleRecording) {
  const std::string db_path = temp_path("example.db");
  const ImportReport report = import_bundle(kExampleDir, db_path);
  EXPECT_EQ(report.frames, 46680);
  EXPECT_TRUE(report.gaps.empty());
  EXPECT_TRUE(report.ignored_columns.empty());
  EXPECT_EQ(report.temp_samples, 1);  // 25.000 throughout

  const RunDb run = RunDb::open(db_path);
  EXPECT_EQ(run.frame_count(), 46680);
  const RecordingMeta meta = run.meta();
  EXPECT_EQ(meta.rate_hz, 20.0);
  EXPECT_EQ(meta.imu_serial, "HELDOUT-101");
  EXPECT_EQ(meta.site.middle_axis_azimuth_deg, 20.0);
  EXPECT_EQ(meta.site.latitude_deg, 59.94);
  ASSERT_TRUE(meta.site.gravity_mps2.has_value());
  EXPECT_EQ(*meta.site.gravity_mps2, 9.81925);
  EXPECT_TRUE(meta.mount.C_o_p.isIdentity(0.0));
  EXPECT_FALSE(meta.gyro_lsb_rad.has_value());  // imported CSV: doubles
  ASSERT_EQ(meta.segments.size(), 40U);
  EXPECT_EQ(meta.segments.front().name, "start");
  EXPECT_EQ(meta.segments[26].kind, "rate");
  EXPECT_EQ(meta.segments[26].name, "rate-z+");
  EXPECT_EQ(meta.segments.back().t1_s, 2334.0);
  EXPECT_THAT(meta.truth_json, HasSubstr("imucal-imu-model/1"));  // truth.json beside it
  EXPECT_EQ(run.frame_storage_stats().codec1_chunks, 0);
  EXPECT_TRUE(stored_gaps(run).empty());
  EXPECT_TRUE(run.extra(kGapsExtraKey).has_value());

  const auto frames = run.read_frames();
  ASSERT_EQ(frames.size(), 46680U);
  // Line 2: 0.050000,1.6724810046738551e-06,...,0.49096109696765955,0,0,0,25.000,...
  EXPECT_EQ(frames[0].t_ns, 50'000'000);
  EXPECT_EQ(bits(frames[0].dtheta_rad.x()), bits(1.6724810046738551e-06));
  EXPECT_EQ(bits(frames[0].dv_mps.z()), bits(0.49096109696765955));
  EXPECT_EQ(frames.back().t_ns, 2'334'000'000'000);
  // Every frame 50 ms apart on the exact decimal times ("1139.950000" -> 1139950000000 ns).
  for (std::size_t i = 1; i < frames.size(); ++i) ASSERT_EQ(frames[i].t_ns - frames[i - 1].t_ns, 50'000'000) << i;
  // Line 3362 wraps the outer axis from 180 to -179.99..; unwrapped it continues above 180.
  EXPECT_EQ(frames[3359].table_deg.x(), 180.0);
  EXPECT_EQ(frames[3360].table_deg.x(), -179.99132582169293 + 360.0);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    ASSERT_LT((frames[i].table_deg - frames[i - 1].table_deg).cwiseAbs().maxCoeff(), 180.0) << i;
  }
  const auto temps = run.temps();
  ASSERT_EQ(temps.size(), 1U);
  EXPECT_EQ(temps[0].chamber_C, 25.0);
  EXPECT_FALSE(temps[0].chamber_setpoint_C.has_value());
}

TEST_F(BundleTest, ExampleSurvivesExportAndReimportBitForBit) {
  const std::string db1 = temp_path("first.db");
  const std::string dir1 = temp_path("bundle1");
  const std::string db2 = temp_path("second.db");
  const std::string dir2 = temp_path("bundle2");
  import_bundle(kExampleDir, db1);
  const RunDb first = RunDb::open(db1);
  export_bundle(first, dir1);
  import_bundle(dir1, db2);
  const RunDb second = RunDb::open(db2);

  expect_meta_equal(first.meta(), second.meta());
  const auto frames = first.read_frames();
  expect_frames_identical(frames, second.read_frames());
  const auto t1 = temps_per_frame(frames, first.temps());
  const auto t2 = temps_per_frame(frames, second.temps());
  for (std::size_t i = 0; i < frames.size(); i += 997) expect_temps_identical(t1[i], t2[i], "frame " + std::to_string(i));

  // The text is a fixed point: exporting the re-import gives the same bytes.
  export_bundle(second, dir2);
  auto slurp = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  };
  const std::string csv = slurp(dir1 + "/frames.csv");
  EXPECT_EQ(csv, slurp(dir2 + "/frames.csv"));
  EXPECT_EQ(slurp(dir1 + "/meta.json"), slurp(dir2 + "/meta.json"));
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            "t_s,dth_x_rad,dth_y_rad,dth_z_rad,dv_x_mps,dv_y_mps,dv_z_mps,outer_deg,middle_deg,inner_deg,"
            "temp_gx_C,temp_gy_C,temp_gz_C,temp_ax_C,temp_ay_C,temp_az_C,temp_chamber_C");
  const auto meta_json = nlohmann::json::parse(slurp(dir1 + "/meta.json"));
  EXPECT_EQ(meta_json.at("format"), "imucal-recording/1");
  EXPECT_EQ(meta_json.at("site").at("gravity_mps2"), 9.81925);
  EXPECT_EQ(meta_json.at("segments").size(), 40U);
}

TEST_F(BundleTest, SimulatedRunSurvivesExportAndImportExactly) {
  const std::string db1 = temp_path("sim.db");
  const std::string dir = temp_path("bundle");
  const std::string db2 = temp_path("reimported.db");
  RecordingMeta meta = simulated_meta();
  meta.site.gravity_mps2.reset();  // optional in the file
  const auto frames = simulated_frames(9000, 7);
  // Temperatures at 10 Hz, starting after the first frame, set point only part of the time.
  std::vector<TempSample> temps;
  for (std::int64_t t_ns = 50'000'000; t_ns < frames.back().t_ns; t_ns += 100'000'000) {
    TempSample sample;
    sample.t_ns = t_ns;
    const double x = static_cast<double>(t_ns) * 1e-9;
    sample.gyro_C = {25.0 + 0.1 * x, 25.0 + std::sin(x), 1.0 / 3.0};
    sample.accel_C = {24.0, -0.0, 26.0 + x * x};
    sample.chamber_C = 30.0 - x / 7.0;
    if (t_ns > 4'000'000'000) sample.chamber_setpoint_C = 30.0;
    temps.push_back(sample);
  }
  {
    RunDb run = RunDb::create(db1, meta);
    run.append(frames);
    run.append_temps(temps);
    run.flush();
    export_bundle(run, dir);
  }
  const ImportReport report = import_bundle(dir, db2);
  EXPECT_EQ(report.frames, 9000);
  const auto meta_json = nlohmann::json::parse(std::ifstream(dir + "/meta.json"));
  EXPECT_FALSE(meta_json.at("site").contains("gravity_mps2"));
  EXPECT_EQ(meta_json.at("mount").at("r0_p_mm").at(0), 12.5);
  EXPECT_TRUE(meta_json.at("mount").contains("r0_p_m"));  // for the awkward third component
  // The table's certificate as formats.md writes it: arc seconds, harmonics [k, a, phi_deg].
  EXPECT_NEAR(meta_json.at("table").at("geometry").at("outer_tilt_arcsec").at(0).get<double>(), 2.0, 1e-12);
  EXPECT_NEAR(meta_json.at("table").at("geometry").at("encoder_error_arcsec").at("outer").at(1).at(2).get<double>(),
              1.7 * units::kRadToDeg, 1e-12);
  EXPECT_NEAR(meta_json.at("table").at("sigma").at("outer_tilt_arcsec").at(1).get<double>(), 0.2, 1e-12);
  EXPECT_EQ(meta_json.at("table").at("certificate"), "TBL-7, 2026-03-01");
  ASSERT_EQ(report.gaps.size(), 2U);  // the two gaps simulated_frames makes
  EXPECT_EQ(report.gaps[0].line, 4500 + 2);
  EXPECT_EQ(report.gaps[0].t1_ns, frames[4500].t_ns);

  // Any reader that takes llround(t_s * 1e9) gets the nanoseconds back.
  {
    std::ifstream csv(dir + "/frames.csv");
    std::string line;
    std::getline(csv, line);
    for (const auto& frame : frames) {
      ASSERT_TRUE(std::getline(csv, line));
      ASSERT_EQ(std::llround(std::stod(line.substr(0, line.find(','))) * 1e9), frame.t_ns) << line;
    }
  }

  const RunDb run = RunDb::open(db2);
  expect_meta_equal(meta, run.meta());
  expect_frames_identical(frames, run.read_frames());
  EXPECT_EQ(run.frame_storage_stats().codec2_chunks, 0);  // the LSBs came along
  const auto expected_temps = temps_per_frame(frames, temps);
  const auto actual_temps = temps_per_frame(frames, run.temps());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    expect_temps_identical(expected_temps[i], actual_temps[i], "frame " + std::to_string(i));
    if (::testing::Test::HasFailure()) break;
  }
}

// A bundle folder written from text, for the malformed-input cases.
std::string write_bundle(const std::string& name, const std::string& csv, double rate_hz = 10.0,
                         const std::string& format = "imucal-recording/1") {
  const std::string dir = temp_path(name);
  fs::create_directories(dir);
  nlohmann::json meta = {
      {"format", format},
      {"site", {{"latitude_deg", 59.94}, {"longitude_deg", 30.31}, {"height_m", 10.0}, {"middle_axis_azimuth_deg", 0.0}}},
      {"imu", {{"serial", "X"}, {"rate_hz", rate_hz}}},
      {"mount", {{"C_o_p", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}, {"r0_p_mm", {0.0, 0.0, 0.0}}}}};
  std::ofstream(dir + "/meta.json") << meta.dump(1);
  std::ofstream(dir + "/frames.csv", std::ios::binary) << csv;
  return dir;
}

const std::string kHeader =
    "t_s,dth_x_rad,dth_y_rad,dth_z_rad,dv_x_mps,dv_y_mps,dv_z_mps,outer_deg,middle_deg,inner_deg,"
    "temp_gx_C,temp_gy_C,temp_gz_C,temp_ax_C,temp_ay_C,temp_az_C,temp_chamber_C";

std::string csv_line(const std::string& t_s, const std::string& angles = "0,0,0") {
  return t_s + ",1e-6,2e-6,3e-6,0.1,0.2,0.3," + angles + ",25,25,25,25,25,25,25\n";
}

// The import fails with a message containing every one of `parts`, and leaves no file behind.
void expect_rejected(const std::string& dir, const std::vector<std::string>& parts) {
  const std::string db_path = temp_path("rejected.db");
  const std::string message = error_message([&] { import_bundle(dir, db_path); });
  for (const auto& part : parts) EXPECT_THAT(message, HasSubstr(part));
  EXPECT_FALSE(fs::exists(db_path));
  EXPECT_FALSE(fs::exists(db_path + ".importing"));
  EXPECT_FALSE(fs::exists(db_path + ".importing-wal"));
}

TEST_F(BundleTest, RejectsMalformedFramesWithTheLineNumber) {
  const std::string good = kHeader + "\n" + csv_line("0.1") + csv_line("0.2") + csv_line("0.3") + csv_line("0.4");
  EXPECT_EQ(import_bundle(write_bundle("good", good), temp_path("good.db")).frames, 4);

  std::string missing_column = kHeader;
  missing_column.replace(missing_column.find("dv_y_mps,"), 9, "");
  expect_rejected(write_bundle("missing", missing_column + "\n" + csv_line("0.1")),
                  {"frames.csv line 1:", "missing column 'dv_y_mps'"});

  std::string swapped = kHeader;
  swapped.replace(swapped.find("dv_x_mps,dv_y_mps"), 17, "dv_y_mps,dv_x_mps");
  expect_rejected(write_bundle("swapped", swapped + "\n" + csv_line("0.1")),
                  {"frames.csv line 1:", "'dv_x_mps' is column 6, expected as column 5"});

  expect_rejected(write_bundle("nonnumber", kHeader + "\n" + csv_line("0.1") + csv_line("0.2") +
                                                "0.3,1e-6,2e-6,3e-6,1.2.3,0.2,0.3,0,0,0,25,25,25,25,25,25,25\n"),
                  {"frames.csv line 4:", "column 'dv_x_mps'", "'1.2.3' is not a number"});
  expect_rejected(write_bundle("word", kHeader + "\n" + csv_line("0.1") +
                                           "0.2,1e-6,2e-6,3e-6,0.1,0.2,0.3,0,0,0,25,25,25,25,25,abc,25\n"),
                  {"frames.csv line 3:", "column 'temp_az_C'", "'abc' is not a number"});
  expect_rejected(write_bundle("nan", kHeader + "\n" + csv_line("0.1") + csv_line("0.2", "nan,0,0")),
                  {"frames.csv line 3:", "column 'outer_deg'", "not a finite number"});
  expect_rejected(write_bundle("empty", kHeader + "\n" + csv_line("0.1", "0,,0")),
                  {"frames.csv line 2:", "column 'middle_deg'", "empty field"});
  expect_rejected(write_bundle("badtime", kHeader + "\n" + csv_line("0.1") + csv_line("t=0.2")),
                  {"frames.csv line 3:", "column 't_s'", "not a number"});

  expect_rejected(write_bundle("backwards", kHeader + "\n" + csv_line("0.1") + csv_line("0.2") + csv_line("0.3") +
                                                csv_line("0.25")),
                  {"frames.csv line 5:", "time does not increase"});
  expect_rejected(write_bundle("equal", kHeader + "\n" + csv_line("0.1") + csv_line("0.1")),
                  {"frames.csv line 3:", "time does not increase"});

  std::string truncated = good + csv_line("0.5");
  truncated.resize(truncated.size() - 20);  // cut inside the last line, no newline at the end
  expect_rejected(write_bundle("truncated", truncated), {"frames.csv line 6:", "too few fields"});
  expect_rejected(write_bundle("toomany", kHeader + "\n" + csv_line("0.1") + "0.2,1,2,3,4,5,6,7,8,9,0,1,2,3,4,5,6,7\n"),
                  {"frames.csv line 3:", "too many fields"});

  expect_rejected(write_bundle("noheader", ""), {"frames.csv line 1:"});
  expect_rejected(write_bundle("format", good, 10.0, "imucal-recording/2"),
                  {"meta.json", "unknown format 'imucal-recording/2'"});
  expect_rejected(temp_path("no-such-bundle"), {"meta.json"});
}

TEST_F(BundleTest, RejectsMetaWithoutARequiredKey) {
  const std::string dir = write_bundle("nosite", kHeader + "\n" + csv_line("0.1"));
  auto meta = nlohmann::json::parse(std::ifstream(dir + "/meta.json"));
  meta["site"].erase("middle_axis_azimuth_deg");
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json", "site.middle_axis_azimuth_deg is required"});
}

TEST_F(BundleTest, MetaKeysAnotherWriterAddedAreReadPastButANearMissIsRefused) {
  const std::string dir = write_bundle("extended", kHeader + "\n" + csv_line("0.1") + csv_line("0.2"));
  auto meta = nlohmann::json::parse(std::ifstream(dir + "/meta.json"));
  // formats.md lets a writer add keys: another logger's own are read past.
  meta["logger"] = "vendor-x 2.1";
  meta["imu"]["model"] = "FOG-3";
  std::ofstream(dir + "/meta.json") << meta.dump();
  const std::string db_path = temp_path("extended.db");
  EXPECT_NO_THROW(import_bundle(dir, db_path));

  // A misspelt gravity would silently become normal gravity (1e-4 m/s^2 off, twenty times the
  // accelerometer bias aimed at): refused, naming the key it resembles.
  meta["site"].erase("gravity_mps2");
  meta["site"]["gravity_mps"] = 9.81925;
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: site: unknown key \"gravity_mps\" (is it \"gravity_mps2\"?)"});
  meta["site"].erase("gravity_mps");
  meta["site"]["height_m"] = "10 m";
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: site.height_m must be a number, not a string"});
  meta["site"]["height_m"] = 10.0;
  meta["mount"]["r0_p_mm"] = {1.0, 2.0};
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: mount.r0_p_mm: expected an array of 3 numbers"});
  meta["mount"]["r0_p_mm"] = {1.0, 2.0, 3.0};
  meta["mount"]["C_o_p"][1][2] = "0";
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: mount.C_o_p[1][2]: expected a number"});

  // The table's certificate: another writer's keys beside ours are read past, but inside the
  // geometry nothing is (a term of the table's error silently dropped is a wrong reference).
  meta["mount"]["C_o_p"][1][2] = 0;
  meta["table"] = {{"certificate", "TBL-7"}, {"lab_note", "re-levelled"}, {"geometry", {{"outer_tilt_arcsec", {1.0, 2.0}}}}};
  std::ofstream(dir + "/meta.json") << meta.dump();
  const std::string table_db = temp_path("extended-table.db");
  EXPECT_NO_THROW(import_bundle(dir, table_db));
  const std::optional<table::TableCertificate> imported = RunDb::open(table_db).meta().table;
  EXPECT_TRUE(imported && imported->geometry.has_value());
  meta["table"]["geometry"]["outer_tilt_arcsec"][1] = "2";
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: table.geometry.outer_tilt_arcsec[1]: must be a number, not a string"});
  meta["table"]["geometry"]["outer_tilt_arcsec"][1] = 2.0;
  meta["table"]["geometry"]["wobble_arcsec"] = {1.0, 1.0};
  std::ofstream(dir + "/meta.json") << meta.dump();
  expect_rejected(dir, {"meta.json: table.geometry: unknown key", "wobble_arcsec"});
}

// The intervals a run's writer marked as held by a fault (imucald's suspensions): the export
// lists them in meta.json, the import keeps them in the run, and its export lists them again.
TEST_F(BundleTest, FaultedIntervalsGoIntoMetaJsonAndComeBackWithTheImport) {
  const nlohmann::json intervals = nlohmann::json::parse(
      R"([{"state": "suspended", "reason": "chamber out of band: 36.1 °C", "start": "2026-11-28T08:00:00.000Z",
           "end": "2026-11-28T08:00:07.500Z", "program_time_s": 150.25}])");
  const std::string db1 = temp_path("faulted.db"), dir1 = temp_path("faulted-bundle");
  const std::string db2 = temp_path("faulted-again.db"), dir2 = temp_path("faulted-bundle-again");
  std::vector<double> told;
  {
    RunDb run = RunDb::create(db1, simulated_meta());
    run.append(simulated_frames(9000, 3));
    run.set_extra(kFaultedIntervalsKey, intervals.dump());
    run.flush();
    export_bundle(run, dir1, [&](double fraction) { told.push_back(fraction); });
  }
  EXPECT_EQ(nlohmann::json::parse(std::ifstream(dir1 + "/meta.json")).at(kFaultedIntervalsKey), intervals);
  // Progress: from the start to the end, never back.
  ASSERT_GE(told.size(), 3U);
  EXPECT_TRUE(std::is_sorted(told.begin(), told.end()));
  EXPECT_LT(told.front(), 0.5);
  EXPECT_EQ(told.back(), 1.0);

  import_bundle(dir1, db2);
  const RunDb again = RunDb::open(db2);
  EXPECT_EQ(nlohmann::json::parse(again.extra(kFaultedIntervalsKey).value_or("null")), intervals);
  export_bundle(again, dir2);
  EXPECT_EQ(nlohmann::json::parse(std::ifstream(dir2 + "/meta.json")).at(kFaultedIntervalsKey), intervals);

  // A run without any: no key. A key of ours that is not a list of intervals, or a near miss of
  // it, is refused (a typo would silently drop them).
  const std::string plain = write_bundle("unfaulted", kHeader + "\n" + csv_line("0.1") + csv_line("0.2"));
  const std::string plain_db = temp_path("unfaulted.db");
  import_bundle(plain, plain_db);
  EXPECT_FALSE(RunDb::open(plain_db).extra(kFaultedIntervalsKey).has_value());
  auto meta = nlohmann::json::parse(std::ifstream(plain + "/meta.json"));
  meta[kFaultedIntervalsKey] = {1, 2};
  std::ofstream(plain + "/meta.json") << meta.dump();
  expect_rejected(plain, {"meta.json: faulted_intervals: must be an array of objects"});
  meta.erase(kFaultedIntervalsKey);
  meta["faulted_interval"] = intervals;
  std::ofstream(plain + "/meta.json") << meta.dump();
  expect_rejected(plain, {"unknown key \"faulted_interval\" (is it \"faulted_intervals\"?)"});
}

TEST_F(BundleTest, UnwrapsTableAngles) {
  // outer wraps at +-180 both ways, middle at 0/360 upwards, inner at 0/360 downwards.
  const std::string csv = kHeader + "\n" + csv_line("0.1", "170,350,2") + csv_line("0.2", "179.5,359,0.5") +
                          csv_line("0.3", "-175,1,358") + csv_line("0.4", "-160,10,355") +
                          csv_line("0.5", "-170,20,359") + csv_line("0.6", "175,30,1");
  const std::string db_path = temp_path("wrap.db");
  import_bundle(write_bundle("wrap", csv), db_path);
  const auto frames = RunDb::open(db_path).read_frames();
  ASSERT_EQ(frames.size(), 6U);
  const std::vector<Eigen::Vector3d> expected = {{170, 350, 2},   {179.5, 359, 0.5}, {185, 361, -2},
                                                 {200, 370, -5},  {190, 380, -1},    {175, 390, 1}};
  for (std::size_t i = 0; i < frames.size(); ++i) expect_same_bits(expected[i], frames[i].table_deg, "line " + std::to_string(i + 2));
}

TEST_F(BundleTest, ReportsAndStoresGaps) {
  // 100 Hz: 1.5 periods (15 ms) is still no gap, 20 ms and 440 ms are.
  const std::string csv = kHeader + "\n" + csv_line("0.01") + csv_line("0.02") + csv_line("0.035") +
                          csv_line("0.055") + csv_line("0.06") + csv_line("0.5") + csv_line("0.51");
  const std::string db_path = temp_path("gaps.db");
  const ImportReport report = import_bundle(write_bundle("gaps", csv, 100.0), db_path);
  EXPECT_EQ(report.frames, 7);
  ASSERT_EQ(report.gaps.size(), 2U);
  EXPECT_EQ(report.gaps[0].line, 5);
  EXPECT_EQ(report.gaps[0].t0_s, 0.035);
  EXPECT_EQ(report.gaps[0].t1_s, 0.055);
  EXPECT_EQ(report.gaps[0].t0_ns, 35'000'000);
  EXPECT_EQ(report.gaps[1].line, 7);
  EXPECT_EQ(report.gaps[1].t1_ns, 500'000'000);

  const auto stored = stored_gaps(RunDb::open(db_path));
  ASSERT_EQ(stored.size(), 2U);
  EXPECT_EQ(stored[1].line, 7);
  EXPECT_EQ(stored[1].t0_s, 0.06);
  EXPECT_EQ(stored[1].t1_ns, 500'000'000);
}

TEST_F(BundleTest, KeepsSetpointAndReportsIgnoredColumns) {
  const std::string header = kHeader + ",temp_gx_1_C,chamber_setpoint_C,comment";
  auto line = [](const std::string& t_s, const std::string& chamber, const std::string& setpoint) {
    return t_s + ", 1e-6 ,2e-6,3e-6,0.1,0.2,0.3,0,0,0,25,25,25,25,25,25," + chamber + ",99," + setpoint + ",x\r\n";
  };
  const std::string csv = header + "\r\n" + line("0.1", "20", "") + line("0.2", "20", "") + line("0.3", "20", "40") +
                          line("0.4", "21", "40") + line("0.5", "21", "40") + "\n";
  const std::string db_path = temp_path("setpoint.db");
  const ImportReport report = import_bundle(write_bundle("setpoint", csv), db_path);
  EXPECT_EQ(report.frames, 5);
  EXPECT_EQ(report.temp_samples, 3);
  EXPECT_EQ(report.ignored_columns, (std::vector<std::string>{"temp_gx_1_C", "comment"}));
  const RunDb run = RunDb::open(db_path);
  const auto temps = run.temps();
  ASSERT_EQ(temps.size(), 3U);
  EXPECT_FALSE(temps[0].chamber_setpoint_C.has_value());
  EXPECT_EQ(temps[1].t_ns, 300'000'000);
  EXPECT_EQ(temps[1].chamber_setpoint_C, std::optional<double>(40.0));
  EXPECT_EQ(temps[2].chamber_C, 21.0);

  // Exported with the set point column; the empty field comes back empty.
  const std::string dir = temp_path("export");
  export_bundle(run, dir);
  std::ifstream in(dir + "/frames.csv");
  std::string first_line;
  std::string second_line;
  std::getline(in, first_line);
  std::getline(in, second_line);
  EXPECT_EQ(first_line, kHeader + ",chamber_setpoint_C");
  EXPECT_EQ(second_line, "0.1,1e-06,2e-06,3e-06,0.1,0.2,0.3,0,0,0,25,25,25,25,25,25,20,");
}

TEST_F(BundleTest, KeepsTheEightSensorsOfEachCoil) {
  // formats.md's optional temp_gx_1_C .. temp_gz_8_C, in any order after the required columns:
  // kept when all 24 are there (empty fields: none at that line), and exported back.
  std::string header = kHeader;
  std::vector<std::string> names;
  for (const char* coil : {"gz", "gy", "gx"})  // reversed, to show that the names decide
    for (int k = 1; k <= 8; ++k) names.push_back(std::string("temp_") + coil + "_" + std::to_string(k) + "_C");
  for (const auto& n : names) header += "," + n;
  auto line = [&](const std::string& t_s, bool with_sensors) {
    std::string l = t_s + ",1e-6,2e-6,3e-6,0.1,0.2,0.3,0,0,0,25,25,25,25,25,25,20";
    for (std::size_t i = 0; i < names.size(); ++i) l += with_sensors ? "," + std::to_string(24.0 + 0.25 * static_cast<double>(i)) : ",";
    return l + "\n";
  };
  const std::string csv = header + "\n" + line("0.1", true) + line("0.2", true) + line("0.3", false);
  const std::string db_path = temp_path("coils.db");
  const ImportReport report = import_bundle(write_bundle("coils", csv), db_path);
  EXPECT_TRUE(report.ignored_columns.empty());
  EXPECT_EQ(report.temp_samples, 2);  // the second line repeats the first
  const RunDb run = RunDb::open(db_path);
  const auto temps = run.temps();
  ASSERT_EQ(temps.size(), 2U);
  ASSERT_TRUE(temps[0].coil_sensors_C.has_value());
  EXPECT_EQ((*temps[0].coil_sensors_C)[2][0], 24.0);   // temp_gz_1_C, the first of the list
  EXPECT_EQ((*temps[0].coil_sensors_C)[0][7], 29.75);  // temp_gx_8_C, the last
  EXPECT_FALSE(temps[1].coil_sensors_C.has_value());

  const std::string dir = temp_path("coils-export");
  export_bundle(run, dir);
  const std::string back = temp_path("coils-back.db");
  import_bundle(dir, back);
  const auto again = RunDb::open(back).temps();
  ASSERT_EQ(again.size(), temps.size());
  for (std::size_t i = 0; i < temps.size(); ++i) expect_temps_identical(temps[i], again[i], "sample " + std::to_string(i));

  // Some of a line's 24 given and some not: refused with the line.
  std::string partial = line("0.1", true);
  partial.replace(partial.rfind(','), std::string::npos, ",\n");
  expect_rejected(write_bundle("coils-partial", header + "\n" + partial), {"line 2", "23 of the 24 coil sensors"});
}

}  // namespace
}  // namespace imucal::storage
