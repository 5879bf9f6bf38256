// IMU driver over SocketCAN (CAN FD, or the classic-CAN fallback), per can_protocol.hpp. The
// driver takes an already-open socket (a CAN_RAW socket from open_socketcan(), or in tests one
// end of socketpair(AF_UNIX, SOCK_SEQPACKET) carrying the same struct can(fd)_frame bytes), reads
// it with kernel receive stamps (SO_TIMESTAMPNS, the nanosecond form of SO_TIMESTAMP) and maps
// each sample's device time tag onto the host time base through a lower-envelope clock model,
// so that receive jitter never reaches the sample times. Sequence gaps, CRC failures, malformed
// frames and status faults are counted per run (from activate()).
// poll() is meant for one thread; counters() and clock_model() may be called from any thread.
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include "drivers/can_protocol.hpp"
#include "drivers/clock_model.hpp"
#include "drivers/interfaces.hpp"

namespace imucal::drivers {

struct CanImuConfig {
  std::string name = "imu";
  can::Framing framing = can::Framing::fd;
  double rate_hz = 1000.0;         // the IMU's sample rate (classic framing: at most 200 Hz)
  double gyro_lsb_rad = 1e-11;     // scale factors: one count of the increments
  double accel_lsb_mps = 1e-10;
  // No sample for this long (after activate) is a stalled stream.
  std::chrono::milliseconds stall_timeout{250};
  // The fixed part of the receive delay not covered by the IMU's latency field (transceiver,
  // driver, bus), measured once on the bench; subtracted before the fit (docs/drivers.md).
  std::int64_t transport_delay_ns = 0;
  ClockFitConfig clock{100'000'000, 128, true, 50'000'000};
};

// Opens a CAN_RAW socket bound to `interface` (CAN FD frames enabled when fd_frames). On failure
// the message names the interface and the reason (e.g. a kernel without AF_CAN support).
Result<int> open_socketcan(const std::string& interface, bool fd_frames);

class CanImu final : public Imu {
 public:
  // Takes ownership of socket_fd (closed by disconnect() or the destructor).
  CanImu(int socket_fd, CanImuConfig config);
  ~CanImu() override;
  CanImu(const CanImu&) = delete;
  CanImu& operator=(const CanImu&) = delete;

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

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::drivers
