// Packing of 32-bit values into pairs of 16-bit Modbus registers and of scaled 16-bit integers.
// Controllers disagree on the order: the Watlow F4T sends the low word first, others the high
// word first, a few swap bytes inside each word as well. The installed libmodbus float helpers
// assume one layout each and have been unreliable across versions, so the drivers and the
// simulated chamber use these helpers only (tests/drivers/test_drivers_protocol.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

namespace imucal::drivers::words {

// Byte order of a 32-bit value A B C D (A most significant) over two registers r0 r1.
enum class WordOrder {
  high_word_first,          // r0 = AB, r1 = CD ("ABCD", big-endian)
  low_word_first,           // r0 = CD, r1 = AB ("CDAB", Watlow F4T)
  high_word_first_swapped,  // r0 = BA, r1 = DC ("BADC")
  low_word_first_swapped,   // r0 = DC, r1 = BA ("DCBA")
};

// "high_word_first" / "ABCD", "low_word_first" / "CDAB", "BADC", "DCBA". Throws
// std::invalid_argument for anything else (configuration error).
WordOrder word_order_from_string(const std::string& name);
const char* to_string(WordOrder order) noexcept;

std::array<std::uint16_t, 2> pack_u32(std::uint32_t value, WordOrder order) noexcept;
std::uint32_t unpack_u32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept;

// IEEE-754 binary32 through its bit pattern (std::bit_cast), so NaN payloads round-trip too.
std::array<std::uint16_t, 2> pack_float32(float value, WordOrder order) noexcept;
float unpack_float32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept;

// Signed 16-bit integer holding value * scale (e.g. tenths of a degree: scale 10), rounded to
// nearest. Empty when the value is not finite or does not fit in int16.
std::optional<std::uint16_t> pack_scaled_i16(double value, double scale) noexcept;
double unpack_scaled_i16(std::uint16_t raw, double scale) noexcept;

}  // namespace imucal::drivers::words
