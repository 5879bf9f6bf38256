// The IMU driver for any link description (imu_link.hpp): frames arrive through a thin transport
// (SocketCAN, a serial line, UDP: imu_transport.hpp), are decoded by the pure codec
// (imu_codec.hpp), checked (checksum, header, length, finite values, status bits, the sequence
// counter unwrapped), stamped and mapped onto the host time base through a lower-envelope clock
// model of the IMU's own time tag (or of its sample count when the frame has no time field), so
// that receive jitter never reaches the sample times. Whatever is wrong on the wire is counted per
// run (from activate()) and never delivered as a sample: a frame lost to a checksum, a dropped
// byte or a counter jump shows as a sequence gap, which the daemon treats as a lost frame.
// poll() is meant for one thread; counters() and clock_model() may be called from any thread.
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include "drivers/clock_model.hpp"
#include "drivers/imu_link.hpp"
#include "drivers/imu_transport.hpp"
#include "drivers/interfaces.hpp"

namespace imucal::drivers {

struct LinkImuConfig {
  std::string name = "imu";
  link::ImuLink link;          // with per-unit LSBs resolved (link::resolve_per_unit_lsb)
  double rate_hz = 1000.0;     // the IMU's sample rate: the period of rate fields and of the count
  // No sample for this long (after activate) is a stalled stream.
  std::chrono::milliseconds stall_timeout{250};
  // The fixed part of the receive delay not covered by the IMU's latency field (transceiver,
  // driver, bus), measured once on the bench; subtracted before the fit (docs/drivers.md).
  std::int64_t transport_delay_ns = 0;
  // Named fields: a positional list silently shifted when a field was added to ClockFitConfig (the
  // reset threshold's 50 ms became the prompt tolerance, which turned the prompt filter off).
  ClockFitConfig clock{.block_span_ns = 100'000'000, .window_blocks = 128, .lower_envelope = true};
};

class LinkImu final : public Imu {
 public:
  LinkImu(std::unique_ptr<ImuTransport> transport, LinkImuConfig config);
  ~LinkImu() override;
  LinkImu(const LinkImu&) = delete;
  LinkImu& operator=(const LinkImu&) = delete;

  Result<void> connect() override;
  Result<void> configure() override;
  Result<void> activate() override;
  Result<void> safe_stop() override;
  void disconnect() noexcept override;
  DeviceState state() const override;
  std::string describe() const override;

  Result<void> poll(ImuBatch& out, std::chrono::milliseconds max_wait) override;
  ImuCounters counters() const override;
  ClockModelState clock_model() const override;
  std::optional<std::string> reported_serial() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers
