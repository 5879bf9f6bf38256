#include "drivers/imu_codec.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <boost/crc.hpp>

namespace imucal::drivers::link {

namespace {

std::uint64_t get_raw(const std::uint8_t* p, std::size_t n, ByteOrder order) noexcept {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = order == ByteOrder::big ? i : n - 1 - i;
    v = (v << 8) | p[k];
  }
  return v;
}

void put_raw(std::uint8_t* p, std::size_t n, ByteOrder order, std::uint64_t v) noexcept {
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = order == ByteOrder::big ? n - 1 - i : i;
    p[k] = static_cast<std::uint8_t>(v >> (8 * i));
  }
}

// The raw bits of one value of a field as a signed number (integers) or the float's value.
double raw_to_number(FieldType t, std::uint64_t raw) noexcept {
  switch (t) {
    case FieldType::u8:
    case FieldType::u16:
    case FieldType::u32:
    case FieldType::u64:
    case FieldType::ascii: return static_cast<double>(raw);
    case FieldType::i8: return static_cast<std::int8_t>(raw);
    case FieldType::i16: return static_cast<std::int16_t>(raw);
    case FieldType::i32: return static_cast<std::int32_t>(raw);
    case FieldType::i64: return static_cast<double>(static_cast<std::int64_t>(raw));
    case FieldType::f32: return static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(raw)));
    case FieldType::f64: return std::bit_cast<double>(raw);
  }
  return 0.0;
}

std::int64_t raw_to_signed(FieldType t, std::uint64_t raw) noexcept {
  switch (t) {
    case FieldType::i8: return static_cast<std::int8_t>(raw);
    case FieldType::i16: return static_cast<std::int16_t>(raw);
    case FieldType::i32: return static_cast<std::int32_t>(raw);
    case FieldType::i64: return static_cast<std::int64_t>(raw);
    default: return static_cast<std::int64_t>(raw);
  }
}

// A number in counts to the raw bits of the type: integers rounded and saturated.
std::uint64_t number_to_raw(FieldType t, double counts) noexcept {
  const std::size_t bits = 8 * type_size(t);
  if (t == FieldType::f32) return std::bit_cast<std::uint32_t>(static_cast<float>(counts));
  if (t == FieldType::f64) return std::bit_cast<std::uint64_t>(counts);
  const double r = std::nearbyint(std::isfinite(counts) ? counts : 0.0);
  if (is_signed(t)) {
    const double hi = std::ldexp(1.0, static_cast<int>(bits) - 1) - 1.0, lo = -std::ldexp(1.0, static_cast<int>(bits) - 1);
    const auto v = static_cast<std::int64_t>(std::clamp(r, lo, bits == 64 ? 9.2e18 : hi));
    const std::uint64_t mask = bits == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << bits) - 1;
    return static_cast<std::uint64_t>(v) & mask;
  }
  const double hi = bits == 64 ? 1.8e19 : std::ldexp(1.0, static_cast<int>(bits)) - 1.0;
  return static_cast<std::uint64_t>(std::clamp(r, 0.0, hi));
}

std::size_t axis_of(Role r) noexcept {
  switch (r) {
    case Role::gyro_y:
    case Role::accel_y: return 1;
    case Role::gyro_z:
    case Role::accel_z: return 2;
    default: return 0;
  }
}

bool header_matches(const Message& m, std::span<const std::uint8_t> bytes) noexcept {
  return bytes.size() >= m.header.size() && std::equal(m.header.begin(), m.header.end(), bytes.begin());
}

template <int Bits>
std::uint32_t crc_of(const Checksum& c, std::span<const std::uint8_t> bytes) noexcept {
  using Crc = boost::crc_basic<Bits>;
  using V = typename Crc::value_type;
  Crc crc(static_cast<V>(c.poly), static_cast<V>(c.init), static_cast<V>(c.xor_out), c.reflect_in, c.reflect_out);
  crc.process_bytes(bytes.data(), bytes.size());
  return static_cast<std::uint32_t>(crc.checksum());
}

double scale_of(const Field& f) noexcept { return f.scale.value_or(1.0); }

}  // namespace

Values::Values() : gyro_temp_C(std::nan("")), accel_temp_C(std::nan("")) {
  coil_C.fill(std::nan(""));
  accel_sensor_C.fill(std::nan(""));
}

const char* to_string(DecodeStatus s) noexcept {
  switch (s) {
    case DecodeStatus::ok: return "ok";
    case DecodeStatus::bad_length: return "bad length";
    case DecodeStatus::bad_header: return "unknown header";
    case DecodeStatus::bad_checksum: return "bad checksum";
    case DecodeStatus::bad_value: return "non-finite value";
  }
  return "?";
}

std::uint32_t checksum(const Checksum& c, std::span<const std::uint8_t> bytes) noexcept {
  switch (c.kind) {
    case ChecksumKind::none: return 0;
    case ChecksumKind::crc:
      if (c.width_bits == 8) return crc_of<8>(c, bytes);
      if (c.width_bits == 16) return crc_of<16>(c, bytes);
      return crc_of<32>(c, bytes);
    case ChecksumKind::sum8: {
      unsigned sum = 0;
      for (const std::uint8_t b : bytes) sum += b;
      return sum & 0xFFu;
    }
    case ChecksumKind::xor8: {
      std::uint8_t x = 0;
      for (const std::uint8_t b : bytes) x = static_cast<std::uint8_t>(x ^ b);
      return x;
    }
  }
  return 0;
}

namespace {

// One decoded value of a field (the k-th of its count) into the values of its role. Apart from
// decode(): a switch over every role inside decode's loops made clang-tidy's optional-access
// analysis of decode take minutes (its cost grows with the branches on optionals in a function).
void store_value(Values& v, const Field& f, std::size_t k, std::uint64_t raw, double value) {
  switch (f.role) {
    case Role::gyro_x:
    case Role::gyro_y:
    case Role::gyro_z: v.gyro[axis_of(f.role)] = value; break;
    case Role::accel_x:
    case Role::accel_y:
    case Role::accel_z: v.accel[axis_of(f.role)] = value; break;
    case Role::status: v.status = raw; break;
    case Role::sequence: v.sequence = raw; break;
    case Role::time: v.time_raw = raw; break;
    case Role::latency: v.latency_ns = value; break;
    case Role::temperature: v.gyro_temp_C = v.accel_temp_C = value; break;
    case Role::gyro_temperature: v.gyro_temp_C = value; break;
    case Role::accel_temperature: v.accel_temp_C = value; break;
    case Role::coil_temperature: v.coil_C[f.index + k] = value; break;
    case Role::accel_sensor_temperature: v.accel_sensor_C[f.index + k] = value; break;
    case Role::serial: v.serial.push_back(static_cast<char>(raw)); break;
  }
}

}  // namespace

namespace {

// The message whose header the frame carries (the last that matches), or none.
std::optional<std::size_t> message_of(const ImuLink& link, std::span<const std::uint8_t> frame) {
  std::optional<std::size_t> found;
  for (std::size_t i = 0; i < link.messages.size(); ++i)
    if (!link.messages[i].header.empty() && header_matches(link.messages[i], frame)) found = i;
  return found;
}

// A field's raw count as a value: its scale applied, NaN for the field's "invalid" count.
double field_value(const Field& f, std::uint64_t raw, double number) {
  const bool missing = f.invalid_raw && raw_to_signed(f.type, raw) == *f.invalid_raw;
  return missing ? std::nan("") : number * scale_of(f);
}

}  // namespace

Decoded decode(const ImuLink& link, std::span<const std::uint8_t> frame, std::optional<std::size_t> message) {
  Decoded d;
  // The optionals are read here and in the two functions above only: decode's loops with them
  // made clang-tidy's optional analysis take from 3 s to over 50 s.
  const std::optional<std::size_t> which = message ? message : message_of(link, frame);
  if (!which || *which >= link.messages.size()) {
    d.status = DecodeStatus::bad_header;
    return d;
  }
  d.message = *which;
  const Message& m = link.messages[d.message];
  if (frame.size() != m.length) {
    d.status = DecodeStatus::bad_length;
    return d;
  }
  // The checksum before the header: a damaged header byte is a damaged frame, not a foreign one.
  if (m.checksum.kind != ChecksumKind::none) {
    const Checksum& c = m.checksum;
    const std::uint64_t stored = get_raw(frame.data() + c.offset, c.size(), c.byte_order);
    if (checksum(c, frame.subspan(c.from, c.to - c.from)) != stored) {
      d.status = DecodeStatus::bad_checksum;
      return d;
    }
  }
  if (!header_matches(m, frame)) {
    d.status = DecodeStatus::bad_header;
    return d;
  }
  Values& v = d.values;
  for (const Field& f : m.fields) {
    const std::size_t size = type_size(f.type);
    for (std::size_t k = 0; k < f.count; ++k) {
      const std::uint64_t raw = get_raw(frame.data() + f.offset + k * size, size, f.byte_order);
      const double number = raw_to_number(f.type, raw);
      if (!std::isfinite(number)) {
        d.status = DecodeStatus::bad_value;
        return d;
      }
      store_value(v, f, k, raw, field_value(f, raw, number));
    }
  }
  if (const Field* f = m.find(Role::serial)) {
    // Padded with NULs or spaces to the field's length; a character outside printable ASCII is a
    // damaged frame, never a serial number.
    const auto end = v.serial.find('\0');
    if (end != std::string::npos) v.serial.resize(end);
    while (!v.serial.empty() && v.serial.back() == ' ') v.serial.pop_back();
    const bool printable = std::all_of(v.serial.begin(), v.serial.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
    if (!printable || v.serial.empty() || f->count == 0) d.status = DecodeStatus::bad_value;
  }
  return d;
}

std::vector<std::uint8_t> encode(const ImuLink& link, std::size_t message, const Values& v) {
  const Message& m = link.messages[message];
  std::vector<std::uint8_t> out(m.length, 0);
  std::copy(m.header.begin(), m.header.end(), out.begin());
  for (const Field& f : m.fields) {
    const std::size_t size = type_size(f.type);
    for (std::size_t k = 0; k < f.count; ++k) {
      std::uint64_t raw = 0;
      auto counts = [&](double value) { return number_to_raw(f.type, value / scale_of(f)); };
      auto temperature = [&](double value) {
        if (std::isnan(value) && f.invalid_raw) return number_to_raw(f.type, static_cast<double>(*f.invalid_raw));
        return counts(value);
      };
      switch (f.role) {
        case Role::gyro_x:
        case Role::gyro_y:
        case Role::gyro_z: raw = counts(v.gyro[axis_of(f.role)]); break;
        case Role::accel_x:
        case Role::accel_y:
        case Role::accel_z: raw = counts(v.accel[axis_of(f.role)]); break;
        case Role::status: raw = v.status; break;
        case Role::sequence: raw = v.sequence % sequence_modulus(m); break;
        case Role::time: raw = v.time_raw.value_or(0); break;
        case Role::latency: raw = counts(v.latency_ns.value_or(0.0)); break;
        case Role::temperature:
        case Role::gyro_temperature: raw = temperature(v.gyro_temp_C); break;
        case Role::accel_temperature: raw = temperature(v.accel_temp_C); break;
        case Role::coil_temperature: raw = temperature(v.coil_C[f.index + k]); break;
        case Role::accel_sensor_temperature: raw = temperature(v.accel_sensor_C[f.index + k]); break;
        case Role::serial: raw = k < v.serial.size() ? static_cast<std::uint8_t>(v.serial[k]) : 0; break;
      }
      put_raw(out.data() + f.offset + k * size, size, f.byte_order, raw);
    }
  }
  if (m.checksum.kind != ChecksumKind::none) {
    const Checksum& c = m.checksum;
    const auto covered = std::span<const std::uint8_t>(out).subspan(c.from, c.to - c.from);
    put_raw(out.data() + c.offset, c.size(), c.byte_order, checksum(c, covered));
  }
  return out;
}

void to_increments(const Message& m, const Values& v, double period_s, std::array<double, 3>& dtheta_rad,
                   std::array<double, 3>& dv_mps) noexcept {
  for (const Field& f : m.fields) {
    const double factor = f.measures == Measures::rate ? period_s : 1.0;
    if (f.role == Role::gyro_x || f.role == Role::gyro_y || f.role == Role::gyro_z)
      dtheta_rad[axis_of(f.role)] = v.gyro[axis_of(f.role)] * factor;
    if (f.role == Role::accel_x || f.role == Role::accel_y || f.role == Role::accel_z)
      dv_mps[axis_of(f.role)] = v.accel[axis_of(f.role)] * factor;
  }
}

void from_increments(const Message& m, const std::array<double, 3>& dtheta_rad, const std::array<double, 3>& dv_mps,
                     double period_s, Values& v) noexcept {
  for (const Field& f : m.fields) {
    const double factor = f.measures == Measures::rate ? 1.0 / period_s : 1.0;
    if (f.role == Role::gyro_x || f.role == Role::gyro_y || f.role == Role::gyro_z)
      v.gyro[axis_of(f.role)] = dtheta_rad[axis_of(f.role)] * factor;
    if (f.role == Role::accel_x || f.role == Role::accel_y || f.role == Role::accel_z)
      v.accel[axis_of(f.role)] = dv_mps[axis_of(f.role)] * factor;
  }
}

bool status_fault(const Message& m, std::uint64_t status) noexcept {
  const Field* f = m.find(Role::status);
  return f && ((status & f->fault_when_set) != 0 || (~status & f->fault_when_clear) != 0);
}

std::uint64_t status_ok(const Message& m) noexcept {
  const Field* f = m.find(Role::status);
  return f ? f->fault_when_clear : 0;
}

std::uint64_t sequence_modulus(const Message& m) noexcept {
  const Field* f = m.find(Role::sequence);
  if (!f) return 0;
  if (f->wrap) return f->wrap;
  const std::size_t bits = 8 * type_size(f->type);
  return bits >= 64 ? 0 : std::uint64_t{1} << bits;  // 0: the full 64-bit range
}

void StreamDecoder::feed(std::span<const std::uint8_t> bytes) { buffer_.insert(buffer_.end(), bytes.begin(), bytes.end()); }

std::optional<Decoded> StreamDecoder::next() {
  for (;;) {
    // The first position where a header starts (or may start: a header cut by the buffer's end).
    std::size_t start = buffer_.size();
    std::optional<std::size_t> message;
    for (std::size_t p = 0; p < buffer_.size() && !message; ++p) {
      const auto rest = std::span<const std::uint8_t>(buffer_).subspan(p);
      for (std::size_t i = 0; i < link_.messages.size(); ++i) {
        const auto& h = link_.messages[i].header;
        const std::size_t n = std::min(h.size(), rest.size());
        if (std::equal(h.begin(), h.begin() + static_cast<std::ptrdiff_t>(n), rest.begin())) {
          start = p;
          if (n == h.size()) message = i;
          break;
        }
      }
      if (start == p) break;
    }
    if (start > 0) {
      discarded_ += start;
      ++resyncs_;
      buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(start));
    }
    if (!message) return std::nullopt;  // no header yet, or only its beginning
    const Message& m = link_.messages[*message];
    if (buffer_.size() < m.length) return std::nullopt;
    Decoded d = decode(link_, std::span<const std::uint8_t>(buffer_.data(), m.length), *message);
    if (d.status == DecodeStatus::ok) {
      buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(m.length));
    } else {
      // A header inside a broken frame may be the next real one: step over one byte only.
      buffer_.erase(buffer_.begin());
      ++discarded_;
    }
    return d;
  }
}

SequenceTracker::Step SequenceTracker::feed(std::uint64_t raw, double elapsed_periods, bool in_order) noexcept {
  Step s;
  if (!last_) {
    last_ = raw;
    count_ = raw;
    s.kind = Kind::first;
    s.count = count_;
    return s;
  }
  // 0 stands for the whole 64-bit range: plain unsigned arithmetic is the modulus.
  const auto mod = [&](std::uint64_t x) { return wrap_ ? x % wrap_ : x; };
  const std::uint64_t step = mod(raw + (wrap_ ? wrap_ : 0) - mod(*last_ + 1));  // 0 = the next one
  const bool long_counter = wrap_ == 0 || wrap_ > (std::uint64_t{1} << 31);
  const std::uint64_t half = wrap_ ? wrap_ / 2 : std::uint64_t{1} << 63;
  std::uint64_t lost = step;
  if (long_counter) {
    if (step >= half) {
      s.kind = Kind::stale;  // older than the last one: a duplicate or reordered frame
      return s;
    }
  } else {
    // How many whole wraps the silence spans, from the time that passed.
    const double missing = std::max(0.0, elapsed_periods - 1.0);
    const double wraps = std::max(0.0, std::round((missing - static_cast<double>(step)) / static_cast<double>(wrap_)));
    if (!in_order && step >= half && wraps == 0.0 && missing < static_cast<double>(half)) {
      s.kind = Kind::stale;
      return s;
    }
    lost = step + static_cast<std::uint64_t>(wraps) * wrap_;
  }
  last_ = raw;
  count_ += lost + 1;
  s.kind = lost == 0 ? Kind::next : Kind::gap;
  s.lost = lost;
  s.count = count_;
  return s;
}

}  // namespace imucal::drivers::link
