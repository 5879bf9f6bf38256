#include "drivers/can_protocol.hpp"

#include <algorithm>
#include <cstring>

#include <linux/can.h>

namespace imucal::drivers::can {

static_assert(sizeof(struct can_frame) == kCanMtu);
static_assert(sizeof(struct canfd_frame) == kCanFdMtu);

std::optional<LinkFrame> parse_wire(std::span<const std::uint8_t> bytes) noexcept {
  LinkFrame f;
  if (bytes.size() == kCanFdMtu) {
    struct canfd_frame cf;
    std::memcpy(&cf, bytes.data(), sizeof cf);
    if (cf.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) return std::nullopt;
    if (cf.len > CANFD_MAX_DLEN) return std::nullopt;
    f.fd = true;
    f.can_id = cf.can_id & CAN_SFF_MASK;
    f.len = cf.len;
    std::memcpy(f.data.data(), cf.data, cf.len);
    return f;
  }
  if (bytes.size() == kCanMtu) {
    struct can_frame cf;
    std::memcpy(&cf, bytes.data(), sizeof cf);
    if (cf.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) return std::nullopt;
    if (cf.len > CAN_MAX_DLEN) return std::nullopt;
    f.fd = false;
    f.can_id = cf.can_id & CAN_SFF_MASK;
    f.len = cf.len;
    std::memcpy(f.data.data(), cf.data, cf.len);
    return f;
  }
  return std::nullopt;
}

std::vector<std::uint8_t> to_wire(const LinkFrame& frame) {
  if (frame.fd) {
    struct canfd_frame cf;
    std::memset(&cf, 0, sizeof cf);
    cf.can_id = frame.can_id & CAN_SFF_MASK;
    cf.len = frame.len > CANFD_MAX_DLEN ? CANFD_MAX_DLEN : frame.len;
    cf.flags = CANFD_BRS;
    std::memcpy(cf.data, frame.data.data(), cf.len);
    std::vector<std::uint8_t> out(sizeof cf);
    std::memcpy(out.data(), &cf, sizeof cf);
    return out;
  }
  struct can_frame cf;
  std::memset(&cf, 0, sizeof cf);
  cf.can_id = frame.can_id & CAN_SFF_MASK;
  cf.len = frame.len > CAN_MAX_DLEN ? CAN_MAX_DLEN : frame.len;
  std::memcpy(cf.data, frame.data.data(), cf.len);
  std::vector<std::uint8_t> out(sizeof cf);
  std::memcpy(out.data(), &cf, sizeof cf);
  return out;
}

namespace {
LinkFrame frame_of(std::uint32_t can_id, bool fd, std::span<const std::uint8_t> bytes) noexcept {
  LinkFrame f;
  f.can_id = can_id;
  f.fd = fd;
  const std::size_t n = std::min(bytes.size(), fd ? kMaxFdBytes : std::size_t{CAN_MAX_DLEN});
  f.len = static_cast<std::uint8_t>(n);
  std::copy_n(bytes.begin(), n, f.data.begin());
  return f;
}
}  // namespace

LinkFrame fd_frame(std::uint32_t can_id, std::span<const std::uint8_t> bytes) noexcept { return frame_of(can_id, true, bytes); }
LinkFrame classic_frame(std::uint32_t can_id, std::span<const std::uint8_t> bytes) noexcept {
  return frame_of(can_id, false, bytes);
}

std::vector<LinkFrame> classic_frames(std::uint32_t base_id, std::uint8_t sequence_byte, std::span<const std::uint8_t> message) {
  std::vector<LinkFrame> out(classic_parts(message.size()));
  for (std::size_t p = 0; p < out.size(); ++p) {
    LinkFrame& f = out[p];
    f.can_id = base_id + static_cast<std::uint32_t>(p);
    f.fd = false;
    f.data[0] = sequence_byte;
    const std::size_t begin = p * kClassicSliceBytes;
    const std::size_t n = std::min(kClassicSliceBytes, message.size() - begin);
    std::copy_n(message.begin() + static_cast<std::ptrdiff_t>(begin), n, f.data.begin() + 1);
    f.len = static_cast<std::uint8_t>(1 + n);
  }
  return out;
}

std::optional<std::vector<std::uint8_t>> ClassicAssembler::feed(const LinkFrame& frame) {
  const auto abandon = [&] {
    if (in_progress_) ++incomplete_;
    reset();
  };
  if (!owns(frame.can_id) || frame.fd || frame.len < 2) {
    abandon();
    return std::nullopt;
  }
  const std::size_t part = frame.can_id - base_id_;
  const std::size_t begin = part * kClassicSliceBytes;
  const std::size_t n = std::min(kClassicSliceBytes, length_ - begin);
  if (frame.len != 1 + n) {
    abandon();
    return std::nullopt;
  }
  if (part == 0) {
    if (in_progress_) ++incomplete_;  // the previous message lost its tail
    in_progress_ = true;
    sequence_byte_ = frame.data[0];
  } else if (!in_progress_ || part != expected_part_ || frame.data[0] != sequence_byte_) {
    abandon();
    return std::nullopt;
  }
  std::copy_n(frame.data.begin() + 1, n, buffer_.begin() + static_cast<std::ptrdiff_t>(begin));
  expected_part_ = part + 1;
  if (expected_part_ == parts_) {
    reset();
    return buffer_;
  }
  return std::nullopt;
}

}  // namespace imucal::drivers::can
