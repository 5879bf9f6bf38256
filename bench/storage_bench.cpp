#include "bench/storage_bench.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <span>
#include <stdexcept>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "core/imu_model.hpp"
#include "sim/simulator.hpp"
#include "estimators/direct_calibration.hpp"
#include "motion_programs/program.hpp"
#include "storage/recorder.hpp"
#include "storage/run_db.hpp"

namespace imucal::bench {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double rss_mb() {
  std::ifstream statm("/proc/self/statm");
  long long pages_total = 0, pages_resident = 0;
  statm >> pages_total >> pages_resident;
  return static_cast<double>(pages_resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1e6;
}

double peak_rss_mb() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) * 1024.0 / 1e6;  // KiB on Linux
}

// The simulated stream: one run of a program, replayed cycle after cycle with shifted times, so
// that a benchmark can produce frames faster than the simulator (1.5 M frames/s) and still feed
// the estimator real statics and rotations. The meta lists the segments of every cycle.
class Stream {
 public:
  Stream(double rate_hz, std::int64_t total_frames) {
    const motion::TableLimits limits;
    program_ = std::make_unique<motion::Program>(motion::load_program("direct-short", limits));
    sim::SimConfig config;
    config.rate_hz = rate_hz;
    sim::Simulator simulator(*program_, ImuModel{}, config);
    meta_ = simulator.meta();
    pool_.reserve(static_cast<std::size_t>(simulator.frame_count()));
    ImuFrame frame;
    while (simulator.next(frame)) pool_.push_back(frame);
    temps_template_ = simulator.take_temps();
    if (pool_.size() < 2) throw std::runtime_error("bench: the simulated program is empty");
    const std::int64_t period_ns = pool_[1].t_ns - pool_[0].t_ns;
    cycle_ns_ = pool_.back().t_ns - pool_.front().t_ns + period_ns;
    const auto pool_n = static_cast<std::int64_t>(pool_.size());
    const std::int64_t cycles = (total_frames + pool_n - 1) / pool_n;
    const std::vector<SegmentInfo> base = meta_.segments;
    meta_.segments.clear();
    for (std::int64_t c = 0; c < cycles; ++c) {
      const double shift_s = static_cast<double>(c * cycle_ns_) * 1e-9;
      for (const auto& s : base) {
        meta_.segments.push_back({s.name + "#" + std::to_string(c), s.kind, s.t0_s + shift_s, s.t1_s + shift_s});
      }
    }
    temp_period_ns_ = static_cast<std::int64_t>(1e9);  // the temperature logger's 1 Hz
  }

  const RecordingMeta& meta() const { return meta_; }
  std::size_t pool_frames() const { return pool_.size(); }

  // The next `n` frames of the stream into `out`; temperatures due in that span into `temps`.
  void next(std::size_t n, std::vector<ImuFrame>& out, std::vector<TempSample>& temps) {
    out.resize(n);
    temps.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t k = static_cast<std::size_t>(index_ % static_cast<std::int64_t>(pool_.size()));
      const std::int64_t cycle = index_ / static_cast<std::int64_t>(pool_.size());
      out[i] = pool_[k];
      out[i].t_ns += cycle * cycle_ns_;
      ++index_;
    }
    while (!out.empty() && next_temp_t_ns_ <= out.back().t_ns) {
      TempSample sample = temps_template_.empty() ? TempSample{} : temps_template_.front();
      sample.t_ns = next_temp_t_ns_;
      sample.chamber_C = 25.0 + 1e-3 * static_cast<double>(next_temp_t_ns_ / temp_period_ns_ % 1000);
      temps.push_back(sample);
      next_temp_t_ns_ += temp_period_ns_;
    }
  }
  void rewind() {
    index_ = 0;
    next_temp_t_ns_ = 0;
  }

 private:
  std::unique_ptr<motion::Program> program_;
  RecordingMeta meta_;
  std::vector<ImuFrame> pool_;
  std::vector<TempSample> temps_template_;
  std::int64_t cycle_ns_ = 0;
  std::int64_t index_ = 0;
  std::int64_t temp_period_ns_ = 0;
  std::int64_t next_temp_t_ns_ = 0;
};

// The baseline: the same chunks, encoded by the same codec, appended with write(2) to a plain
// file by a writer thread behind the same kind of bounded queue, with an fsync every commit
// interval and at the end.
class RawAppender {
 public:
  RawAppender(const std::string& path, const RecordingMeta& meta, double interval_s, std::int64_t capacity_frames)
      : meta_(meta), interval_(std::chrono::duration<double>(interval_s)), capacity_(capacity_frames) {
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) throw std::runtime_error(path + ": " + std::strerror(errno));
    thread_ = std::thread([this] { run(); });
  }
  ~RawAppender() {
    finish();
    if (fd_ >= 0) ::close(fd_);
  }
  void push(std::span<const ImuFrame> frames) {
    std::unique_lock lock(mutex_);
    space_.wait(lock, [&] { return queued_ + static_cast<std::int64_t>(frames.size()) <= capacity_; });
    queue_.emplace_back(frames.begin(), frames.end());
    queued_ += static_cast<std::int64_t>(frames.size());
    work_.notify_one();
  }
  void finish() {
    {
      std::lock_guard lock(mutex_);
      done_ = true;
    }
    work_.notify_one();
    if (thread_.joinable()) thread_.join();
    if (error_) throw std::runtime_error(*error_);
  }
  std::int64_t bytes() const { return bytes_; }

 private:
  void write_all(const std::vector<unsigned char>& data) {
    std::size_t done = 0;
    while (done < data.size()) {
      const ssize_t n = ::write(fd_, data.data() + done, data.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        throw std::runtime_error(std::string("raw append: ") + std::strerror(errno));
      }
      done += static_cast<std::size_t>(n);
    }
    bytes_ += static_cast<std::int64_t>(data.size());
  }
  void sync() {
    if (::fsync(fd_) != 0) throw std::runtime_error(std::string("raw append fsync: ") + std::strerror(errno));
  }
  void run() {
    try {
      std::vector<ImuFrame> chunk;
      chunk.reserve(storage::RunDb::kFramesPerChunk);
      std::vector<unsigned char> payload;
      auto last_sync = Clock::now();
      for (;;) {
        std::vector<ImuFrame> block;
        {
          std::unique_lock lock(mutex_);
          work_.wait(lock, [&] { return !queue_.empty() || done_; });
          if (queue_.empty()) break;
          block = std::move(queue_.front());
          queue_.pop_front();
        }
        for (const auto& frame : block) {
          chunk.push_back(frame);
          if (chunk.size() == storage::RunDb::kFramesPerChunk) {
            storage::encode_chunk_payload(chunk, meta_, payload);
            write_all(payload);
            chunk.clear();
          }
        }
        {
          std::lock_guard lock(mutex_);
          queued_ -= static_cast<std::int64_t>(block.size());
        }
        space_.notify_all();
        if (Clock::now() - last_sync >= interval_) {
          sync();
          last_sync = Clock::now();
        }
      }
      if (!chunk.empty()) {
        storage::encode_chunk_payload(chunk, meta_, payload);
        write_all(payload);
      }
      sync();
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      error_ = e.what();
      queue_.clear();
      queued_ = 0;
      space_.notify_all();
    }
  }

  RecordingMeta meta_;
  std::chrono::duration<double> interval_;
  std::int64_t capacity_;
  int fd_ = -1;
  std::int64_t bytes_ = 0;
  std::mutex mutex_;
  std::condition_variable work_, space_;
  std::deque<std::vector<ImuFrame>> queue_;
  std::int64_t queued_ = 0;
  bool done_ = false;
  std::optional<std::string> error_;
  std::thread thread_;
};

// Samples the resident set while a phase runs.
class RssSampler {
 public:
  explicit RssSampler(std::function<double()> progress) : progress_(std::move(progress)) {
    thread_ = std::thread([this] {
      std::unique_lock lock(mutex_);
      while (!stop_) {
        samples_.emplace_back(progress_(), rss_mb());
        cv_.wait_for(lock, std::chrono::milliseconds(500), [&] { return stop_; });
      }
    });
  }
  std::vector<std::pair<double, double>> stop() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
    samples_.emplace_back(progress_(), rss_mb());
    return samples_;
  }

 private:
  std::function<double()> progress_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::vector<std::pair<double, double>> samples_;
  std::thread thread_;
};

// Produces `total` frames in batches into `push`, with the estimator consuming each batch after
// handing it over (so that the writer thread works on it meanwhile).
PhaseResult produce(Stream& stream, std::int64_t total, std::int64_t batch_frames, bool estimator,
                    const std::function<void(std::span<const ImuFrame>)>& push,
                    const std::function<void(std::span<const TempSample>)>& push_temps,
                    const std::function<void()>& finish, std::atomic<std::int64_t>& produced,
                    std::int64_t* estimator_intervals) {
  stream.rewind();
  std::optional<direct::DirectCalibrator> calibrator;
  if (estimator) calibrator.emplace(stream.meta());
  std::vector<ImuFrame> batch;
  std::vector<TempSample> temps;
  const auto t0 = Clock::now();
  std::int64_t done = 0;
  while (done < total) {
    const auto n = static_cast<std::size_t>(std::min(batch_frames, total - done));
    stream.next(n, batch, temps);
    push(batch);
    if (!temps.empty()) push_temps(temps);
    if (calibrator) {
      for (const auto& frame : batch) calibrator->push(frame);
    }
    done += static_cast<std::int64_t>(n);
    produced.store(done, std::memory_order_relaxed);
  }
  finish();
  PhaseResult result;
  result.frames = total;
  result.wall_s = seconds_since(t0);
  result.frames_per_s = static_cast<double>(total) / result.wall_s;
  if (calibrator && estimator_intervals != nullptr) {
    *estimator_intervals = static_cast<std::int64_t>(calibrator->intervals().size());
  }
  return result;
}

void remove_run(const std::string& path) {
  std::error_code ignored;
  for (const char* suffix : {"", "-wal", "-shm", "-writer"}) fs::remove(path + suffix, ignored);
}

}  // namespace

RecordBenchResult run_record_bench(const RecordBenchOptions& o) {
  const bool memory_run = o.data_hours > 0.0;
  const std::int64_t total =
      memory_run ? static_cast<std::int64_t>(o.data_hours * 3600.0 * o.rate_hz) : o.frames;
  if (total <= 0 || o.batch_frames <= 0) throw std::runtime_error("bench record: frames and batch must be positive");
  fs::create_directories(o.dir);
  Stream stream(o.rate_hz, total);
  RecordBenchResult r;
  std::atomic<std::int64_t> produced{0};
  std::int64_t raw_bytes = 0;

  auto raw_phase = [&](bool estimator) {
    const std::string path = (fs::path(o.dir) / "raw-append.bin").string();
    PhaseResult phase;
    {
      RawAppender raw(path, stream.meta(), o.commit_interval_s, o.queue_frames);
      phase = produce(
          stream, total, o.batch_frames, estimator, [&](std::span<const ImuFrame> f) { raw.push(f); },
          [](std::span<const TempSample>) {}, [&] { raw.finish(); }, produced, nullptr);
      raw_bytes = raw.bytes();
    }
    fs::remove(path);
    return phase;
  };

  auto recorder_phase = [&](bool estimator, bool sample_memory) {
    const std::string path = (fs::path(o.dir) / "bench-run.db").string();
    remove_run(path);
    storage::RecorderOptions options;
    options.commit_interval_s = o.commit_interval_s;
    options.queue_capacity_frames = o.queue_frames;
    options.wait_when_full = true;  // measure the recorder's own pace
    produced = 0;
    if (sample_memory) r.rss_before_recording_mb = rss_mb();
    std::optional<RssSampler> sampler;
    if (sample_memory) {
      sampler.emplace([&] { return static_cast<double>(produced.load()) / static_cast<double>(total); });
    }
    PhaseResult phase;
    storage::RecorderStats stats;
    {
      storage::Recorder recorder(storage::RunDb::create(path, stream.meta()), options);
      phase = produce(
          stream, total, o.batch_frames, estimator,
          [&](std::span<const ImuFrame> f) {
            if (recorder.push(f) != storage::Recorder::Push::Queued) {
              throw std::runtime_error("bench record: " + recorder.error().value_or("push refused"));
            }
          },
          [&](std::span<const TempSample> t) { recorder.push_temps(t); },
          [&] {
            if (!recorder.close()) throw std::runtime_error("bench record: " + recorder.error().value_or("failed"));
          },
          produced, estimator ? &r.estimator_intervals : nullptr);
      stats = recorder.stats();
    }
    if (sampler) r.rss_mb_by_progress = sampler->stop();
    r.commits = stats.commits;
    r.max_commit_s = stats.max_commit_s;
    r.queue_high_water_frames = stats.high_water_frames;
    r.dropped_frames = stats.dropped_frames;
    r.bytes_per_frame = static_cast<double>(fs::file_size(path)) / static_cast<double>(total);
    if (o.keep && sample_memory) {
      r.run_path = path;
    } else {
      remove_run(path);
    }
    return phase;
  };

  if (!memory_run) {
    r.raw = raw_phase(true);
    r.raw_bytes_per_frame = static_cast<double>(raw_bytes) / static_cast<double>(total);
    if (o.storage_only_phases) {
      r.raw_storage_only = raw_phase(false);
      r.recorder_storage_only = recorder_phase(false, false);
      r.raw_append_ratio_storage_only = r.recorder_storage_only.frames_per_s / r.raw_storage_only.frames_per_s;
    }
  }
  r.recorder = recorder_phase(o.estimator, true);
  if (!memory_run) r.raw_append_ratio = r.recorder.frames_per_s / r.raw.frames_per_s;
  r.peak_rss_mb = peak_rss_mb();
  return r;
}

namespace {

// The baseline of `bench read`: the run's chunks as a plain file ([u32 frames, u32 codec, u32
// bytes, payload] each, written untimed), read back with read(2) and decoded by the same codec.
void raw_read_baseline(const std::string& run_path, const std::string& dir, ReadBenchResult& r) {
  const std::string raw_path = (fs::path(dir) / "raw-read.bin").string();
  {
    const storage::RunDb db = storage::RunDb::open(run_path, storage::OpenMode::Read);
    const RecordingMeta meta = db.meta();
    std::ofstream out(raw_path, std::ios::binary | std::ios::trunc);
    std::vector<unsigned char> payload;
    db.for_each_block([&](std::span<const ImuFrame> block) {
      for (std::size_t at = 0; at < block.size(); at += storage::RunDb::kFramesPerChunk) {
        const auto part = block.subspan(at, std::min(storage::RunDb::kFramesPerChunk, block.size() - at));
        const auto codec = static_cast<std::uint32_t>(storage::encode_chunk_payload(part, meta, payload));
        const std::uint32_t header[3] = {static_cast<std::uint32_t>(part.size()), codec,
                                         static_cast<std::uint32_t>(payload.size())};
        out.write(reinterpret_cast<const char*>(header), sizeof(header));
        out.write(reinterpret_cast<const char*>(payload.data()), static_cast<std::streamsize>(payload.size()));
      }
    });
    if (!out) throw std::runtime_error(raw_path + ": cannot write");
  }
  const int fd = ::open(raw_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(raw_path + ": " + std::strerror(errno));
  auto read_exact = [&](void* to, std::size_t bytes) {
    std::size_t done = 0;
    while (done < bytes) {
      const ssize_t n = ::read(fd, static_cast<char*>(to) + done, bytes - done);
      if (n <= 0) return false;
      done += static_cast<std::size_t>(n);
    }
    return true;
  };
  std::vector<unsigned char> payload;
  std::vector<ImuFrame> decoded;
  std::int64_t frames = 0;
  double checksum = 0.0;
  const auto t0 = Clock::now();
  std::uint32_t header[3];
  while (read_exact(header, sizeof(header))) {
    payload.resize(header[2]);
    if (!read_exact(payload.data(), payload.size())) break;
    storage::decode_chunk_payload(payload, header[0], static_cast<int>(header[1]), decoded);
    frames += static_cast<std::int64_t>(decoded.size());
    checksum += decoded.back().dv_mps.z();
  }
  const double wall_s = seconds_since(t0);
  ::close(fd);
  fs::remove(raw_path);
  if (frames != r.frames) throw std::runtime_error("bench read: the raw file holds a different number of frames");
  r.raw_frames_per_s = static_cast<double>(frames) / wall_s;
  std::fprintf(stderr, "(raw checksum %.3g)\n", checksum);
}

}  // namespace

ReadBenchResult run_read_bench(const ReadBenchOptions& o) {
  std::string path = o.db;
  bool made = false;
  if (path.empty()) {
    RecordBenchOptions rec;
    rec.dir = o.dir;
    rec.frames = o.frames;
    fs::create_directories(o.dir);
    path = (fs::path(o.dir) / "bench-read.db").string();
    remove_run(path);
    Stream stream(rec.rate_hz, rec.frames);
    storage::RecorderOptions options;
    options.wait_when_full = true;
    storage::Recorder recorder(storage::RunDb::create(path, stream.meta()), options);
    std::vector<ImuFrame> batch;
    std::vector<TempSample> temps;
    for (std::int64_t done = 0; done < rec.frames; done += rec.batch_frames) {
      stream.next(static_cast<std::size_t>(std::min(rec.batch_frames, rec.frames - done)), batch, temps);
      recorder.push(batch);
      recorder.push_temps(temps);
    }
    if (!recorder.close()) throw std::runtime_error("bench read: " + recorder.error().value_or("failed"));
    made = true;
  }
  ReadBenchResult r;
  {
    const storage::RunDb db = storage::RunDb::open(path, storage::OpenMode::Read);
    // Whole run, block by block (what an estimator or the export does).
    std::int64_t frames = 0;
    double checksum = 0.0;  // keeps the decoding from being optimised away
    std::int64_t first_t = 0, last_t = 0;
    auto t0 = Clock::now();
    db.for_each_block([&](std::span<const ImuFrame> block) {
      if (frames == 0) first_t = block.front().t_ns;
      frames += static_cast<std::int64_t>(block.size());
      checksum += block.back().dv_mps.z();
      last_t = block.back().t_ns;
    });
    r.wall_s = seconds_since(t0);
    r.frames = frames;
    r.frames_per_s = static_cast<double>(frames) / r.wall_s;
    if (frames == 0) throw std::runtime_error("bench read: the run holds no frames");

    // Random 10 s ranges (plots zoomed in, estimators re-reading a segment).
    std::mt19937_64 rng(1);
    const std::int64_t window_ns = 10'000'000'000;
    std::uniform_int_distribution<std::int64_t> start(first_t, std::max(first_t, last_t - window_ns));
    std::int64_t range_frames = 0;
    t0 = Clock::now();
    for (int i = 0; i < o.range_reads; ++i) {
      const std::int64_t a = start(rng);
      const auto got = db.read_frames(a, a + window_ns);
      range_frames += static_cast<std::int64_t>(got.size());
      if (!got.empty()) checksum += got.front().dtheta_rad.x();
    }
    r.range_frames_per_s = static_cast<double>(range_frames) / seconds_since(t0);

    t0 = Clock::now();
    const auto full = db.decimate(first_t, last_t + 1, o.plot_columns);
    r.decimate_full_ms = seconds_since(t0) * 1e3;
    t0 = Clock::now();
    const auto window = db.decimate(first_t, std::min(last_t + 1, first_t + 60'000'000'000), o.plot_columns);
    r.decimate_decoded_ms = seconds_since(t0) * 1e3;
    checksum += full.front().max[0] + window.front().min[0];
    std::fprintf(stderr, "(checksum %.3g)\n", checksum);
  }
  r.bytes_per_frame = static_cast<double>(fs::file_size(path)) / static_cast<double>(r.frames);
  raw_read_baseline(path, o.dir, r);
  r.raw_append_ratio = r.frames_per_s / r.raw_frames_per_s;
  if (made) remove_run(path);
  return r;
}

namespace {

nlohmann::json phase_json(const PhaseResult& p) {
  return {{"frames", p.frames}, {"wall_s", p.wall_s}, {"frames_per_s", p.frames_per_s}};
}

}  // namespace

void add_storage_bench_commands(CLI::App& bench) {
  bench.require_subcommand(1);

  auto record_options = std::make_shared<RecordBenchOptions>();
  auto record_json = std::make_shared<bool>(false);
  auto* record = bench.add_subcommand(
      "record", "Recorder throughput (stage 1 consuming the stream) against a plain-file append with fsync");
  record->add_option("--dir", record_options->dir, "folder on the disk under test")->capture_default_str();
  record->add_option("--frames", record_options->frames, "frames per phase")->capture_default_str();
  record->add_option("--data-hours", record_options->data_hours,
                     "record this many hours of data (at --rate) with the estimator, sampling memory; "
                     "skips the raw phases")
      ->check(CLI::NonNegativeNumber);
  record->add_option("--rate", record_options->rate_hz, "IMU rate of the stream, Hz")->capture_default_str();
  record->add_option("--commit-interval", record_options->commit_interval_s, "recorder commit interval, s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  record->add_option("--batch", record_options->batch_frames, "frames per push")->capture_default_str();
  record->add_option("--queue-frames", record_options->queue_frames, "recorder queue capacity")->capture_default_str();
  record->add_flag("--keep", record_options->keep, "keep the recorded run");
  record->add_flag("!--no-estimator", record_options->estimator,
                   "record without stage 1 consuming the stream (the memory of the storage alone)");
  record->add_flag("--json", *record_json, "print one JSON object");
  record->callback([record_options, record_json] {
    RecordBenchResult r;
    try {
      r = run_record_bench(*record_options);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "imucal bench record: %s\n", e.what());
      throw CLI::RuntimeError(1);
    }
    nlohmann::json rss = nlohmann::json::array();
    for (const auto& [progress, mb] : r.rss_mb_by_progress) rss.push_back({progress, mb});
    const bool memory_run = record_options->data_hours > 0.0;
    nlohmann::json j = {{"frames_per_s", r.recorder.frames_per_s},
                        {"frames", r.recorder.frames},
                        {"wall_s", r.recorder.wall_s},
                        {"raw_append_ratio", memory_run ? nlohmann::json(nullptr) : nlohmann::json(r.raw_append_ratio)},
                        {"raw_frames_per_s", r.raw.frames_per_s},
                        {"bytes_per_frame", r.bytes_per_frame},
                        {"raw_bytes_per_frame", r.raw_bytes_per_frame},
                        {"estimator", record_options->estimator ? "DirectCalibrator" : "none"},
                        {"estimator_intervals", r.estimator_intervals},
                        {"commit_interval_s", record_options->commit_interval_s},
                        {"commits", r.commits},
                        {"max_commit_s", r.max_commit_s},
                        {"queue_high_water_frames", r.queue_high_water_frames},
                        {"dropped_frames", r.dropped_frames},
                        {"peak_rss_mb", r.peak_rss_mb},
                        {"rss_before_recording_mb", r.rss_before_recording_mb},
                        {"rss_mb_by_progress", rss}};
    if (!memory_run && record_options->storage_only_phases) {
      j["storage_only"] = {{"recorder", phase_json(r.recorder_storage_only)},
                           {"raw", phase_json(r.raw_storage_only)},
                           {"raw_append_ratio", r.raw_append_ratio_storage_only}};
    }
    if (!r.run_path.empty()) j["run"] = r.run_path;
    if (*record_json) {
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("recorder%s: %lld frames in %.2f s = %.0f frames/s (%lld commits, longest %.3f s, "
                "queue high water %lld, dropped %lld)\n",
                record_options->estimator ? " + stage 1" : "", static_cast<long long>(r.recorder.frames),
                r.recorder.wall_s, r.recorder.frames_per_s,
                static_cast<long long>(r.commits), r.max_commit_s, static_cast<long long>(r.queue_high_water_frames),
                static_cast<long long>(r.dropped_frames));
    if (!memory_run) {
      std::printf("raw append + stage 1: %.0f frames/s -> raw_append_ratio %.2f\n", r.raw.frames_per_s,
                  r.raw_append_ratio);
      if (record_options->storage_only_phases) {
        std::printf("storage only: recorder %.0f frames/s, raw append %.0f frames/s -> ratio %.2f\n",
                    r.recorder_storage_only.frames_per_s, r.raw_storage_only.frames_per_s,
                    r.raw_append_ratio_storage_only);
      }
    }
    std::printf("bytes per frame: %.2f (raw file %.2f)\n", r.bytes_per_frame, r.raw_bytes_per_frame);
    std::printf("memory: %.1f MB before recording, peak %.1f MB (RSS samples over the run:",
                r.rss_before_recording_mb, r.peak_rss_mb);
    for (const auto& [progress, mb] : r.rss_mb_by_progress) std::printf(" %.0f%%:%.1f", 100 * progress, mb);
    std::printf(")\n");
  });

  auto read_options = std::make_shared<ReadBenchOptions>();
  auto read_json = std::make_shared<bool>(false);
  auto* read = bench.add_subcommand("read", "Read speed of a run: whole run, random ranges, plot decimation");
  read->add_option("--db", read_options->db, "run to read (default: record one first, not timed)")
      ->check(CLI::ExistingFile);
  read->add_option("--dir", read_options->dir, "folder for the run recorded first")->capture_default_str();
  read->add_option("--frames", read_options->frames, "frames of the run recorded first")->capture_default_str();
  read->add_flag("--json", *read_json, "print one JSON object");
  read->callback([read_options, read_json] {
    ReadBenchResult r;
    try {
      r = run_read_bench(*read_options);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "imucal bench read: %s\n", e.what());
      throw CLI::RuntimeError(1);
    }
    nlohmann::json j = {{"frames_per_s", r.frames_per_s},
                        {"frames", r.frames},
                        {"wall_s", r.wall_s},
                        {"range_frames_per_s", r.range_frames_per_s},
                        {"decimate_full_ms", r.decimate_full_ms},
                        {"decimate_60s_decoded_ms", r.decimate_decoded_ms},
                        {"raw_frames_per_s", r.raw_frames_per_s},
                        {"raw_append_ratio", r.raw_append_ratio},
                        {"raw_baseline", "the same chunk bytes read with read(2) from a plain file and decoded"},
                        {"bytes_per_frame", r.bytes_per_frame}};
    if (*read_json) {
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("read: %lld frames in %.3f s = %.0f frames/s (plain file %.0f frames/s, ratio %.2f); random 10 s "
                "ranges %.0f frames/s; decimate whole run %.1f ms, 60 s window %.1f ms; %.2f bytes/frame\n",
                static_cast<long long>(r.frames), r.wall_s, r.frames_per_s, r.raw_frames_per_s, r.raw_append_ratio,
                r.range_frames_per_s, r.decimate_full_ms, r.decimate_decoded_ms, r.bytes_per_frame);
  });
}

}  // namespace imucal::bench
