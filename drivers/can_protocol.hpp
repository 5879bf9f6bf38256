// The IMU's CAN wire format (docs/drivers.md, "IMU over CAN FD"): one 64-byte record per sample
// (big-endian, CRC-32 last), a 64-byte temperature record in two pages at a lower rate, the
// host's start/stop command, and the classic-CAN fallback that cuts each record into ten 8-byte
// frames sharing the sample's sequence byte. Pure encode/decode, no sockets: the driver, the
// simulated IMU and the fuzz tests use the same code. Frames on the wire are the kernel's
// `struct can_frame` (16 bytes) and `struct canfd_frame` (72 bytes) of <linux/can.h>.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <variant>
#include <vector>

namespace imucal::drivers::can {

// One 64-byte CAN FD frame per record, or the classic-CAN fallback (ten 8-byte frames).
enum class Framing { fd, classic };
inline constexpr double kClassicMaxRate_hz = 200.0;

inline constexpr std::size_t kRecordBytes = 64;
inline constexpr std::size_t kCrcOffset = 60;         // CRC-32 over bytes [0, 60), stored at 60
inline constexpr std::size_t kCanMtu = 16;            // sizeof(struct can_frame)
inline constexpr std::size_t kCanFdMtu = 72;          // sizeof(struct canfd_frame)
inline constexpr std::size_t kClassicParts = 10;      // 64 bytes in 7-byte slices
inline constexpr std::size_t kClassicSliceBytes = 7;

// 11-bit identifiers.
inline constexpr std::uint32_t kIdCommand = 0x080;         // host -> IMU, classic, 8 bytes
inline constexpr std::uint32_t kIdSampleFd = 0x100;        // IMU -> host, CAN FD, 64 bytes
inline constexpr std::uint32_t kIdTemperatureFd = 0x101;
inline constexpr std::uint32_t kIdSampleClassic = 0x110;   // + part 0..9
inline constexpr std::uint32_t kIdTemperatureClassic = 0x130;

inline constexpr std::uint8_t kTypeSample = 0x01;
inline constexpr std::uint8_t kTypeTemperature = 0x02;
inline constexpr std::uint8_t kLayoutVersion = 1;

inline constexpr std::uint8_t kCommandStart = 0x01;
inline constexpr std::uint8_t kCommandStop = 0x02;

// Status bits of a sample. The low byte holds faults (data suspect), the high byte information.
namespace status {
inline constexpr std::uint16_t kGyroFault = 0x0001;
inline constexpr std::uint16_t kAccelFault = 0x0002;
inline constexpr std::uint16_t kTemperatureFault = 0x0004;
inline constexpr std::uint16_t kOverRange = 0x0008;
inline constexpr std::uint16_t kBuiltInTestFail = 0x0010;
inline constexpr std::uint16_t kFaultMask = 0x00FF;
inline constexpr std::uint16_t kWarmingUp = 0x0100;
}  // namespace status

inline constexpr std::int16_t kNoTemperature = INT16_MIN;  // 0x8000: sensor absent
inline constexpr double kTemperatureLsb_C = 0.01;

struct SampleRecord {
  std::uint16_t status = 0;
  std::uint32_t sequence = 0;
  std::uint32_t latency_us = 0;
  std::uint64_t device_time_ns = 0;
  std::array<std::int32_t, 3> gyro_counts{};
  std::array<std::int32_t, 3> accel_counts{};
  std::int16_t gyro_temp_cC = 0;   // hundredths of a degree Celsius
  std::int16_t accel_temp_cC = 0;
};

// Page 0: the 24 FOG coil sensors (gyro x 0..7, y 0..7, z 0..7). Page 1: accelerometers x y z in
// values[0..2], the rest kNoTemperature. Both pages of one measurement share the sequence.
struct TemperatureRecord {
  std::uint8_t page = 0;
  std::uint16_t sequence = 0;
  std::uint64_t device_time_ns = 0;
  std::array<std::int16_t, 24> values_cC{};
};

using Record = std::variant<SampleRecord, TemperatureRecord>;

enum class DecodeStatus { ok, bad_length, bad_crc, bad_type, bad_version, bad_field };

// CRC-32 (IEEE 802.3: poly 0x04C11DB7, init and final xor 0xFFFFFFFF, reflected; check value of
// "123456789" is 0xCBF43926), i.e. boost::crc_32_type.
std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept;

std::array<std::uint8_t, kRecordBytes> encode(const SampleRecord& r) noexcept;
std::array<std::uint8_t, kRecordBytes> encode(const TemperatureRecord& r) noexcept;
DecodeStatus decode(std::span<const std::uint8_t> bytes, Record& out) noexcept;

// A frame as read from or written to a CAN_RAW socket (with CAN_RAW_FD_FRAMES on).
struct LinkFrame {
  std::uint32_t can_id = 0;  // 11-bit identifier (flags stripped)
  bool fd = false;
  std::uint8_t len = 0;
  std::array<std::uint8_t, 64> data{};
};

// Parses the bytes of one read: 16 bytes = can_frame, 72 = canfd_frame. Empty for any other
// size, an extended/RTR/error frame, or a length code beyond the frame type's maximum.
std::optional<LinkFrame> parse_wire(std::span<const std::uint8_t> bytes) noexcept;
std::vector<std::uint8_t> to_wire(const LinkFrame& frame);

LinkFrame fd_frame(std::uint32_t can_id, const std::array<std::uint8_t, kRecordBytes>& record) noexcept;
std::array<LinkFrame, kClassicParts> classic_frames(std::uint32_t base_id, std::uint8_t sequence_byte,
                                                    const std::array<std::uint8_t, kRecordBytes>& record) noexcept;
LinkFrame command_frame(std::uint8_t command) noexcept;

// Reassembles one classic-CAN record stream (one base id). Parts must arrive in order with the
// same sequence byte; anything else abandons the record in progress (counted as incomplete) so
// that parts of two samples are never mixed.
class ClassicAssembler {
 public:
  explicit ClassicAssembler(std::uint32_t base_id) : base_id_(base_id) {}
  bool owns(std::uint32_t can_id) const noexcept {
    return can_id >= base_id_ && can_id < base_id_ + kClassicParts;
  }
  // Feeds one frame of this stream; returns the record when its last part arrived.
  std::optional<std::array<std::uint8_t, kRecordBytes>> feed(const LinkFrame& frame) noexcept;
  std::uint64_t incomplete() const noexcept { return incomplete_; }
  void reset() noexcept { expected_part_ = 0; in_progress_ = false; }

 private:
  std::uint32_t base_id_;
  std::array<std::uint8_t, kRecordBytes> buffer_{};
  std::size_t expected_part_ = 0;
  std::uint8_t sequence_byte_ = 0;
  bool in_progress_ = false;
  std::uint64_t incomplete_ = 0;
};

}  // namespace imucal::drivers::can
