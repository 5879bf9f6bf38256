// Device clock to host time base: host = offset + (1 + drift) * device, fitted from pairs of
// (device time tag, host time) observations whose host time carries an unknown, non-negative,
// jittery delay (SO_TIMESTAMP receive stamps of an IMU) or a symmetric error bounded by half a
// round trip (a table's reply to a request). Jitter must not reach the data: observations are
// grouped in blocks of device time, each block keeps its best point (smallest delay proxy), and
// a least-squares line is fitted through the best points of a sliding window. For one-sided
// delays only the prompt points count (those near the lower envelope: a whole block delayed by a
// loaded host does not tilt the line), and the line is then lowered onto the lowest point.
// docs/drivers.md gives the error.
// Pure: no clock is read here.
#pragma once

#include <cstdint>
#include <deque>

#include "drivers/interfaces.hpp"

namespace imucal::drivers {

struct ClockFitConfig {
  std::int64_t block_span_ns = 100'000'000;  // device time per block
  std::size_t window_blocks = 128;           // blocks in the fit (window = span * blocks)
  bool lower_envelope = true;                // one-sided delays (receive stamps)
  // With one-sided delays the drift comes from the block points within this of the lowest
  // tenth's height above the envelope: the prompt ones; with round trips, from those whose round
  // trip is within twice this of the lowest tenth's.
  std::int64_t prompt_tolerance_ns = 20'000;
  // An observation further than this from the model, beyond what its delay can explain, means
  // the device or host clock jumped: the fit restarts from that observation. What a delay
  // explains: with one-sided delays any lateness (a sender descheduled for half a second sends
  // its backlog late, and that must not restart the fit onto a late point), unless every
  // observation stays that late for late_confirm_ns of device time; with round trips, half the
  // observation's round trip.
  std::int64_t reset_threshold_ns = 50'000'000;
  std::int64_t late_confirm_ns = 2'000'000'000;
  // Round trips: a point's weight is 1 / (half its round trip)^2, the half taken at least this
  // (the host's own stamping error).
  std::int64_t round_trip_floor_ns = 20'000;
};

class ClockFit {
 public:
  explicit ClockFit(ClockFitConfig config = {}) : config_(config) {}

  // `key` ranks observations inside a block, smaller is better: host - device for receive
  // stamps (the delay plus a constant), the round-trip time for request/reply pairs (and then
  // bounds the observation's error: half of it).
  void add(std::int64_t device_ns, std::int64_t host_ns, std::int64_t key);
  bool valid() const noexcept { return have_model_; }
  std::int64_t map(std::int64_t device_ns) const noexcept;
  ClockModelState state() const noexcept;
  std::uint64_t resets() const noexcept { return resets_; }
  void clear() noexcept;

 private:
  struct Point {
    std::int64_t device_ns, host_ns, key;
  };
  void refit() noexcept;
  bool jumped(std::int64_t device_ns, std::int64_t host_ns, std::int64_t key) noexcept;
  double model_at(std::int64_t device_ns) const noexcept;  // host - ref_host, ns

  ClockFitConfig config_;
  std::deque<Point> blocks_;  // best point of each completed block
  Point current_{};
  bool have_current_ = false;
  std::int64_t block_start_ns_ = 0;
  bool have_model_ = false;
  std::int64_t ref_device_ns_ = 0, ref_host_ns_ = 0;
  double a_ns_ = 0.0, b_ = 1.0;  // host - ref_host = a + b (device - ref_device)
  double residual_rms_ns_ = 0.0;
  std::uint64_t resets_ = 0;
  bool late_ = false;  // one-sided: every observation since late_since_device_ns_ came late
  std::int64_t late_since_device_ns_ = 0;
};

}  // namespace imucal::drivers
