// SocketCAN frames as imucal's IMU links carry them (docs/drivers.md, "IMU links"): the kernel's
// `struct can_frame` (16 bytes) and `struct canfd_frame` (72 bytes) images, one message of an IMU
// link description per CAN FD frame, and the classic-CAN fallback that cuts a message into 8-byte
// frames (identifier base + part, data byte 0 the low byte of the sample's sequence, then 7 bytes
// of the message) and puts it back together. Pure, no sockets: the driver's transport, the
// simulated IMU and the fuzz tests use the same code. What the bytes of a message mean is the
// description's business (imu_link.hpp, imu_codec.hpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace imucal::drivers::can {

// One CAN FD frame per message, or the classic-CAN fallback (a message in 7-byte slices).
enum class Framing { fd, classic };
// Ten classic frames per 64-byte sample: a 1 Mbit/s bus carries about 200 samples/s.
inline constexpr double kClassicMaxRate_hz = 200.0;

inline constexpr std::size_t kCanMtu = 16;            // sizeof(struct can_frame)
inline constexpr std::size_t kCanFdMtu = 72;          // sizeof(struct canfd_frame)
inline constexpr std::size_t kMaxFdBytes = 64;
inline constexpr std::size_t kClassicSliceBytes = 7;

// Classic frames needed for a message of `length` bytes.
constexpr std::size_t classic_parts(std::size_t length) noexcept { return (length + kClassicSliceBytes - 1) / kClassicSliceBytes; }

// A frame as read from or written to a CAN_RAW socket (with CAN_RAW_FD_FRAMES on).
struct LinkFrame {
  std::uint32_t can_id = 0;  // 11-bit identifier (flags stripped)
  bool fd = false;
  std::uint8_t len = 0;
  std::array<std::uint8_t, kMaxFdBytes> data{};
};

// Parses the bytes of one read: 16 bytes = can_frame, 72 = canfd_frame. Empty for any other
// size, an extended/RTR/error frame, or a length code beyond the frame type's maximum.
std::optional<LinkFrame> parse_wire(std::span<const std::uint8_t> bytes) noexcept;
std::vector<std::uint8_t> to_wire(const LinkFrame& frame);

// A CAN FD frame holding `bytes` (at most 64), or a classic one (at most 8).
LinkFrame fd_frame(std::uint32_t can_id, std::span<const std::uint8_t> bytes) noexcept;
LinkFrame classic_frame(std::uint32_t can_id, std::span<const std::uint8_t> bytes) noexcept;
std::vector<LinkFrame> classic_frames(std::uint32_t base_id, std::uint8_t sequence_byte, std::span<const std::uint8_t> message);

// Reassembles one classic-CAN message stream (one base id). Parts must arrive in order with the
// same sequence byte; anything else abandons the message in progress (counted as incomplete) so
// that parts of two samples are never mixed.
class ClassicAssembler {
 public:
  ClassicAssembler(std::uint32_t base_id, std::size_t message_length)
      : base_id_(base_id), length_(message_length), parts_(classic_parts(message_length)), buffer_(message_length) {}
  bool owns(std::uint32_t can_id) const noexcept { return can_id >= base_id_ && can_id < base_id_ + parts_; }
  // Feeds one frame of this stream; returns the message when its last part arrived.
  std::optional<std::vector<std::uint8_t>> feed(const LinkFrame& frame);
  std::uint64_t incomplete() const noexcept { return incomplete_; }
  void reset() noexcept { expected_part_ = 0; in_progress_ = false; }

 private:
  std::uint32_t base_id_;
  std::size_t length_;
  std::size_t parts_;
  std::vector<std::uint8_t> buffer_;
  std::size_t expected_part_ = 0;
  std::uint8_t sequence_byte_ = 0;
  bool in_progress_ = false;
  std::uint64_t incomplete_ = 0;
};

}  // namespace imucal::drivers::can
