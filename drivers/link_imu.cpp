#include "drivers/link_imu.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <mutex>
#include <optional>

#include <poll.h>

#include "core/expect_value.hpp"
#include "drivers/imu_codec.hpp"

namespace imucal::drivers {

using Clock = std::chrono::steady_clock;

namespace {

// The counter's modulus as unsigned arithmetic sees it: 0 for a full 64-bit field.
std::uint64_t modulus_of(const link::Field& f) {
  if (f.wrap) return f.wrap;
  const std::size_t bits = 8 * link::type_size(f.type);
  return bits >= 64 ? 0 : std::uint64_t{1} << bits;
}

// The codec gives every frame of a message with a time field its time tag.
constexpr const char* kTimeTag = "the time tag of a frame whose message has a time field";

// A temperature set in progress: its sequence, which of its messages arrived, the values. At
// namespace scope: a nested type's member initialisers are not usable inside its enclosing class
// (clang refuses the emplace() below there; the static check compiles with clang).
struct PendingSet {
  std::optional<std::uint64_t> sequence;
  std::vector<bool> got;
  ImuTemperatures t;
  bool has_time = false;
};

}  // namespace

struct LinkImu::Impl {
  LinkImuConfig cfg;
  std::unique_ptr<ImuTransport> transport;
  link::StreamDecoder stream;
  const link::Message& sample;
  const link::Field* time_field;
  std::uint64_t time_modulus = 0;
  double period_ns;
  link::SequenceTracker sequence;
  DeviceState state = DeviceState::disconnected;
  bool link_lost = false;
  ClockFit clock;
  ImuCounters counts;
  Clock::time_point last_sample{};
  std::int64_t last_rx_ns = 0;
  // A byte stream's rx stamps are read times: a frame stamped late may have waited in the line's
  // buffer while the reader was descheduled. Only silence the driver saw (a drain that found the
  // line empty, stamped before it read) shows that time passed on the IMU's side.
  std::int64_t silent_until_ns = 0;
  Clock::duration longest_wait = Clock::duration::max();
  std::optional<std::uint64_t> last_time_raw;  // of the last accepted sample
  std::uint64_t time_ext = 0;                  // its time field, unwrapped, in field counts
  std::uint64_t transport_malformed = 0;       // the transport's count at activate()

  std::optional<PendingSet> pending;

  mutable std::mutex published_mutex;  // what other threads may read
  ImuCounters published_counts;
  ClockModelState published_clock;
  std::optional<std::string> serial;  // as the IMU last reported it (under published_mutex)

  Impl(std::unique_ptr<ImuTransport> t, LinkImuConfig c)
      : cfg(std::move(c)),
        transport(std::move(t)),
        stream(cfg.link),
        sample(cfg.link.messages[cfg.link.sample_message()]),
        time_field(sample.find(link::Role::time)),
        period_ns(1e9 / cfg.rate_hz),
        sequence(link::sequence_modulus(sample)),
        clock(cfg.clock) {
    if (time_field) time_modulus = modulus_of(*time_field);
    // A short counter on a line without time tags counts its wraps from the silence the driver
    // watched, known to within one wait: keep each wait under a quarter of a wrap.
    const std::uint64_t wrap = link::sequence_modulus(sample);
    if (cfg.link.stream() && !time_field && wrap != 0 && wrap <= 1u << 16)
      longest_wait = std::chrono::nanoseconds(static_cast<std::int64_t>(period_ns * static_cast<double>(wrap) / 4.0));
  }

  std::string who() const { return "imu '" + cfg.name + "' (" + cfg.link.name + " over " + transport->describe() + ")"; }

  void publish() {
    std::lock_guard lock(published_mutex);
    published_counts = counts;
    published_clock = clock.state();
  }

  bool is_sample(const link::Decoded& d) const {
    return d.status == link::DecodeStatus::ok && cfg.link.messages[d.message].kind == link::MessageKind::sample;
  }

  // `read_after`: samples read after this one in the same drain. They were waiting together, so
  // this one came at least that many periods before its stamp.
  void handle(const link::Decoded& d, std::int64_t rx_ns, ImuBatch& out, std::size_t read_after = 0) {
    ++counts.frames_received;
    if (d.status == link::DecodeStatus::bad_checksum) {
      ++counts.crc_failures;
      return;
    }
    if (d.status != link::DecodeStatus::ok) {
      ++counts.malformed_frames;
      return;
    }
    switch (cfg.link.messages[d.message].kind) {
      case link::MessageKind::sample: handle_sample(d.values, rx_ns, read_after, out); break;
      case link::MessageKind::temperature: handle_temperature(d.message, d.values, rx_ns, out); break;
      case link::MessageKind::identity: {
        std::lock_guard lock(published_mutex);
        serial = d.values.serial;
        break;
      }
    }
  }

  void handle_sample(const link::Values& v, std::int64_t rx_ns, std::size_t read_after, ImuBatch& out) {
    // Time since the last sample in periods: on the IMU's clock when the frame carries it. Else,
    // for datagrams, from their kernel stamps. For a byte stream, from the silence the driver
    // watched after the last sample: a reader stalled for longer than a 7-bit counter's wrap
    // reads frames that waited in the line's buffer (or behind a writer that waited for the
    // reader), and they must not be taken for 128 lost samples. Frames read together after a
    // watched silence also waited together: a late burst is not a gap.
    const double since_ns = static_cast<double>((cfg.link.stream() ? silent_until_ns : rx_ns) - last_rx_ns);
    double elapsed_periods = std::max(0.0, since_ns / period_ns - static_cast<double>(read_after));
    std::uint64_t time_delta = 0;
    if (time_field && last_time_raw) {
      const std::uint64_t raw = expect_value(v.time_raw, kTimeTag), last = *last_time_raw;
      time_delta = time_modulus ? (raw % time_modulus + time_modulus - last % time_modulus) % time_modulus : raw - last;
      const std::uint64_t half = time_modulus ? time_modulus / 2 : std::uint64_t{1} << 63;
      if (time_delta >= half) {
        ++counts.malformed_frames;  // its time tag runs backwards: stale or reordered
        return;
      }
      elapsed_periods = static_cast<double>(time_delta) * time_field->scale.value_or(1.0) / period_ns;
    }
    // A line delivers bytes in order: a frame on it is never a duplicate or a reordered one.
    const link::SequenceTracker::Step step = sequence.feed(v.sequence, elapsed_periods, cfg.link.stream());
    if (step.kind == link::SequenceTracker::Kind::stale) {
      // Older than the last one (duplicate or reordered): never deliver it after newer data.
      ++counts.malformed_frames;
      return;
    }
    if (step.kind == link::SequenceTracker::Kind::gap) {
      ++counts.sequence_gaps;
      counts.samples_lost += step.lost;
    }
    last_rx_ns = rx_ns;
    last_sample = Clock::now();
    std::int64_t dev = 0;
    if (time_field) {
      time_ext = last_time_raw ? time_ext + time_delta : expect_value(v.time_raw, kTimeTag);
      last_time_raw = v.time_raw;
      dev = std::llround(static_cast<double>(time_ext) * time_field->scale.value_or(1.0));
    } else {
      // No time tag: the IMU's sample clock is its clock, one period per counted sample.
      dev = std::llround(static_cast<double>(step.count) * period_ns);
    }
    const auto latency_ns = static_cast<std::int64_t>(std::llround(v.latency_ns.value_or(0.0)));
    // What remains of the receive delay after the IMU's own latency is one-sided jitter on top of
    // a fixed transport delay.
    const std::int64_t host = rx_ns - latency_ns - cfg.transport_delay_ns;
    clock.add(dev, host, host - dev);
    ImuSample s;
    s.sequence = static_cast<std::uint32_t>(step.count);
    s.device_time_ns = dev;
    s.t_ns = clock.map(dev);
    s.rx_ns = rx_ns;
    s.latency_us = static_cast<std::uint32_t>(std::clamp<std::int64_t>(latency_ns / 1000, 0, UINT32_MAX));
    link::to_increments(sample, v, 1.0 / cfg.rate_hz, s.dtheta_rad, s.dv_mps);
    s.status = v.status;
    s.status_fault = link::status_fault(sample, v.status);
    s.gyro_temp_C = v.gyro_temp_C;
    s.accel_temp_C = v.accel_temp_C;
    if (s.status_fault) ++counts.status_faults;
    ++counts.samples_delivered;
    out.samples.push_back(s);
  }

  // Temperature messages come in sets (pages sharing a sequence); a set is delivered when its
  // completing message arrives after every other one of the same sequence.
  void handle_temperature(std::size_t index, const link::Values& v, std::int64_t rx_ns, ImuBatch& out) {
    const link::Message& m = cfg.link.messages[index];
    const std::optional<std::uint64_t> seq = m.find(link::Role::sequence) ? std::optional(v.sequence) : std::nullopt;
    if (pending && pending->sequence != seq) {
      ++counts.malformed_frames;  // the set before never completed
      pending.reset();
    }
    if (!pending) {
      pending.emplace();
      pending->sequence = seq;
      pending->got.assign(cfg.link.messages.size(), false);
      pending->t.coil_C.fill(std::nan(""));
      pending->t.accel_C.fill(std::nan(""));
    }
    PendingSet& p = *pending;
    for (const link::Field& f : m.fields) {
      for (std::size_t k = f.index; k < f.index + f.count; ++k) {
        if (f.role == link::Role::coil_temperature) p.t.coil_C[k] = v.coil_C[k];
        if (f.role == link::Role::accel_sensor_temperature) p.t.accel_C[k] = v.accel_sensor_C[k];
      }
    }
    if (const link::Field* tf = m.find(link::Role::time); tf && !p.has_time) {
      p.t.device_time_ns = std::llround(static_cast<double>(expect_value(v.time_raw, kTimeTag)) * tf->scale.value_or(1.0));
      p.has_time = true;
    }
    if (!p.has_time) p.t.device_time_ns = 0;
    p.got[index] = true;
    if (!m.completes) return;
    bool complete = true;
    for (std::size_t i = 0; i < cfg.link.messages.size(); ++i)
      if (cfg.link.messages[i].kind == link::MessageKind::temperature && !p.got[i]) complete = false;
    if (!complete) {
      ++counts.malformed_frames;  // a page of the set is missing
      pending.reset();
      return;
    }
    p.t.t_ns = p.has_time && clock.valid() ? clock.map(p.t.device_time_ns) : rx_ns;
    ++counts.temperature_messages;
    out.temperatures.push_back(p.t);
    pending.reset();
  }

  // Reads and decodes every chunk already queued; false when the link is gone.
  bool drain(ImuBatch& out, Result<void>& error) {
    std::vector<LinkChunk> chunks;
    const std::int64_t before_ns = host_time_ns();
    const Result<void> r = transport->drain(chunks);
    if (r && chunks.empty()) silent_until_ns = before_ns;
    std::vector<std::pair<link::Decoded, std::int64_t>> on_line;  // a byte stream's frames, as read
    for (const LinkChunk& c : chunks) {
      if (cfg.link.stream()) {
        const std::uint64_t resyncs = stream.resyncs(), discarded = stream.bytes_discarded();
        stream.feed(c.bytes);
        // Not `while (auto d = stream.next())`: clang-tidy 16's optional-access check does not see
        // the test of a while loop's condition variable (nor of a for loop's condition).
        for (;;) {
          auto d = stream.next();
          if (!d) break;
          on_line.emplace_back(std::move(*d), c.rx_ns);
        }
        counts.resyncs += stream.resyncs() - resyncs;
        counts.bytes_discarded += stream.bytes_discarded() - discarded;
      } else {
        handle(link::decode(cfg.link, c.bytes, c.message), c.rx_ns, out);
      }
    }
    std::size_t samples_after = 0;
    for (const auto& [d, rx_ns] : on_line) samples_after += is_sample(d) ? 1 : 0;
    for (const auto& [d, rx_ns] : on_line) {
      if (is_sample(d)) --samples_after;
      handle(d, rx_ns, out, samples_after);
    }
    const std::uint64_t transport_now = transport->malformed();
    counts.malformed_frames += transport_now - transport_malformed;
    transport_malformed = transport_now;
    if (!r) {
      link_lost = r.code() == DriverErrc::connection_lost;
      error = Result<void>(r.code(), who() + ": " + r.error().message);
      return false;
    }
    return true;
  }
};

LinkImu::LinkImu(std::unique_ptr<ImuTransport> transport, LinkImuConfig config)
    : impl_(std::make_unique<Impl>(std::move(transport), std::move(config))) {}

LinkImu::~LinkImu() { impl_->transport->close(); }

std::string LinkImu::describe() const { return impl_->who(); }

DeviceState LinkImu::state() const {
  if (impl_->state != DeviceState::disconnected && impl_->link_lost) return DeviceState::faulted;
  return impl_->state;
}

ImuCounters LinkImu::counters() const {
  std::lock_guard lock(impl_->published_mutex);
  return impl_->published_counts;
}

std::optional<std::string> LinkImu::reported_serial() const {
  std::lock_guard lock(impl_->published_mutex);
  return impl_->serial;
}

ClockModelState LinkImu::clock_model() const {
  std::lock_guard lock(impl_->published_mutex);
  return impl_->published_clock;
}

Result<void> LinkImu::connect() {
  Impl& m = *impl_;
  if (auto r = m.transport->open(); !r) return r;
  m.link_lost = false;
  m.state = DeviceState::connected;
  return success();
}

Result<void> LinkImu::configure() {
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected) return {DriverErrc::invalid_state, m.who() + ": configure before connect"};
  if (!(m.cfg.rate_hz > 0.0) || !std::isfinite(m.cfg.rate_hz))
    return {DriverErrc::invalid_argument, m.who() + ": rate must be a positive number of Hz"};
  if (const auto max = m.transport->max_rate_hz(); max && m.cfg.rate_hz > *max) {
    char text[160];
    std::snprintf(text, sizeof text, ": the link carries at most %.0f samples/s of %zu-byte frames; the IMU is configured for %g Hz",
                  std::floor(*max), m.sample.length, m.cfg.rate_hz);
    return {DriverErrc::invalid_argument, m.who() + text};
  }
  for (const link::Field& f : m.sample.fields)
    if (!f.scale) return {DriverErrc::invalid_argument, m.who() + ": the per-unit LSB of " + link::to_string(f.role) + " was not given"};
  m.state = DeviceState::configured;
  return success();
}

Result<void> LinkImu::activate() {
  Impl& m = *impl_;
  if (m.state != DeviceState::configured && m.state != DeviceState::active)
    return {DriverErrc::invalid_state, m.who() + ": activate before configure"};
  // A new run: counters, sequence and clock model start afresh; frames queued before the start
  // belong to no run and are discarded.
  ImuBatch discard;
  Result<void> err;
  if (!m.drain(discard, err)) return err;
  m.stream.reset();
  m.transport->reset();
  m.counts = {};
  m.sequence.reset();
  m.last_time_raw.reset();
  m.pending.reset();
  m.clock.clear();
  if (m.cfg.link.start) {
    if (auto r = m.transport->send(*m.cfg.link.start); !r) {
      m.link_lost = r.code() == DriverErrc::connection_lost;
      return Result<void>(r.code(), m.who() + ": start: " + r.error().message);
    }
  }
  m.last_sample = Clock::now();
  m.last_rx_ns = host_time_ns();
  m.silent_until_ns = m.last_rx_ns;
  m.state = DeviceState::active;
  m.publish();
  return success();
}

Result<void> LinkImu::safe_stop() {
  Impl& m = *impl_;
  if (m.state == DeviceState::disconnected || m.link_lost) return success();
  if (m.cfg.link.stop) {
    if (auto r = m.transport->send(*m.cfg.link.stop); !r) {
      m.link_lost = r.code() == DriverErrc::connection_lost;
      return Result<void>(r.code(), m.who() + ": stop: " + r.error().message);
    }
  }
  m.state = DeviceState::configured;
  return success();
}

void LinkImu::disconnect() noexcept {
  impl_->transport->close();
  impl_->state = DeviceState::disconnected;
}

Result<void> LinkImu::poll(ImuBatch& out, std::chrono::milliseconds max_wait) {
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
    if (stall_left > Clock::duration::zero()) left = std::min({left, stall_left, m.longest_wait});
    else if (!first_wait) break;
    first_wait = false;
    pollfd p{m.transport->wait_handle(), POLLIN, 0};
    const int wait_ms = static_cast<int>(std::chrono::ceil<std::chrono::milliseconds>(left).count());
    const int rc = ::poll(&p, 1, std::max(wait_ms, 1));
    if (rc < 0 && errno != EINTR) {
      const int e = errno;
      m.publish();
      return {DriverErrc::io_error, m.who() + ": poll failed: " + std::strerror(e)};
    }
    // A hung-up line with nothing left to read: the next drain reports it.
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
