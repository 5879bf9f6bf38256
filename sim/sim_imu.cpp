#include "sim/sim_imu.hpp"

#include <atomic>
#include <cerrno>
#include <cmath>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include "drivers/imu_codec.hpp"
#include "sim/simulator.hpp"

namespace imucal::sim {

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

using ::imucal::sim::SimConfig;
using ::imucal::sim::Simulator;

namespace {
// Truth kept for this long (a benchmark looks samples up shortly after receiving them).
constexpr double kTruthHistory_s = 60.0;
constexpr double kOpenEnded_s = 1e6;  // a restarted simulator runs until the next restart
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
  std::atomic<int> drop{0}, corrupt{0}, sequence_skip{0}, drop_byte{0};
  std::atomic<bool> close_requested{false};
  std::atomic<std::uint64_t> status_bits{0};
  std::mutex garbage_mutex;
  std::vector<std::uint8_t> garbage;
  std::vector<std::uint8_t> command_bytes;  // a byte stream's input, searched for commands
  // A pause is asked for (its length) and begun by this thread when it next sends: a loaded machine
  // that holds the thread up meanwhile then cannot shorten the silence (the frames held up were
  // sent late inside it, and the driver saw no stall).
  std::atomic<std::int64_t> pause_request_ns{0};
  std::atomic<std::int64_t> pause_until_ns{0}, pause_began_ns{0};
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
  double next_identity_s = 0.0;  // world time of the next identity message

  mutable std::mutex truth_mutex;
  std::vector<SampleTruth> truth_ring;
  std::vector<bool> truth_valid;

  Impl(SimWorld& w, int f, SimImuConfig c) : world(w), fd(f), cfg(std::move(c)), temperature_C(cfg.temperature_C) {
    dt_s = 1.0 / cfg.rate_hz;
    link::resolve_per_unit_lsb(cfg.link,
                               cfg.link.gyro_lsb_per_unit() ? std::optional(SimImu::gyro_lsb_rad_at(cfg.rate_hz)) : std::nullopt,
                               cfg.link.accel_lsb_per_unit() ? std::optional(SimImu::accel_lsb_mps_at(cfg.rate_hz)) : std::nullopt);
    gyro_lsb = cfg.link.gyro_increment_lsb_rad().value_or(0.0);
    accel_lsb = cfg.link.accel_increment_lsb_mps().value_or(0.0);
    // A description without a start command streams from power-on.
    streaming = !cfg.link.start.has_value();
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
      sc.duration_s = kOpenEnded_s;
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

  // Writes all of `bytes` on a byte stream, waiting for room while the reader is behind; what
  // does not fit within a second is lost, as on a real line whose receiver overran. A second, not
  // the 50 ms it once was: a reader merely descheduled on a loaded host (a test beside a parallel
  // build) lost a frame, and a test counting the gaps of one injected fault saw two.
  bool write_stream(std::span<const std::uint8_t> bytes) {
    std::size_t done = 0;
    for (int tries = 0; done < bytes.size() && tries < 1000; ++tries) {
      const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
      if (n > 0) {
        done += static_cast<std::size_t>(n);
        continue;
      }
      if (n < 0 && errno != EAGAIN && errno != EINTR) return false;  // EIO: no reader on the line
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 1);
    }
    return done == bytes.size();
  }

  bool send_datagram(std::span<const std::uint8_t> bytes) {
    const ssize_t n = ::send(fd, bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(bytes.size())) return true;
    if (n < 0 && (errno == EPIPE || errno == ECONNRESET || errno == ENOTCONN)) link_closed = true;
    return false;
  }

  // One message of the description on this link: a CAN FD frame, classic CAN parts, a datagram
  // or bytes on the line.
  bool send_message(std::size_t message, std::span<const std::uint8_t> bytes, std::uint8_t sequence_byte) {
    const link::Message& m = cfg.link.messages[message];
    switch (cfg.link.transport) {
      case link::Transport::socketcan:
        if (cfg.framing == can::Framing::fd && m.can_id) return send_datagram(can::to_wire(can::fd_frame(*m.can_id, bytes)));
        if (cfg.framing == can::Framing::classic && m.classic_base_id) {
          bool ok = true;
          for (const auto& part : can::classic_frames(*m.classic_base_id, sequence_byte, bytes))
            ok = send_datagram(can::to_wire(part)) && ok;
          return ok;
        }
        return false;
      case link::Transport::udp: return send_datagram(bytes);
      case link::Transport::serial: {
        std::vector<std::uint8_t> junk;
        {
          std::lock_guard lock(garbage_mutex);
          junk.swap(garbage);
        }
        if (!junk.empty()) (void)write_stream(junk);
        return write_stream(bytes);
      }
    }
    return false;
  }

  void command(std::span<const std::uint8_t> bytes) {
    const auto is = [&](const std::optional<link::Command>& c) {
      return c && bytes.size() >= c->bytes.size() && std::equal(c->bytes.begin(), c->bytes.end(), bytes.begin());
    };
    if (is(cfg.link.start) && !streaming) {
      next_k = static_cast<std::int64_t>(std::floor(world.now_s() / dt_s)) + 1;
      next_temperature_s = static_cast<double>(next_k) * dt_s;
      next_identity_s = next_temperature_s;  // say who it is first
      streaming = true;
    } else if (is(cfg.link.stop)) {
      streaming = false;
    }
  }

  void read_commands() {
    for (;;) {
      std::uint8_t buf[512];
      const ssize_t n = cfg.link.transport == link::Transport::serial ? ::read(fd, buf, sizeof buf)
                                                                      : ::recv(fd, buf, sizeof buf, MSG_DONTWAIT);
      if (n <= 0) {
        if (n == 0 && cfg.link.transport == link::Transport::socketcan) link_closed = true;
        return;
      }
      const auto got = std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n));
      if (cfg.link.transport == link::Transport::socketcan) {
        const auto f = can::parse_wire(got);
        if (!f) continue;
        for (const auto& c : {cfg.link.start, cfg.link.stop})
          if (c && c->can_id == f->can_id) command(std::span<const std::uint8_t>(f->data.data(), f->len));
      } else if (cfg.link.transport == link::Transport::udp) {
        command(got);
      } else {
        // A byte stream: commands may arrive in pieces; look for each at every position.
        command_bytes.insert(command_bytes.end(), got.begin(), got.end());
        for (std::size_t p = 0; p < command_bytes.size(); ++p) command(std::span(command_bytes).subspan(p));
        const std::size_t keep = 16;
        if (command_bytes.size() > keep) command_bytes.erase(command_bytes.begin(), command_bytes.end() - keep);
      }
    }
  }

  void send_identity() {
    if (cfg.serial.empty()) return;
    link::Values v;
    v.serial = cfg.serial;
    for (std::size_t i = 0; i < cfg.link.messages.size(); ++i)
      if (cfg.link.messages[i].kind == link::MessageKind::identity) send_message(i, link::encode(cfg.link, i, v), 0);
  }

  void send_temperatures(double t_s) {
    const double base = temperature_C.load();
    link::Values v;
    v.sequence = temperature_sequence++;
    // Coil sensors spread a little around the block temperature, accelerometers a bit warmer.
    for (std::size_t j = 0; j < 24; ++j) v.coil_C[j] = base + 0.02 * static_cast<double>(j % 8) - 0.07;
    v.accel_sensor_C.fill(base + 0.5);
    for (std::size_t i = 0; i < cfg.link.messages.size(); ++i) {
      const link::Message& m = cfg.link.messages[i];
      if (m.kind != link::MessageKind::temperature) continue;
      v.time_raw = time_counts(m, t_s);
      send_message(i, link::encode(cfg.link, i, v), static_cast<std::uint8_t>(v.sequence));
    }
  }

  // The device time of world time t_s in counts of the message's time field (wrapped as it is).
  std::optional<std::uint64_t> time_counts(const link::Message& m, double t_s) const {
    const link::Field* f = m.find(link::Role::time);
    if (!f) return std::nullopt;
    const auto counts = static_cast<std::uint64_t>(std::llround(static_cast<double>(device_time_ns(t_s)) / f->scale.value_or(1.0)));
    return f->wrap ? counts % f->wrap : counts;
  }

  std::uint64_t device_time_ns(double world_s) const {
    const double ns = world.clock_s(world_s) * 1e9 * (1.0 + cfg.clock_drift_ppm * 1e-6);  // host seconds' ticks
    return static_cast<std::uint64_t>(std::llround(ns) + cfg.clock_offset_ns);
  }

  void run() {
    // A real IMU sends on its hardware clock. A thread's sleep ends up to the timer slack (50 us
    // by default) late, a different amount each time: the receive stamps then rarely showed the
    // link's own delay, and the driver's clock model (which rests on the prompt frames) had few
    // to rest on. 1 ns asks for the timer's own resolution.
    (void)::prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    const std::size_t sample = cfg.link.sample_message();
    const link::Message& sm = cfg.link.messages[sample];
    const link::Field* gyro_x = sm.find(link::Role::gyro_x);
    while (!stop) {
      if (close_requested && !link_closed) {
        // The thread closes its own descriptor, so no write can race the close.
        if (cfg.link.transport == link::Transport::serial) {
          ::close(fd);
          fd = -1;
        } else {
          ::shutdown(fd, SHUT_RDWR);
        }
        link_closed = true;
      }
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
        if (left <= 0 || stop || close_requested) break;
        std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<std::int64_t>(left, 20'000'000)));
      }
      if (stop) break;
      if (close_requested) continue;
      read_commands();
      if (!streaming || link_closed) continue;

      const ImuFrame f = produce(k);
      ++next_k;
      next_sequence += static_cast<std::uint32_t>(sequence_skip.exchange(0));
      const std::uint32_t seq = next_sequence++;
      link::Values v;
      v.sequence = seq;
      v.time_raw = time_counts(sm, t_k);
      v.status = link::status_ok(sm) ^ status_bits.load();
      std::array<double, 3> dtheta{}, dv{};
      for (std::size_t j = 0; j < 3; ++j) {
        dtheta[j] = f.dtheta_rad[static_cast<Eigen::Index>(j)];
        dv[j] = f.dv_mps[static_cast<Eigen::Index>(j)];
      }
      link::from_increments(sm, dtheta, dv, dt_s, v);
      const double temp = temperature_C.load();
      v.gyro_temp_C = temp;
      v.accel_temp_C = temp + 0.5;
      {
        // What the frame says, as the description decodes it: the truth the driver must deliver.
        const link::Decoded d = link::decode(cfg.link, link::encode(cfg.link, sample, v), sample);
        SampleTruth truth{seq, t_k, sample_host_ns, f.table_deg, {}, {}};
        link::to_increments(sm, d.values, dt_s, truth.dtheta_rad, truth.dv_mps);
        std::lock_guard lock(truth_mutex);
        const std::size_t i = seq % truth_ring.size();
        truth_ring[i] = truth;
        truth_valid[i] = true;
      }
      // The latency field is the age of the sample when the frame leaves, as a real IMU's: taken
      // after the work above (measured before it, every frame carried tens of microseconds more
      // delay than it declared, except when that work happened to be quick).
      const std::int64_t now = host_time_ns();
      v.latency_ns = static_cast<double>(std::max<std::int64_t>(0, (now - sample_host_ns) / 1000) * 1000);
      std::vector<std::uint8_t> bytes = link::encode(cfg.link, sample, v);
      if (const std::int64_t asked = pause_request_ns.exchange(0); asked > 0) {
        pause_began_ns = now;
        pause_until_ns = now + asked;
      }
      // Lost: what is due while it lasts. Frames held up until it began (a loaded machine) are
      // still sent, late, before the silence.
      bool skip_it = send_at >= pause_began_ns.load() && send_at < pause_until_ns.load();
      if (!skip_it && drop.load() > 0) {
        --drop;
        skip_it = true;
      }
      if (skip_it) {
        ++not_sent;
      } else {
        if (corrupt.load() > 0 && gyro_x) {
          --corrupt;
          bytes[gyro_x->offset + 1] = static_cast<std::uint8_t>(bytes[gyro_x->offset + 1] ^ 0x10);  // after the checksum
        }
        if (drop_byte.load() > 0 && gyro_x) {
          --drop_byte;
          bytes.erase(bytes.begin() + static_cast<std::ptrdiff_t>(gyro_x->offset));
        }
        if (send_message(sample, bytes, static_cast<std::uint8_t>(seq)))
          ++sent;
        else
          ++not_sent;
      }
      if (t_k >= next_identity_s && cfg.identity_period_s > 0.0) {
        if (now >= pause_until_ns.load()) send_identity();
        next_identity_s = t_k + cfg.identity_period_s;
      }
      if (cfg.temp_rate_hz > 0.0 && t_k >= next_temperature_s) {
        if (now >= pause_until_ns.load()) send_temperatures(t_k);
        next_temperature_s += 1.0 / cfg.temp_rate_hz;
        if (next_temperature_s < t_k) next_temperature_s = t_k + 1.0 / cfg.temp_rate_hz;
      }
    }
  }
};

SimImu::SimImu(SimWorld& world, int link_fd, SimImuConfig config)
    : impl_(std::make_unique<Impl>(world, link_fd, std::move(config))) {
  // On a socket pair the sender's buffer is the link's queue: room for seconds of frames, as a
  // CAN controller's receive queue plus the kernel's would hold (clamped by net.core.wmem_max).
  // (A pseudo-terminal has no such option: its queue is the tty buffer.)
  const int bytes = 4 << 20;
  (void)::setsockopt(link_fd, SOL_SOCKET, SO_SNDBUF, &bytes, sizeof bytes);
  if (impl_->cfg.link.transport == link::Transport::serial)
    (void)::fcntl(link_fd, F_SETFL, ::fcntl(link_fd, F_GETFL) | O_NONBLOCK);
  impl_->thread = std::thread([this] { impl_->run(); });
}

SimImu::~SimImu() {
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
  if (impl_->fd >= 0) ::close(impl_->fd);
}

double SimImu::gyro_lsb_rad_at(double rate_hz) noexcept { return Simulator::kGyroLsbAt1kHz_rad * 1000.0 / rate_hz; }
double SimImu::accel_lsb_mps_at(double rate_hz) noexcept { return Simulator::kAccelLsbAt1kHz_mps * 1000.0 / rate_hz; }
double SimImu::gyro_lsb_rad() const noexcept { return impl_->gyro_lsb; }
LinkImuConfig SimImu::driver_config() const {
  LinkImuConfig c;
  c.link = impl_->cfg.link;
  c.rate_hz = impl_->cfg.rate_hz;
  return c;
}
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
void SimImu::set_status_bits(std::uint64_t bits) { impl_->status_bits = bits; }
void SimImu::skip_sequence(int count) { impl_->sequence_skip = count; }
void SimImu::drop_byte_of_next_sample() { impl_->drop_byte = 1; }
void SimImu::drop_byte_of_next_samples(int count) { impl_->drop_byte = count; }
void SimImu::send_garbage(std::vector<std::uint8_t> bytes) {
  std::lock_guard lock(impl_->garbage_mutex);
  impl_->garbage.insert(impl_->garbage.end(), bytes.begin(), bytes.end());
}
void SimImu::pause(std::chrono::milliseconds duration) {
  impl_->pause_request_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(duration).count();
}
std::int64_t SimImu::pause_began_ns() const { return impl_->pause_began_ns.load(); }
void SimImu::close_link() { impl_->close_requested = true; }
void SimImu::set_temperature(double celsius) { impl_->temperature_C = celsius; }

}  // namespace imucal::sim
