// An IMU link described as data (`imucal-imu-link/1`, docs/drivers.md): how the IMU is reached
// (SocketCAN, a serial line, UDP) and the layout of its frames (sync header, length, fields with
// their offsets, types, byte order and units, the sequence counter and its wrap, the status bits
// that mean invalid data, the checksum, the IMU's own time tag). One generic driver (LinkImu) and
// one simulated IMU (sim::SimImu) work from such a description, so a lab adds an IMU by writing a
// file. This header is the parsed form and its parser; the codec is imu_codec.hpp.
//
// Every quantity is converted to SI once, when the description is parsed: a field's `scale` is SI
// units per raw count (its LSB times its unit's factor), so decoding is `raw * scale`.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace imucal::drivers::link {

inline constexpr const char* kFormat = "imucal-imu-link/1";

enum class Transport { socketcan, serial, udp };
// ascii: one character a byte (an identity message's serial number).
enum class FieldType { u8, i8, u16, i16, u32, i32, u64, i64, f32, f64, ascii };
enum class ByteOrder { big, little };

// What a field carries. Sample messages: the six inertial channels, status, sequence, the IMU's
// time tag, its transmission latency, block temperatures. Temperature messages: the set's
// sequence and time, the 24 FOG coil sensors and the three accelerometer sensors.
enum class Role {
  gyro_x, gyro_y, gyro_z, accel_x, accel_y, accel_z,
  status, sequence, time, latency,
  temperature,         // one IMU temperature: both blocks
  gyro_temperature, accel_temperature,
  coil_temperature,    // temperature messages, `count` values from `index`
  accel_sensor_temperature,
  serial,              // identity messages: the unit's serial number, `count` ASCII characters
};

// A gyro or accelerometer field is an increment over the sample period (rad, m/s) or a rate
// (rad/s, m/s^2) by its unit; rates are turned into increments with the nominal sample period.
enum class Measures { increment, rate, other };

// identity: what the IMU says it is (its serial number), which the daemon checks against the
// campaign's unit before anything moves.
enum class MessageKind { sample, temperature, identity };

struct Field {
  Role role = Role::status;
  std::size_t offset = 0;
  FieldType type = FieldType::u8;
  ByteOrder byte_order = ByteOrder::big;
  std::size_t count = 1;   // consecutive values of this type (coil temperatures)
  std::size_t index = 0;   // first slot they fill (coil_temperature 0..23, accel_sensor 0..2)
  // SI per raw count: lsb x unit factor (rad, m/s, rad/s, m/s^2, C; ns for time and latency).
  // Empty for a gyro or accelerometer field whose LSB is per unit (`"lsb": "per-unit"`, given by
  // the device configuration) until resolve_per_unit_lsb() sets it.
  std::optional<double> scale = 1.0;
  Measures measures = Measures::other;
  std::optional<std::int64_t> invalid_raw;  // a raw value meaning "no value" (0x8000 temperatures)
  std::uint64_t fault_when_set = 0;         // status: any of these bits set = invalid data
  std::uint64_t fault_when_clear = 0;       // status: any of these bits clear = invalid data
  std::uint64_t wrap = 0;                   // sequence, time: the counter's modulus (0 = 2^bits)
};

enum class ChecksumKind { none, crc, sum8, xor8 };

struct Checksum {
  ChecksumKind kind = ChecksumKind::none;
  // CRC parameters in the Rocksoft/"Catalogue of CRC algorithms" model.
  int width_bits = 32;  // 8, 16 or 32
  std::uint32_t poly = 0, init = 0, xor_out = 0;
  bool reflect_in = false, reflect_out = false;
  std::size_t offset = 0;           // where the checksum is stored in the frame
  std::size_t from = 0, to = 0;     // the bytes it covers, [from, to)
  ByteOrder byte_order = ByteOrder::big;
  std::size_t size() const noexcept;  // bytes it occupies
};

struct Message {
  std::string name;
  MessageKind kind = MessageKind::sample;
  std::vector<std::uint8_t> header;  // at offset 0: the sync bytes (and record type)
  std::size_t length = 0;            // the whole frame: header, data, checksum
  Checksum checksum;
  std::vector<Field> fields;
  std::optional<std::uint32_t> can_id;           // SocketCAN: the CAN FD identifier
  std::optional<std::uint32_t> classic_base_id;  // SocketCAN: classic fallback, base + part
  bool completes = true;  // temperature: the message that completes a set (pages of one sequence)

  const Field* find(Role role) const noexcept;
};

// A command the host sends (start or stop streaming): raw bytes, on CAN in a classic frame.
struct Command {
  std::vector<std::uint8_t> bytes;
  std::optional<std::uint32_t> can_id;
};

enum class Parity { none, odd, even };

struct SerialLine {
  unsigned baud = 115200;
  Parity parity = Parity::none;
  unsigned data_bits = 8;
  unsigned stop_bits = 1;  // 1 or 2
};

struct ImuLink {
  std::string name;
  std::string source;  // where the layout comes from (manual, revision, pages)
  Transport transport = Transport::socketcan;
  SerialLine serial;   // transport serial
  std::vector<Message> messages;
  std::optional<Command> start, stop;

  std::size_t sample_message() const noexcept;  // index of the one sample message
  bool reports_serial() const noexcept;         // an identity message is described
  std::size_t max_length() const noexcept;
  // Datagrams (CAN, UDP) carry one frame each; a serial line is a byte stream to resynchronise.
  bool stream() const noexcept { return transport == Transport::serial; }
  // The LSB of the sample message's gyro (accelerometer) increments when all three are integers
  // of one increment scale: what the run file stores counts under. Empty for floats or rates.
  std::optional<double> gyro_increment_lsb_rad() const noexcept;
  std::optional<double> accel_increment_lsb_mps() const noexcept;
  // True when some gyro (accelerometer) field takes its LSB from the device configuration.
  bool gyro_lsb_per_unit() const noexcept;
  bool accel_lsb_per_unit() const noexcept;
};

const char* to_string(Transport t) noexcept;
const char* to_string(Role r) noexcept;
std::size_t type_size(FieldType t) noexcept;
bool is_integer(FieldType t) noexcept;
bool is_signed(FieldType t) noexcept;

// Parses an imucal-imu-link/1 document. Throws std::invalid_argument naming the key path
// ("imu link 'kvh-1750': messages[0].fields[3].type: ...").
ImuLink imu_link_from_json(const std::string& json_text);
// A built-in description by name (imucal-can, kvh-1750, kvh-1775-b) or a file path.
ImuLink load_imu_link(const std::string& name_or_path);
std::vector<std::string> builtin_imu_link_names();
std::string builtin_imu_link_json(const std::string& name);  // throws for an unknown name

// Sets the scale of every `"lsb": "per-unit"` gyro (accelerometer) field from the unit's LSB in
// rad (m/s) per count, times the field's unit factor. Throws std::invalid_argument when a per-unit
// LSB is missing or positive where the description fixes it: one place decides where LSBs come
// from.
void resolve_per_unit_lsb(ImuLink& link, std::optional<double> gyro_lsb_rad, std::optional<double> accel_lsb_mps);

}  // namespace imucal::drivers::link
