#include "drivers/can_imu.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <optional>

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace imucal::drivers {

using Clock = std::chrono::steady_clock;

Result<int> open_socketcan(const std::string& interface, bool fd_frames) {
  const std::string who = "cannot open CAN interface '" + interface + "': ";
  if (interface.empty() || interface.size() >= IFNAMSIZ)
    return {DriverErrc::invalid_argument, who + "an interface name has 1 to " + std::to_string(IFNAMSIZ - 1) + " characters"};
  const int s = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (s < 0) {
    const int e = errno;
    std::string why = std::string("socket(AF_CAN, SOCK_RAW, CAN_RAW) failed: ") + std::strerror(e);
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT)
      why += " (this kernel has no SocketCAN support; load the can and can_raw modules or use a machine with a CAN interface)";
    return {DriverErrc::connect_failed, who + why};
  }
  const unsigned index = ::if_nametoindex(interface.c_str());
  if (index == 0) {
    const int e = errno;
    ::close(s);
    return {DriverErrc::connect_failed, who + "no such network interface (" + std::strerror(e) + ")"};
  }
  if (fd_frames) {
    const int on = 1;
    if (::setsockopt(s, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) != 0) {
      const int e = errno;
      ::close(s);
      return {DriverErrc::connect_failed, who + "CAN FD frames not supported: " + std::strerror(e)};
    }
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(index);
  if (::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    const int e = errno;
    ::close(s);
    return {DriverErrc::connect_failed, who + "bind failed: " + std::strerror(e)};
  }
  return s;
}

struct CanImu::Impl {
  CanImuConfig cfg;
  int fd;
  DeviceState state = DeviceState::disconnected;
  bool link_lost = false;
  can::ClassicAssembler sample_parts{can::kIdSampleClassic};
  can::ClassicAssembler temperature_parts{can::kIdTemperatureClassic};
  ClockFit clock;
  ImuCounters counts;
  std::optional<std::uint32_t> last_sequence;
  Clock::time_point last_sample{};
  std::optional<can::TemperatureRecord> temperature_page0;

  mutable std::mutex published_mutex;  // what other threads may read
  ImuCounters published_counts;
  ClockModelState published_clock;

  Impl(int f, CanImuConfig c) : cfg(std::move(c)), fd(f), clock(cfg.clock) {}

  std::string who() const { return "imu '" + cfg.name + "' (CAN " + (cfg.framing == can::Framing::fd ? "FD" : "classic") + ")"; }

  void publish() {
    std::lock_guard lock(published_mutex);
    published_counts = counts;
    published_clock = clock.state();
  }

  Result<void> send_command(std::uint8_t command) {
    const auto wire = can::to_wire(can::command_frame(command));
    const ssize_t n = ::send(fd, wire.data(), wire.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n != static_cast<ssize_t>(wire.size())) {
      const int e = errno;
      if (n < 0 && (e == EPIPE || e == ECONNRESET || e == ENOTCONN)) {
        link_lost = true;
        return {DriverErrc::connection_lost, who() + ": link lost sending a command: " + std::strerror(e)};
      }
      return {DriverErrc::io_error, who() + ": cannot send a command: " + (n < 0 ? std::strerror(e) : "short write")};
    }
    return success();
  }

  void handle_record(const std::array<std::uint8_t, can::kRecordBytes>& bytes, std::int64_t rx_ns, ImuBatch& out) {
    can::Record rec;
    const can::DecodeStatus st = can::decode(bytes, rec);
    if (st == can::DecodeStatus::bad_crc) {
      ++counts.crc_failures;
      return;
    }
    if (st != can::DecodeStatus::ok) {
      ++counts.malformed_frames;
      return;
    }
    if (const auto* s = std::get_if<can::SampleRecord>(&rec)) {
      handle_sample(*s, rx_ns, out);
    } else {
      handle_temperature(std::get<can::TemperatureRecord>(rec), rx_ns, out);
    }
  }

  void handle_sample(const can::SampleRecord& r, std::int64_t rx_ns, ImuBatch& out) {
    if (last_sequence) {
      const std::uint32_t gap = r.sequence - (*last_sequence + 1u);  // modulo 2^32
      if (gap >= 0x80000000u) {
        // Older than the last one (duplicate or reordered): never deliver it after newer data.
        ++counts.malformed_frames;
        return;
      }
      if (gap > 0) {
        ++counts.sequence_gaps;
        counts.samples_lost += gap;
      }
    }
    last_sequence = r.sequence;
    last_sample = Clock::now();
    const auto dev = static_cast<std::int64_t>(r.device_time_ns);
    // The IMU says how long after its sample instant it started sending; what remains of the
    // receive delay is one-sided jitter on top of a fixed transport delay.
    const std::int64_t host = rx_ns - static_cast<std::int64_t>(r.latency_us) * 1000 - cfg.transport_delay_ns;
    clock.add(dev, host, host - dev);
    ImuSample s;
    s.sequence = r.sequence;
    s.device_time_ns = dev;
    s.t_ns = clock.map(dev);
    s.rx_ns = rx_ns;
    s.latency_us = r.latency_us;
    s.gyro_counts = r.gyro_counts;
    s.accel_counts = r.accel_counts;
    s.gyro_lsb_rad = cfg.gyro_lsb_rad;
    s.accel_lsb_mps = cfg.accel_lsb_mps;
    s.status = r.status;
    s.status_fault = (r.status & can::status::kFaultMask) != 0;
    s.gyro_temp_C = r.gyro_temp_cC == can::kNoTemperature ? std::nan("") : r.gyro_temp_cC * can::kTemperatureLsb_C;
    s.accel_temp_C = r.accel_temp_cC == can::kNoTemperature ? std::nan("") : r.accel_temp_cC * can::kTemperatureLsb_C;
    if (s.status_fault) ++counts.status_faults;
    ++counts.samples_delivered;
    out.samples.push_back(s);
  }

  void handle_temperature(const can::TemperatureRecord& r, std::int64_t rx_ns, ImuBatch& out) {
    if (r.page == 0) {
      if (temperature_page0) ++counts.malformed_frames;  // page 1 of the previous one never came
      temperature_page0 = r;
      return;
    }
    if (!temperature_page0 || temperature_page0->sequence != r.sequence) {
      ++counts.malformed_frames;
      temperature_page0.reset();
      return;
    }
    auto value = [](std::int16_t v) { return v == can::kNoTemperature ? std::nan("") : v * can::kTemperatureLsb_C; };
    ImuTemperatures t;
    t.device_time_ns = static_cast<std::int64_t>(temperature_page0->device_time_ns);
    t.t_ns = clock.valid() ? clock.map(t.device_time_ns) : rx_ns;
    for (std::size_t k = 0; k < 24; ++k) t.coil_C[k] = value(temperature_page0->values_cC[k]);
    for (std::size_t k = 0; k < 3; ++k) t.accel_C[k] = value(r.values_cC[k]);
    temperature_page0.reset();
    ++counts.temperature_messages;
    out.temperatures.push_back(t);
  }

  void handle_frame(const can::LinkFrame& f, std::int64_t rx_ns, ImuBatch& out) {
    if (f.fd && (f.can_id == can::kIdSampleFd || f.can_id == can::kIdTemperatureFd)) {
      if (f.len != can::kRecordBytes) {
        ++counts.malformed_frames;
        return;
      }
      std::array<std::uint8_t, can::kRecordBytes> b;
      std::memcpy(b.data(), f.data.data(), b.size());
      handle_record(b, rx_ns, out);
      return;
    }
    for (can::ClassicAssembler* as : {&sample_parts, &temperature_parts}) {
      if (!as->owns(f.can_id)) continue;
      const std::uint64_t before = as->incomplete();
      if (const auto rec = as->feed(f)) handle_record(*rec, rx_ns, out);
      counts.malformed_frames += as->incomplete() - before;
      return;
    }
    // Other identifiers belong to other nodes on the bus: not ours to count.
  }

  // Reads every frame already queued; false when the link is gone.
  bool drain(ImuBatch& out, Result<void>& error) {
    for (;;) {
      std::uint8_t buf[can::kCanFdMtu + 8];
      alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(timeval)) + 64];
      iovec iov{buf, sizeof buf};
      msghdr msg{};
      msg.msg_iov = &iov;
      msg.msg_iovlen = 1;
      msg.msg_control = control;
      msg.msg_controllen = sizeof control;
      const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT);
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK) return true;
        if (errno == EINTR) continue;
        const int e = errno;
        link_lost = true;
        error = Result<void>(DriverErrc::connection_lost, who() + ": receive failed: " + std::strerror(e));
        return false;
      }
      if (n == 0) {
        link_lost = true;
        error = Result<void>(DriverErrc::connection_lost, who() + ": the link was closed by the other end");
        return false;
      }
      std::int64_t rx_ns = 0;
      for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
        if (c->cmsg_level != SOL_SOCKET) continue;
        if (c->cmsg_type == SCM_TIMESTAMPNS) {
          timespec ts;
          std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
          rx_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
        } else if (c->cmsg_type == SCM_TIMESTAMP) {
          timeval tv;
          std::memcpy(&tv, CMSG_DATA(c), sizeof tv);
          rx_ns = static_cast<std::int64_t>(tv.tv_sec) * 1'000'000'000 + tv.tv_usec * 1000;
        }
      }
      if (rx_ns == 0) rx_ns = host_time_ns();  // no kernel stamp: the best we have
      ++counts.frames_received;
      const auto f = can::parse_wire(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)));
      if (!f) {
        ++counts.malformed_frames;
        continue;
      }
      handle_frame(*f, rx_ns, out);
    }
  }
};

CanImu::CanImu(int socket_fd, CanImuConfig config) : impl_(std::make_unique<Impl>(socket_fd, std::move(config))) {}

CanImu::~CanImu() {
  if (impl_->fd >= 0) ::close(impl_->fd);
}

std::string CanImu::describe() const { return impl_->who(); }

DeviceState CanImu::state() const {
  if (impl_->state != DeviceState::disconnected && impl_->link_lost) return DeviceState::faulted;
  return impl_->state;
}

ImuCounters CanImu::counters() const {
  std::lock_guard lock(impl_->published_mutex);
  return impl_->published_counts;
}

ClockModelState CanImu::clock_model() const {
  std::lock_guard lock(impl_->published_mutex);
  return impl_->published_clock;
}

Result<void> CanImu::connect() {
  Impl& m = *impl_;
  if (m.fd < 0 || ::fcntl(m.fd, F_GETFD) < 0) return {DriverErrc::connect_failed, m.who() + ": no open socket"};
  // Kernel receive stamps: nanoseconds if the kernel offers them, else microseconds.
  const int on = 1;
  if (::setsockopt(m.fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0 &&
      ::setsockopt(m.fd, SOL_SOCKET, SO_TIMESTAMP, &on, sizeof on) != 0)
    return {DriverErrc::connect_failed, m.who() + ": cannot enable receive time stamps: " + std::strerror(errno)};
  // A deep receive queue rides out scheduling hiccups of the polling thread without losing
  // frames (best effort: the kernel clamps it to net.core.rmem_max).
  const int bytes = 4 << 20;
  (void)::setsockopt(m.fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
  m.link_lost = false;
  m.state = DeviceState::connected;
  return success();
}

Result<void> CanImu::configure() {
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return {DriverErrc::invalid_state, m.who() + ": configure before connect"};
  if (!(m.cfg.rate_hz > 0.0) || !std::isfinite(m.cfg.rate_hz))
    return {DriverErrc::invalid_argument, m.who() + ": rate must be a positive number of Hz"};
  if (m.cfg.framing == can::Framing::classic && m.cfg.rate_hz > can::kClassicMaxRate_hz)
    return {DriverErrc::invalid_argument, m.who() + ": classic CAN carries at most " + std::to_string(static_cast<int>(can::kClassicMaxRate_hz)) +
                                              " samples/s (ten frames each); use CAN FD"};
  if (!(m.cfg.gyro_lsb_rad > 0.0) || !(m.cfg.accel_lsb_mps > 0.0))
    return {DriverErrc::invalid_argument, m.who() + ": scale factors (LSB) must be positive"};
  m.state = DeviceState::configured;
  return success();
}

Result<void> CanImu::activate() {
  Impl& m = *impl_;
  if (m.state != DeviceState::configured && m.state != DeviceState::active)
    return {DriverErrc::invalid_state, m.who() + ": activate before configure"};
  // A new run: counters, sequence and clock model start afresh; frames queued before the start
  // command belong to no run and are discarded.
  ImuBatch discard;
  Result<void> err;
  if (!m.drain(discard, err)) return err;
  m.counts = {};
  m.last_sequence.reset();
  m.temperature_page0.reset();
  m.sample_parts.reset();
  m.temperature_parts.reset();
  m.clock.clear();
  if (auto r = m.send_command(can::kCommandStart); !r) return r;
  m.last_sample = Clock::now();
  m.state = DeviceState::active;
  m.publish();
  return success();
}

Result<void> CanImu::safe_stop() {
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected || m.link_lost) return success();
  auto r = m.send_command(can::kCommandStop);
  if (r) m.state = DeviceState::configured;
  return r;
}

void CanImu::disconnect() noexcept {
  Impl& m = *impl_;
  if (m.fd >= 0) ::close(m.fd);
  m.fd = -1;
  m.state = DeviceState::disconnected;
}

Result<void> CanImu::poll(ImuBatch& out, std::chrono::milliseconds max_wait) {
  Impl& m = *impl_;
  if (m.state != DeviceState::active) return {DriverErrc::invalid_state, m.who() + ": poll before activate"};
  if (m.link_lost) return {DriverErrc::connection_lost, m.who() + ": link lost"};
  const std::size_t samples_before = out.samples.size(), temps_before = out.temperatures.size();
  const auto deadline = Clock::now() + max_wait;
  Result<void> err;
  bool first_wait = true;
  for (;;) {
    if (!m.drain(out, err)) {
      m.publish();
      return err;
    }
    if (out.samples.size() > samples_before || out.temperatures.size() > temps_before) break;
    const auto now = Clock::now();
    if (now >= deadline) break;
    // Wait for data up to the deadline, but wake when the stall timeout runs out so that a stall
    // is reported promptly; once stalled, keep waiting the full max_wait (no busy loop).
    auto left = deadline - now;
    const auto stall_left = m.cfg.stall_timeout - (now - m.last_sample);
    if (stall_left > Clock::duration::zero()) left = std::min(left, stall_left);
    else if (!first_wait) break;
    first_wait = false;
    pollfd p{m.fd, POLLIN, 0};
    const int wait_ms = static_cast<int>(std::chrono::ceil<std::chrono::milliseconds>(left).count());
    const int rc = ::poll(&p, 1, std::max(wait_ms, 1));
    if (rc < 0 && errno != EINTR) {
      const int e = errno;
      m.publish();
      return {DriverErrc::io_error, m.who() + ": poll failed: " + std::strerror(e)};
    }
  }
  const bool got_samples = out.samples.size() > samples_before;
  if (!got_samples && Clock::now() - m.last_sample > m.cfg.stall_timeout) {
    ++m.counts.stalls;
    m.publish();
    const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - m.last_sample).count();
    return {DriverErrc::stream_stalled, m.who() + ": no sample for " + std::to_string(ms) + " ms (stall timeout " +
                                            std::to_string(m.cfg.stall_timeout.count()) + " ms)"};
  }
  m.publish();
  return success();
}

}  // namespace imucal::drivers
