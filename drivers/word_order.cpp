#include "drivers/word_order.hpp"

#include <bit>
#include <cmath>
#include <stdexcept>

namespace imucal::drivers::words {

namespace {
std::uint16_t swap_bytes(std::uint16_t w) noexcept {
  return static_cast<std::uint16_t>(((w & 0x00FFu) << 8) | ((w >> 8) & 0x00FFu));
}
}  // namespace

WordOrder word_order_from_string(const std::string& name) {
  if (name == "high_word_first" || name == "ABCD") return WordOrder::high_word_first;
  if (name == "low_word_first" || name == "CDAB") return WordOrder::low_word_first;
  if (name == "high_word_first_swapped" || name == "BADC") return WordOrder::high_word_first_swapped;
  if (name == "low_word_first_swapped" || name == "DCBA") return WordOrder::low_word_first_swapped;
  throw std::invalid_argument("unknown word order '" + name +
                              "' (expected ABCD, CDAB, BADC or DCBA)");
}

const char* to_string(WordOrder order) noexcept {
  switch (order) {
    case WordOrder::high_word_first: return "ABCD";
    case WordOrder::low_word_first: return "CDAB";
    case WordOrder::high_word_first_swapped: return "BADC";
    case WordOrder::low_word_first_swapped: return "DCBA";
  }
  return "?";
}

std::array<std::uint16_t, 2> pack_u32(std::uint32_t value, WordOrder order) noexcept {
  const auto hi = static_cast<std::uint16_t>(value >> 16);
  const auto lo = static_cast<std::uint16_t>(value & 0xFFFFu);
  switch (order) {
    case WordOrder::high_word_first: return {hi, lo};
    case WordOrder::low_word_first: return {lo, hi};
    case WordOrder::high_word_first_swapped: return {swap_bytes(hi), swap_bytes(lo)};
    case WordOrder::low_word_first_swapped: return {swap_bytes(lo), swap_bytes(hi)};
  }
  return {hi, lo};
}

std::uint32_t unpack_u32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept {
  std::uint16_t hi = r0, lo = r1;
  switch (order) {
    case WordOrder::high_word_first: break;
    case WordOrder::low_word_first: hi = r1; lo = r0; break;
    case WordOrder::high_word_first_swapped: hi = swap_bytes(r0); lo = swap_bytes(r1); break;
    case WordOrder::low_word_first_swapped: hi = swap_bytes(r1); lo = swap_bytes(r0); break;
  }
  return (static_cast<std::uint32_t>(hi) << 16) | lo;
}

std::array<std::uint16_t, 2> pack_float32(float value, WordOrder order) noexcept {
  return pack_u32(std::bit_cast<std::uint32_t>(value), order);
}

float unpack_float32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept {
  return std::bit_cast<float>(unpack_u32(r0, r1, order));
}

std::optional<std::uint16_t> pack_scaled_i16(double value, double scale) noexcept {
  const double scaled = std::nearbyint(value * scale);
  if (!std::isfinite(scaled) || scaled < -32768.0 || scaled > 32767.0) return std::nullopt;
  const auto i = static_cast<std::int16_t>(scaled);
  return static_cast<std::uint16_t>(i);
}

double unpack_scaled_i16(std::uint16_t raw, double scale) noexcept {
  return static_cast<double>(static_cast<std::int16_t>(raw)) / scale;
}

}  // namespace imucal::drivers::words
