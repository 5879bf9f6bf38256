#include "drivers/sim/sim_imu.hpp"

#include <atomic>
#include <cerrno>
#include <cmath>
#include <mutex>
#include <thread>
#include <vector>

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "drivers/sim/simulator.hpp"

namespace imucal::drivers::sim {

using ::imucal::sim::SimConfig;
using ::imucal::sim::Simulator;

namespace {
// Truth kept for this long (a benchmark looks samples up shortly after receiving them).
constexpr double kTruthHistory_s = 60.0;
constexpr double kFarFuture_s = 1e6;
}  // namespace

struct SimImu::Impl {
  SimWorld& world;
  int fd;
  SimImuConfig cfg;
  double dt_s;
  double gyro_lsb, accel_lsb;
  std::int64_t lead_frames;  // physics restarts begin this many frames early (channel delays)
  std::thread thread;
  std::atomic<bool> stop{false};
  std::atomic<bool> streaming{false};
  std::atomic<bool> link_closed{false};
  std::atomic<std::uint64_t> sent{0}, not_sent{0}, restarts{0};
  std::atomic<int> drop{0}, corrupt{0};
  std::atomic<std::uint16_t> status_bits{0};
  std::atomic<std::int64_t> pause_until_ns{0};
  std::atomic<double> temperature_C;

  // Physics: a Simulator over the table motion from shortly before the frame it must produce.
  std::unique_ptr<motion::Program> program;
  std::unique_ptr<Simulator> simulator;
  std::uint64_t motion_version = 0;
  std::int64_t physics_next_k = -1;

  std::int64_t next_k = 0;
  std::uint32_t next_sequence = 0;
  std::uint16_t temperature_sequence = 0;
  double next_temperature_s = 0.0;

  mutable std::mutex truth_mutex;
  std::vector<SampleTruth> truth_ring;
  std::vector<bool> truth_valid;

  Impl(SimWorld& w, int f, SimImuConfig c) : world(w), fd(f), cfg(std::move(c)), temperature_C(cfg.temperature_C) {
    dt_s = 1.0 / cfg.rate_hz;
    gyro_lsb = SimImu::gyro_lsb_rad_at(cfg.rate_hz);
    accel_lsb = SimImu::accel_lsb_mps_at(cfg.rate_hz);
    double max_delay = 0.0;
    for (int j = 0; j < 3; ++j) max_delay = std::max({max_delay, cfg.truth.gyro.delay_s[j], cfg.truth.accel.delay_s[j]});
    lead_frames = static_cast<std::int64_t>(std::ceil(max_delay / dt_s)) + 2;
    const auto n = static_cast<std::size_t>(std::ceil(kTruthHistory_s * cfg.rate_hz));
    truth_ring.resize(n);
    truth_valid.assign(n, false);
  }

  // The frame covering world ((k-1) dt, k dt].
  ImuFrame produce(std::int64_t k) {
    const bool need_restart = !simulator || physics_next_k != k;
    std::unique_ptr<motion::Program> fresh;
    const double t_from = static_cast<double>(k - 1 - lead_frames) * dt_s;
    world.with_servo([&](TableServo& s, double) {
      // Motion only ever changes from "now" on, and now is past t_k: a Simulator started before
      // the change stays exact up to it, then must be restarted on the new motion.
      if (need_restart || s.version() != motion_version) {
        motion_version = s.version();
        fresh = std::make_unique<motion::Program>(s.program_from(t_from));
      }
      return 0;
    });
    if (fresh) {
      SimConfig sc;
      sc.site = cfg.site;
      sc.mount = cfg.mount;
      sc.rate_hz = cfg.rate_hz;
      // One noise stream per restart, derived from the seed (restarts are rare: motion changes).
      sc.seed = cfg.seed ^ (0x9E3779B97F4A7C15ULL * (restarts.load() + 1));
      sc.duration_s = kFarFuture_s;
      sc.temperature_C = temperature_C.load();
      simulator.reset();
      program = std::move(fresh);
      simulator = std::make_unique<Simulator>(*program, cfg.truth, sc);
      ImuFrame skip;
      for (std::int64_t i = 0; i < lead_frames; ++i) simulator->next(skip);
      ++restarts;
    }
    ImuFrame f;
    simulator->next(f);
    (void)simulator->take_temps();  // temperatures come from this device's own model
    physics_next_k = k + 1;
    return f;
  }

  bool send_frame(const can::LinkFrame& frame) {
    const auto wire = can::to_wire(frame);
    const ssize_t n = ::send(fd, wire.data(), wire.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(wire.size())) return true;
    if (n < 0 && (errno == EPIPE || errno == ECONNRESET || errno == ENOTCONN)) link_closed = true;
    return false;
  }

  bool send_record(std::uint32_t fd_id, std::uint32_t classic_base, std::uint8_t seq_byte,
                   const std::array<std::uint8_t, can::kRecordBytes>& rec) {
    if (cfg.framing == can::Framing::fd) return send_frame(can::fd_frame(fd_id, rec));
    bool ok = true;
    for (const auto& part : can::classic_frames(classic_base, seq_byte, rec)) ok = send_frame(part) && ok;
    return ok;
  }

  void read_commands() {
    for (;;) {
      std::uint8_t buf[can::kCanFdMtu];
      const ssize_t n = ::recv(fd, buf, sizeof buf, MSG_DONTWAIT);
      if (n <= 0) {
        if (n == 0) link_closed = true;
        return;
      }
      const auto f = can::parse_wire(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)));
      if (!f || f->can_id != can::kIdCommand || f->len < 1) continue;
      if (f->data[0] == can::kCommandStart && !streaming) {
        next_k = static_cast<std::int64_t>(std::floor(world.now_s() / dt_s)) + 1;
        next_temperature_s = static_cast<double>(next_k) * dt_s;
        streaming = true;
      } else if (f->data[0] == can::kCommandStop) {
        streaming = false;
      }
    }
  }

  void send_temperatures(double t_s) {
    const double base = temperature_C.load();
    can::TemperatureRecord p0, p1;
    p0.page = 0;
    p1.page = 1;
    p0.sequence = p1.sequence = temperature_sequence++;
    p0.device_time_ns = p1.device_time_ns = device_time_ns(t_s);
    // Coil sensors spread a little around the block temperature, accelerometers a bit warmer.
    for (std::size_t j = 0; j < 24; ++j)
      p0.values_cC[j] = static_cast<std::int16_t>(std::lround((base + 0.02 * static_cast<double>(j % 8) - 0.07) * 100.0));
    p1.values_cC.fill(can::kNoTemperature);
    for (std::size_t j = 0; j < 3; ++j) p1.values_cC[j] = static_cast<std::int16_t>(std::lround((base + 0.5) * 100.0));
    const auto seq_byte = static_cast<std::uint8_t>(p0.sequence);
    send_record(can::kIdTemperatureFd, can::kIdTemperatureClassic, seq_byte, can::encode(p0));
    send_record(can::kIdTemperatureFd, can::kIdTemperatureClassic, seq_byte, can::encode(p1));
  }

  std::uint64_t device_time_ns(double world_s) const {
    const double ns = world_s * 1e9 * (1.0 + cfg.clock_drift_ppm * 1e-6);
    return static_cast<std::uint64_t>(std::llround(ns) + cfg.clock_offset_ns);
  }

  static std::int32_t to_counts(double value, double lsb, std::uint16_t& status) {
    const double c = std::nearbyint(value / lsb);
    if (c > static_cast<double>(INT32_MAX) || c < static_cast<double>(INT32_MIN)) {
      status = static_cast<std::uint16_t>(status | can::status::kOverRange);
      return c > 0 ? INT32_MAX : INT32_MIN;
    }
    return static_cast<std::int32_t>(c);
  }

  void run() {
    while (!stop) {
      if (link_closed) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        continue;
      }
      if (!streaming) {
        pollfd p{fd, POLLIN, 0};
        ::poll(&p, 1, 20);
        read_commands();
        continue;
      }
      const std::int64_t k = next_k;
      const double t_k = static_cast<double>(k) * dt_s;
      const std::int64_t sample_host_ns = world.host_ns(t_k);
      const std::int64_t send_at = world.host_ns(t_k + cfg.latency_us * 1e-6);
      // Sleep until the transmission time in short steps, so that stop() is prompt at any rate.
      for (;;) {
        const std::int64_t left = send_at - host_time_ns();
        if (left <= 0 || stop) break;
        std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<std::int64_t>(left, 20'000'000)));
      }
      if (stop) break;
      read_commands();
      if (!streaming || link_closed) continue;

      const ImuFrame f = produce(k);
      ++next_k;
      const std::uint32_t seq = next_sequence++;
      can::SampleRecord r;
      r.sequence = seq;
      r.device_time_ns = device_time_ns(t_k);
      r.status = status_bits.load();
      for (std::size_t j = 0; j < 3; ++j) {
        r.gyro_counts[j] = to_counts(f.dtheta_rad[static_cast<Eigen::Index>(j)], gyro_lsb, r.status);
        r.accel_counts[j] = to_counts(f.dv_mps[static_cast<Eigen::Index>(j)], accel_lsb, r.status);
      }
      const double temp = temperature_C.load();
      r.gyro_temp_cC = static_cast<std::int16_t>(std::lround(temp * 100.0));
      r.accel_temp_cC = static_cast<std::int16_t>(std::lround((temp + 0.5) * 100.0));
      {
        std::lock_guard lock(truth_mutex);
        const std::size_t i = seq % truth_ring.size();
        truth_ring[i] = SampleTruth{seq, t_k, sample_host_ns, f.table_deg, r.gyro_counts, r.accel_counts};
        truth_valid[i] = true;
      }
      const std::int64_t now = host_time_ns();
      r.latency_us = static_cast<std::uint32_t>(std::max<std::int64_t>(0, (now - sample_host_ns) / 1000));
      bool skip = now < pause_until_ns.load();
      if (!skip && drop.load() > 0) {
        --drop;
        skip = true;
      }
      if (skip) {
        ++not_sent;
      } else {
        auto rec = can::encode(r);
        if (corrupt.load() > 0) {
          --corrupt;
          rec[21] = static_cast<std::uint8_t>(rec[21] ^ 0x10);  // one bit of gyro x, after the CRC
        }
        if (send_record(can::kIdSampleFd, can::kIdSampleClassic, static_cast<std::uint8_t>(seq), rec))
          ++sent;
        else
          ++not_sent;
      }
      if (cfg.temp_rate_hz > 0.0 && t_k >= next_temperature_s) {
        if (now >= pause_until_ns.load()) send_temperatures(t_k);
        next_temperature_s += 1.0 / cfg.temp_rate_hz;
        if (next_temperature_s < t_k) next_temperature_s = t_k + 1.0 / cfg.temp_rate_hz;
      }
    }
  }
};

SimImu::SimImu(SimWorld& world, int socket_fd, SimImuConfig config)
    : impl_(std::make_unique<Impl>(world, socket_fd, std::move(config))) {
  // On a socket pair the sender's buffer is the link's queue: room for seconds of frames, as a
  // CAN controller's receive queue plus the kernel's would hold (clamped by net.core.wmem_max).
  const int bytes = 4 << 20;
  (void)::setsockopt(socket_fd, SOL_SOCKET, SO_SNDBUF, &bytes, sizeof bytes);
  impl_->thread = std::thread([this] { impl_->run(); });
}

SimImu::~SimImu() {
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
  ::close(impl_->fd);
}

double SimImu::gyro_lsb_rad_at(double rate_hz) noexcept { return Simulator::kGyroLsbAt1kHz_rad * 1000.0 / rate_hz; }
double SimImu::accel_lsb_mps_at(double rate_hz) noexcept { return Simulator::kAccelLsbAt1kHz_mps * 1000.0 / rate_hz; }
double SimImu::gyro_lsb_rad() const noexcept { return impl_->gyro_lsb; }
double SimImu::accel_lsb_mps() const noexcept { return impl_->accel_lsb; }
bool SimImu::streaming() const noexcept { return impl_->streaming; }
std::uint64_t SimImu::samples_sent() const noexcept { return impl_->sent; }
std::uint64_t SimImu::samples_not_sent() const noexcept { return impl_->not_sent; }
std::uint64_t SimImu::physics_restarts() const noexcept { return impl_->restarts; }

std::optional<SampleTruth> SimImu::truth(std::uint32_t sequence) const {
  std::lock_guard lock(impl_->truth_mutex);
  const std::size_t i = sequence % impl_->truth_ring.size();
  if (!impl_->truth_valid[i] || impl_->truth_ring[i].sequence != sequence) return std::nullopt;
  return impl_->truth_ring[i];
}

void SimImu::drop_next_samples(int count) { impl_->drop = count; }
void SimImu::corrupt_next_samples(int count) { impl_->corrupt = count; }
void SimImu::set_status_bits(std::uint16_t bits) { impl_->status_bits = bits; }
void SimImu::pause(std::chrono::milliseconds duration) {
  impl_->pause_until_ns = host_time_ns() + std::chrono::duration_cast<std::chrono::nanoseconds>(duration).count();
}
void SimImu::close_link() {
  ::shutdown(impl_->fd, SHUT_RDWR);
  impl_->link_closed = true;
}
void SimImu::set_temperature(double celsius) { impl_->temperature_C = celsius; }

}  // namespace imucal::drivers::sim
