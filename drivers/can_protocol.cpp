#include "drivers/can_protocol.hpp"

#include <cstring>

#include <boost/crc.hpp>
#include <linux/can.h>

namespace imucal::drivers::can {

static_assert(sizeof(struct can_frame) == kCanMtu);
static_assert(sizeof(struct canfd_frame) == kCanFdMtu);

namespace {

void put16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v);
}
void put32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
}
void put64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (56 - 8 * i));
}
std::uint16_t get16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>((p[0] << 8) | p[1]);
}
std::uint32_t get32(const std::uint8_t* p) noexcept {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | p[i];
  return v;
}
std::uint64_t get64(const std::uint8_t* p) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
  return v;
}

void seal(std::array<std::uint8_t, kRecordBytes>& b) noexcept {
  put32(b.data() + kCrcOffset, crc32(std::span<const std::uint8_t>(b.data(), kCrcOffset)));
}

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes) noexcept {
  boost::crc_32_type crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

std::array<std::uint8_t, kRecordBytes> encode(const SampleRecord& r) noexcept {
  std::array<std::uint8_t, kRecordBytes> b{};
  b[0] = kTypeSample;
  b[1] = kLayoutVersion;
  put16(&b[2], r.status);
  put32(&b[4], r.sequence);
  put32(&b[8], r.latency_us);
  put64(&b[12], r.device_time_ns);
  for (std::size_t j = 0; j < 3; ++j) {
    put32(&b[20 + 4 * j], static_cast<std::uint32_t>(r.gyro_counts[j]));
    put32(&b[32 + 4 * j], static_cast<std::uint32_t>(r.accel_counts[j]));
  }
  put16(&b[44], static_cast<std::uint16_t>(r.gyro_temp_cC));
  put16(&b[46], static_cast<std::uint16_t>(r.accel_temp_cC));
  seal(b);
  return b;
}

std::array<std::uint8_t, kRecordBytes> encode(const TemperatureRecord& r) noexcept {
  std::array<std::uint8_t, kRecordBytes> b{};
  b[0] = kTypeTemperature;
  b[1] = r.page;
  put16(&b[2], r.sequence);
  put64(&b[4], r.device_time_ns);
  for (std::size_t k = 0; k < 24; ++k) put16(&b[12 + 2 * k], static_cast<std::uint16_t>(r.values_cC[k]));
  seal(b);
  return b;
}

DecodeStatus decode(std::span<const std::uint8_t> bytes, Record& out) noexcept {
  if (bytes.size() != kRecordBytes) return DecodeStatus::bad_length;
  const std::uint8_t* b = bytes.data();
  // The CRC first: a corrupted type byte must count as a CRC failure, not as a foreign record.
  if (crc32(bytes.first(kCrcOffset)) != get32(b + kCrcOffset)) return DecodeStatus::bad_crc;
  if (b[0] == kTypeSample) {
    if (b[1] != kLayoutVersion) return DecodeStatus::bad_version;
    SampleRecord r;
    r.status = get16(b + 2);
    r.sequence = get32(b + 4);
    r.latency_us = get32(b + 8);
    r.device_time_ns = get64(b + 12);
    for (std::size_t j = 0; j < 3; ++j) {
      r.gyro_counts[j] = static_cast<std::int32_t>(get32(b + 20 + 4 * j));
      r.accel_counts[j] = static_cast<std::int32_t>(get32(b + 32 + 4 * j));
    }
    r.gyro_temp_cC = static_cast<std::int16_t>(get16(b + 44));
    r.accel_temp_cC = static_cast<std::int16_t>(get16(b + 46));
    // Device time is a count of nanoseconds since the IMU started: the top bit set would be
    // centuries; treat it as a broken field rather than feed the clock model.
    if (r.device_time_ns > (std::uint64_t{1} << 62)) return DecodeStatus::bad_field;
    out = r;
    return DecodeStatus::ok;
  }
  if (b[0] == kTypeTemperature) {
    TemperatureRecord r;
    r.page = b[1];
    if (r.page > 1) return DecodeStatus::bad_field;
    r.sequence = get16(b + 2);
    r.device_time_ns = get64(b + 4);
    if (r.device_time_ns > (std::uint64_t{1} << 62)) return DecodeStatus::bad_field;
    for (std::size_t k = 0; k < 24; ++k) r.values_cC[k] = static_cast<std::int16_t>(get16(b + 12 + 2 * k));
    out = r;
    return DecodeStatus::ok;
  }
  return DecodeStatus::bad_type;
}

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

LinkFrame fd_frame(std::uint32_t can_id, const std::array<std::uint8_t, kRecordBytes>& record) noexcept {
  LinkFrame f;
  f.can_id = can_id;
  f.fd = true;
  f.len = static_cast<std::uint8_t>(kRecordBytes);
  f.data = record;
  return f;
}

std::array<LinkFrame, kClassicParts> classic_frames(std::uint32_t base_id, std::uint8_t sequence_byte,
                                                    const std::array<std::uint8_t, kRecordBytes>& record) noexcept {
  std::array<LinkFrame, kClassicParts> out{};
  for (std::size_t p = 0; p < kClassicParts; ++p) {
    LinkFrame& f = out[p];
    f.can_id = base_id + static_cast<std::uint32_t>(p);
    f.fd = false;
    f.data[0] = sequence_byte;
    const std::size_t begin = p * kClassicSliceBytes;
    const std::size_t n = begin + kClassicSliceBytes <= kRecordBytes ? kClassicSliceBytes : kRecordBytes - begin;
    std::memcpy(&f.data[1], record.data() + begin, n);
    f.len = static_cast<std::uint8_t>(1 + n);
  }
  return out;
}

LinkFrame command_frame(std::uint8_t command) noexcept {
  LinkFrame f;
  f.can_id = kIdCommand;
  f.fd = false;
  f.len = 8;
  f.data[0] = command;
  return f;
}

std::optional<std::array<std::uint8_t, kRecordBytes>> ClassicAssembler::feed(const LinkFrame& frame) noexcept {
  if (!owns(frame.can_id) || frame.fd || frame.len < 2) {
    if (in_progress_) ++incomplete_;
    reset();
    return std::nullopt;
  }
  const std::size_t part = frame.can_id - base_id_;
  const std::size_t begin = part * kClassicSliceBytes;
  const std::size_t n = begin + kClassicSliceBytes <= kRecordBytes ? kClassicSliceBytes : kRecordBytes - begin;
  if (frame.len != 1 + n) {
    if (in_progress_) ++incomplete_;
    reset();
    return std::nullopt;
  }
  if (part == 0) {
    if (in_progress_) ++incomplete_;  // the previous record lost its tail
    in_progress_ = true;
    sequence_byte_ = frame.data[0];
  } else if (!in_progress_ || part != expected_part_ || frame.data[0] != sequence_byte_) {
    if (in_progress_) ++incomplete_;
    reset();
    return std::nullopt;
  }
  std::memcpy(buffer_.data() + begin, &frame.data[1], n);
  expected_part_ = part + 1;
  if (expected_part_ == kClassicParts) {
    reset();
    return buffer_;
  }
  return std::nullopt;
}

}  // namespace imucal::drivers::can
