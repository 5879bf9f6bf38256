// The pure codec of an IMU link description (imu_link.hpp): frames to values and back, the
// checksums (Boost.CRC), the resynchronising decoder of a byte stream (serial lines), and the
// tracker that unwraps a short sequence counter and tells a gap from a stale frame. No I/O and no
// clock: the driver (link_imu.hpp), the simulated IMU (sim/sim_imu.hpp) and the fuzz tests share it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/imu_link.hpp"

namespace imucal::drivers::link {

// The values of one frame, in SI, as the fields give them: gyro and accelerometer in the unit's
// quantity (increments in rad and m/s, or rates in rad/s and m/s^2: see to_increments). Counters
// are raw. A temperature slot without a sensor (or a field) is NaN.
struct Values {
  std::array<double, 3> gyro{};
  std::array<double, 3> accel{};
  std::uint64_t status = 0;
  std::uint64_t sequence = 0;
  std::optional<std::uint64_t> time_raw;  // the IMU's time tag in counts of its field
  std::optional<double> latency_ns;
  double gyro_temp_C;
  double accel_temp_C;
  std::array<double, 24> coil_C;
  std::array<double, 3> accel_sensor_C;
  std::string serial;  // an identity message's serial number, without its padding
  Values();
};

enum class DecodeStatus {
  ok,
  bad_length,    // not the message's length
  bad_header,    // no message of the description starts with these bytes
  bad_checksum,
  bad_value,     // a float field that is not finite, a serial not printable: never a value
};
const char* to_string(DecodeStatus s) noexcept;

struct Decoded {
  DecodeStatus status = DecodeStatus::ok;
  std::size_t message = 0;  // index in link.messages (meaningful from bad_checksum on)
  Values values;
};

// The checksum of `bytes` (the covered range) with the message's parameters.
std::uint32_t checksum(const Checksum& c, std::span<const std::uint8_t> bytes) noexcept;

// One frame of `link`. `message`: the message it must be (a CAN identifier says so), or empty to
// find it by header. The checksum is checked before any field is read.
Decoded decode(const ImuLink& link, std::span<const std::uint8_t> frame, std::optional<std::size_t> message = std::nullopt);
// The frame of message `message` holding `v`: integers rounded from value / scale (saturated at
// the type's range), floats stored as value / scale; checksum last.
std::vector<std::uint8_t> encode(const ImuLink& link, std::size_t message, const Values& v);

// The sample's gyro and accelerometer values as increments over the sample period (rates times
// the period), and back: the one place where a rate becomes an increment.
void to_increments(const Message& m, const Values& v, double period_s, std::array<double, 3>& dtheta_rad,
                   std::array<double, 3>& dv_mps) noexcept;
void from_increments(const Message& m, const std::array<double, 3>& dtheta_rad, const std::array<double, 3>& dv_mps,
                     double period_s, Values& v) noexcept;
// The status bits that mean invalid data are set (or the bits that mean valid are clear).
bool status_fault(const Message& m, std::uint64_t status) noexcept;
// A status with every "valid" bit set and no fault bit: what a healthy IMU sends.
std::uint64_t status_ok(const Message& m) noexcept;
// The sequence counter's modulus (its `wrap`, else 2^bits of its type).
std::uint64_t sequence_modulus(const Message& m) noexcept;

// Finds frames in a byte stream: bytes before a header are garbage (counted), a frame whose
// checksum fails is dropped by one byte only, so a real header inside it is still found.
class StreamDecoder {
 public:
  explicit StreamDecoder(const ImuLink& link) : link_(link) {}
  void feed(std::span<const std::uint8_t> bytes);
  // The next decoded frame or error; empty when more bytes are needed.
  std::optional<Decoded> next();
  void reset() noexcept { buffer_.clear(); }
  std::uint64_t bytes_discarded() const noexcept { return discarded_; }  // garbage, all told
  std::uint64_t resyncs() const noexcept { return resyncs_; }           // runs of garbage skipped
  std::size_t buffered() const noexcept { return buffer_.size(); }

 private:
  const ImuLink& link_;
  std::vector<std::uint8_t> buffer_;
  std::uint64_t discarded_ = 0;
  std::uint64_t resyncs_ = 0;
};

// Unwraps a sequence counter of modulus `wrap` into a running count, and classifies each step.
// With a counter much shorter than a silence can last (KVH: 0..127), how many wraps a gap spans
// comes from the time that passed, in sample periods, measured on the IMU's clock when it has one.
class SequenceTracker {
 public:
  explicit SequenceTracker(std::uint64_t wrap) : wrap_(wrap) {}
  enum class Kind { first, next, gap, stale };
  struct Step {
    Kind kind = Kind::first;
    std::uint64_t lost = 0;       // samples missing before this one (gap)
    std::uint64_t count = 0;      // the running count of this sample (first: its raw value)
  };
  // `elapsed_periods`: time since the last accepted sample in sample periods (ignored when the
  // counter is 32 bits or more: it cannot wrap within a run). `in_order`: the link cannot duplicate
  // or reorder (a serial line), so a short counter's step back is a gap, never a stale frame.
  Step feed(std::uint64_t raw, double elapsed_periods, bool in_order = false) noexcept;
  void reset() noexcept { last_.reset(); }

 private:
  std::uint64_t wrap_;
  std::optional<std::uint64_t> last_;  // raw
  std::uint64_t count_ = 0;
};

}  // namespace imucal::drivers::link
