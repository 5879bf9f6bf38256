// The pure wire layer: word-order helpers, register maps, IMU link descriptions and their codec
// (checksums, frames, the resynchronising stream decoder, the sequence counter), classic-CAN
// reassembly, the table dialects (imucal's ACL-style one and one only the tests define), the
// clock model; plus randomized fuzz tests of every
// parser (fixed seed, bounded iterations).
#include <cmath>
#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>
#include <functional>
#include <sstream>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "drivers/can_protocol.hpp"
#include "drivers/clock_model.hpp"
#include "drivers/imu_codec.hpp"
#include "drivers/imu_link.hpp"
#include "drivers/link_imu.hpp"
#include "drivers/register_map.hpp"
#include "drivers/table_dialect.hpp"
#include "drivers/tcp_table.hpp"
#include "drivers/word_order.hpp"
#include "tests/test_paths.hpp"

using namespace imucal::drivers;

// ------------------------------------------------------------------------------------------------
// Word order

TEST(WordOrder, KnownPatternsOfOnePointFive) {
  // 1.5f = 0x3FC00000: A=3F B=C0 C=00 D=00.
  using words::WordOrder;
  EXPECT_EQ(words::pack_float32(1.5f, WordOrder::high_word_first), (std::array<std::uint16_t, 2>{0x3FC0, 0x0000}));
  EXPECT_EQ(words::pack_float32(1.5f, WordOrder::low_word_first), (std::array<std::uint16_t, 2>{0x0000, 0x3FC0}));
  EXPECT_EQ(words::pack_float32(1.5f, WordOrder::high_word_first_swapped), (std::array<std::uint16_t, 2>{0xC03F, 0x0000}));
  EXPECT_EQ(words::pack_float32(1.5f, WordOrder::low_word_first_swapped), (std::array<std::uint16_t, 2>{0x0000, 0xC03F}));
  // -273.15f = 0xC3889333
  const auto w = words::pack_float32(-273.15f, WordOrder::low_word_first);
  EXPECT_EQ(w[0], 0x9333);
  EXPECT_EQ(w[1], 0xC388);
  EXPECT_EQ(words::unpack_float32(0x9333, 0xC388, WordOrder::low_word_first), -273.15f);
}

TEST(WordOrder, RoundTripsEveryOrderAndBitPattern) {
  std::mt19937_64 rng(42);
  for (auto order : {words::WordOrder::high_word_first, words::WordOrder::low_word_first,
                     words::WordOrder::high_word_first_swapped, words::WordOrder::low_word_first_swapped}) {
    for (int i = 0; i < 2000; ++i) {
      const auto v = static_cast<std::uint32_t>(rng());
      const auto w = words::pack_u32(v, order);
      EXPECT_EQ(words::unpack_u32(w[0], w[1], order), v);
    }
    EXPECT_EQ(words::word_order_from_string(words::to_string(order)), order);
  }
  EXPECT_THROW(words::word_order_from_string("ACBD"), std::invalid_argument);
}

TEST(WordOrder, ScaledInt16RoundsAndRejectsOutOfRange) {
  EXPECT_EQ(words::pack_scaled_i16(23.46, 10.0), std::optional<std::uint16_t>(235));
  EXPECT_EQ(words::pack_scaled_i16(-40.0, 10.0), std::optional<std::uint16_t>(static_cast<std::uint16_t>(-400)));
  EXPECT_DOUBLE_EQ(words::unpack_scaled_i16(static_cast<std::uint16_t>(-400), 10.0), -40.0);
  EXPECT_FALSE(words::pack_scaled_i16(3276.8, 10.0));
  EXPECT_TRUE(words::pack_scaled_i16(3276.7, 10.0));
  EXPECT_FALSE(words::pack_scaled_i16(std::nan(""), 10.0));
}

// ------------------------------------------------------------------------------------------------
// Register maps

TEST(RegisterMap, BuiltInWatlowF4t) {
  const RegisterMap m = load_register_map("watlow-f4t");
  EXPECT_EQ(m.encoding, ValueEncoding::float32);
  EXPECT_EQ(m.word_order, words::WordOrder::low_word_first);
  EXPECT_EQ(m.process_value, 27586);  // Universal Input 1's analog input value, as the manuals give it
  EXPECT_EQ(m.setpoint, 2782);
  EXPECT_EQ(m.working_setpoint, 2810);
  ASSERT_TRUE(m.control_mode);
  EXPECT_EQ(m.control_mode->address, 2730);
  ASSERT_TRUE(m.units);
  EXPECT_EQ(m.units->address, 1328);
  EXPECT_FALSE(m.ramp_rate_per_min);  // the driver ramps
  ASSERT_EQ(m.alarms.size(), 1u);
  EXPECT_FALSE(m.alarms[0].active(61));
  EXPECT_TRUE(m.alarms[0].active(7));
  EXPECT_EQ(m.address_end(), 27588);
}

TEST(RegisterMap, BuiltInEzt570iAndEncoding) {
  const RegisterMap m = load_register_map("csz-ezt570i");
  EXPECT_EQ(m.encoding, ValueEncoding::scaled_i16);
  EXPECT_DOUBLE_EQ(m.scale, 10.0);
  EXPECT_EQ(m.process_value, 61);
  EXPECT_EQ(m.setpoint, 60);
  EXPECT_FALSE(m.ramp_rate_per_min) << "none outside profiles: the driver ramps";
  EXPECT_FALSE(m.working_setpoint);
  EXPECT_FALSE(m.control_mode) << "run/stop is a bit of an event word, not in the map";
  ASSERT_EQ(m.alarms.size(), 4u);
  EXPECT_EQ(m.alarms[2].address, 57);
  EXPECT_FALSE(m.alarms[2].active(0x8000)) << "bit 15 is not defined";
  EXPECT_TRUE(m.alarms[2].active(1u << 9)) << "door open";
  const auto regs = encode_value(m, -12.34);
  ASSERT_TRUE(regs);
  ASSERT_EQ(regs->size(), 1u);
  const std::optional<double> back = decode_value(m, *regs);
  ASSERT_TRUE(back);
  EXPECT_DOUBLE_EQ(*back, -12.3);
  EXPECT_FALSE(encode_value(m, 5000.0));
}

TEST(RegisterMap, RejectsBadConfigurationNamingTheKey) {
  auto msg = [](const std::string& text) {
    try {
      register_map_from_json(text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(msg("{").find("not valid JSON"), std::string::npos);
  EXPECT_NE(msg(R"({"format":"x"})").find("format"), std::string::npos);
  EXPECT_NE(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"float32","word_order":"ABCD"},"process_value":70000,"setpoint":1})")
                .find("process_value"),
            std::string::npos);
  // A required register given as null ("this controller has none") is refused by name: it once
  // read an empty optional (found by the static check, issue 33).
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":10},"process_value":null,"setpoint":2})"),
            "register map: process_value: is required: a register address (0-65535), not null");
  EXPECT_NE(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":0},"process_value":1,"setpoint":2})")
                .find("scale"),
            std::string::npos);
  EXPECT_NE(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":10},"process_value":1,"setpoint":2,
                   "alarms":[{"name":"a","address":3}]})")
                .find("alarm 'a'"),
            std::string::npos);
  // Path first, the rule broken, the map's name when it has one; a misspelt key is refused (it
  // would otherwise leave the controller's ramping set point unread).
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"float32","word_order":"ABCD"},"process_value":70000,"setpoint":1})"),
            "register map: process_value is 70000, must be between 0 and 65535");
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","name":"lab","value":{"type":"float32","word_order":"ABCD"},
                   "process_value":1,"setpoint":3,"working_setpiont":5})"),
            "register map 'lab': unknown key \"working_setpiont\"");
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"float32","word_order":"ABCD","scale":10},"process_value":1,"setpoint":3})"),
            "register map: value: unknown key \"scale\"");
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"float32","word_order":"XY"},"process_value":1,"setpoint":3})"),
            "register map: value.word_order: unknown word order 'XY' (expected ABCD, CDAB, BADC or DCBA)");
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":10},"process_value":1,"setpoint":2,
                   "alarms":[{"name":"a","address":3,"normal":[1,-2]}]})"),
            "register map: alarms[0].normal[1]: must be an integer between 0 and 65535");
  EXPECT_EQ(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":10},"process_value":1,"setpoint":2,
                   "control_mode":{"address":4,"auto":1}})"),
            "register map: control_mode.off is required");
  EXPECT_THROW(load_register_map("no-such-map"), std::invalid_argument);
}

TEST(RegisterMap, DecodeRejectsNonFiniteAndWrongLength) {
  const RegisterMap f4t = load_register_map("watlow-f4t");
  const auto nan = words::pack_float32(std::nanf(""), f4t.word_order);
  EXPECT_FALSE(decode_value(f4t, std::vector<std::uint16_t>{nan[0], nan[1]}));
  EXPECT_FALSE(decode_value(f4t, std::vector<std::uint16_t>{1}));
  EXPECT_DOUBLE_EQ(unit_to_celsius(celsius_to_unit(-40.0, TemperatureUnit::fahrenheit), TemperatureUnit::fahrenheit), -40.0);
  EXPECT_DOUBLE_EQ(celsius_to_unit(100.0, TemperatureUnit::fahrenheit), 212.0);
}

// Fuzz: any register content decodes to a finite number or to nothing, never crashes, and every
// finite float round-trips through both encodings' word orders.
TEST(RegisterMapFuzz, RandomRegistersDecodeSafely) {
  std::mt19937_64 rng(7);
  const RegisterMap maps[] = {load_register_map("watlow-f4t"), load_register_map("csz-ezt570i")};
  for (int i = 0; i < 20000; ++i) {
    const RegisterMap& m = maps[i % 2];
    std::vector<std::uint16_t> regs(static_cast<std::size_t>(rng() % 4));
    for (auto& r : regs) r = static_cast<std::uint16_t>(rng());
    const auto v = decode_value(m, regs);
    if (v) {
      EXPECT_TRUE(std::isfinite(*v));
      const auto again = encode_value(m, *v);
      ASSERT_TRUE(again);
      EXPECT_EQ(*again, regs);  // the decoded value re-encodes to the same registers
    }
  }
}

// ------------------------------------------------------------------------------------------------
// CAN records

namespace {

// Every frame the decoder has whole now, in order.
std::vector<link::Decoded> decoded_frames(link::StreamDecoder& dec) {
  std::vector<link::Decoded> out;
  for (;;) {  // not `while (auto d = dec.next())`: clang-tidy 16's optional check misses that test
    auto d = dec.next();
    if (!d) return out;
    out.push_back(std::move(*d));
  }
}

link::ImuLink imucal_can() {
  link::ImuLink l = link::load_imu_link("imucal-can");
  link::resolve_per_unit_lsb(l, 1e-9, 1e-8);
  return l;
}

std::span<const std::uint8_t> text_bytes(const char* s) {
  return {reinterpret_cast<const std::uint8_t*>(s), std::strlen(s)};
}

link::Checksum preset(const std::string& name) {
  const std::string text = R"({"format": "imucal-imu-link/1", "name": "p", "source": "test", "transport": {"type": "udp"},
    "byte_order": "big", "messages": [{"name": "s", "kind": "sample", "header": "AA 55", "length": 16,
    "checksum": {"type": "crc", "preset": ")" + name + R"(", "offset": 12},
    "fields": [{"role": "gyro_x", "offset": 2, "type": "int8", "unit": "rad"}, {"role": "gyro_y", "offset": 3, "type": "int8", "unit": "rad"},
      {"role": "gyro_z", "offset": 4, "type": "int8", "unit": "rad"}, {"role": "accel_x", "offset": 5, "type": "int8", "unit": "m/s"},
      {"role": "accel_y", "offset": 6, "type": "int8", "unit": "m/s"}, {"role": "accel_z", "offset": 7, "type": "int8", "unit": "m/s"},
      {"role": "sequence", "offset": 8, "type": "uint8"}]}]})";
  return link::imu_link_from_json(text).messages[0].checksum;
}

// The error a description is refused with, or "(accepted)".
std::string link_error_of(const std::string& text) {
  try {
    (void)link::imu_link_from_json(text);
  } catch (const std::invalid_argument& e) {
    return std::string(e.what());
  }
  return std::string("(accepted)");
}

// `text` with its first `from` replaced by `to` (a test failure when there is none).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

}  // namespace

// The check value of every CRC preset: CRC("123456789") from the CRC catalogue.
TEST(ImuCodec, CrcPresetsGiveTheirCatalogueCheckValues) {
  const auto nine = text_bytes("123456789");
  EXPECT_EQ(link::checksum(preset("crc-32"), nine), 0xCBF43926u);
  EXPECT_EQ(link::checksum(preset("crc-32/mpeg-2"), nine), 0x0376E6E7u);
  EXPECT_EQ(link::checksum(preset("crc-32c"), nine), 0xE3069283u);
  EXPECT_EQ(link::checksum(preset("crc-16/ibm-3740"), nine), 0x29B1u);
  EXPECT_EQ(link::checksum(preset("crc-16/xmodem"), nine), 0x31C3u);
  EXPECT_EQ(link::checksum(preset("crc-16/kermit"), nine), 0x2189u);
  EXPECT_EQ(link::checksum(preset("crc-16/modbus"), nine), 0x4B37u);
  EXPECT_EQ(link::checksum(preset("crc-8/smbus"), nine), 0xF4u);
  link::Checksum sum;
  sum.kind = link::ChecksumKind::sum8;
  EXPECT_EQ(link::checksum(sum, nine), (0x31u + 0x32 + 0x33 + 0x34 + 0x35 + 0x36 + 0x37 + 0x38 + 0x39) & 0xFFu);
  sum.kind = link::ChecksumKind::xor8;
  EXPECT_EQ(link::checksum(sum, nine), 0x31u ^ 0x32 ^ 0x33 ^ 0x34 ^ 0x35 ^ 0x36 ^ 0x37 ^ 0x38 ^ 0x39);
}

// A KVH 1750 format A frame built by hand from the ICD's tables: header FE 81 FF 55, big-endian
// IEEE-754 floats, status, sequence, temperature, then the CRC-32/MPEG-2 of bytes 0..31.
TEST(ImuCodec, Kvh1750FrameDecodesAsTheManualLaysItOut) {
  const link::ImuLink kvh = link::load_imu_link("kvh-1750");
  std::vector<std::uint8_t> f = {0xFE, 0x81, 0xFF, 0x55};
  auto put_float = [&](float v) {
    const auto u = std::bit_cast<std::uint32_t>(v);
    for (int i = 3; i >= 0; --i) f.push_back(static_cast<std::uint8_t>(u >> (8 * i)));
  };
  for (float v : {1e-5f, -2e-5f, 3e-5f, 0.0f, 0.5f, 1.0f}) put_float(v);
  f.push_back(0x77);                 // status: every sensor valid
  f.push_back(127);                  // sequence
  f.push_back(0x09);                 // temperature 2345 x 0.01 C, big-endian
  f.push_back(0x29);
  const std::uint32_t crc = link::checksum(kvh.messages[0].checksum, f);
  for (int i = 3; i >= 0; --i) f.push_back(static_cast<std::uint8_t>(crc >> (8 * i)));
  ASSERT_EQ(f.size(), 36u);
  const link::Decoded d = link::decode(kvh, f);
  ASSERT_EQ(d.status, link::DecodeStatus::ok);
  EXPECT_DOUBLE_EQ(d.values.gyro[0], static_cast<double>(1e-5f));
  EXPECT_DOUBLE_EQ(d.values.gyro[1], static_cast<double>(-2e-5f));
  EXPECT_DOUBLE_EQ(d.values.accel[2], 9.80665);  // 1 g
  EXPECT_EQ(d.values.sequence, 127u);
  EXPECT_NEAR(d.values.gyro_temp_C, 23.45, 1e-12);
  EXPECT_FALSE(link::status_fault(kvh.messages[0], d.values.status));
  EXPECT_TRUE(link::status_fault(kvh.messages[0], 0x76));  // gyro x invalid
  // Accelerations in g are rates: over a 1 ms period they become velocity increments.
  std::array<double, 3> dth{}, dv{};
  link::to_increments(kvh.messages[0], d.values, 1e-3, dth, dv);
  EXPECT_DOUBLE_EQ(dv[2], 9.80665e-3);
  EXPECT_DOUBLE_EQ(dth[0], static_cast<double>(1e-5f));
  // The encoder writes the same bytes.
  EXPECT_EQ(link::encode(kvh, 0, d.values), f);
  // A NaN in a float field with a valid CRC is refused, never a sample.
  auto nan = f;
  nan[4] = 0x7F;
  nan[5] = 0xC0;
  const std::uint32_t c2 = link::checksum(kvh.messages[0].checksum, std::span(nan).first(32));
  for (int i = 0; i < 4; ++i) nan[static_cast<std::size_t>(32 + i)] = static_cast<std::uint8_t>(c2 >> (24 - 8 * i));
  EXPECT_EQ(link::decode(kvh, nan).status, link::DecodeStatus::bad_value);
}

TEST(ImuCodec, ImucalCanLayoutIsBigEndianAsDocumented) {
  const link::ImuLink l = imucal_can();
  link::Values v;
  v.status = 0x0102;
  v.sequence = 0xA1B2C3D4;
  v.latency_ns = 250'000.0;
  v.time_raw = 0x0102030405060708ull;
  v.gyro = {1e-9, -2e-9, 123456789e-9};
  v.accel = {-1e-8, 0, 7e-8};
  v.gyro_temp_C = 25.0;
  v.accel_temp_C = std::nan("");
  const auto b = link::encode(l, 0, v);
  ASSERT_EQ(b.size(), 64u);
  EXPECT_EQ(b[0], 0x01);
  EXPECT_EQ(b[1], 0x01);
  EXPECT_EQ(b[2], 0x01);
  EXPECT_EQ(b[3], 0x02);
  EXPECT_EQ(b[4], 0xA1);
  EXPECT_EQ(b[7], 0xD4);
  EXPECT_EQ(b[8], 0x00);  // 250 us
  EXPECT_EQ(b[11], 0xFA);
  EXPECT_EQ(b[12], 0x01);
  EXPECT_EQ(b[19], 0x08);
  EXPECT_EQ(b[23], 0x01);  // gyro x = 1 count
  EXPECT_EQ(b[24], 0xFF);  // gyro y = -2 counts
  EXPECT_EQ(b[27], 0xFE);
  EXPECT_EQ(b[44], 0x09);  // 2500 = 0x09C4
  EXPECT_EQ(b[45], 0xC4);
  EXPECT_EQ(b[46], 0x80);  // no sensor
  EXPECT_EQ(b[47], 0x00);
  const std::uint32_t crc = (std::uint32_t{b[60]} << 24) | (std::uint32_t{b[61]} << 16) | (std::uint32_t{b[62]} << 8) | b[63];
  EXPECT_EQ(crc, link::checksum(l.messages[0].checksum, std::span(b).first(60)));
  const link::Decoded d = link::decode(l, b);
  ASSERT_EQ(d.status, link::DecodeStatus::ok);
  EXPECT_EQ(d.values.sequence, 0xA1B2C3D4u);
  EXPECT_EQ(d.values.gyro[2], 123456789.0 * 1e-9);  // count x LSB, bit for bit: what storage keeps
  EXPECT_TRUE(std::isnan(d.values.accel_temp_C));
  const auto& time_raw = d.values.time_raw;
  ASSERT_TRUE(time_raw);
  EXPECT_EQ(*time_raw, 0x0102030405060708ull);
  EXPECT_TRUE(link::status_fault(l.messages[0], 0x0002));
  EXPECT_FALSE(link::status_fault(l.messages[0], 0x0100));  // warming up: information
  EXPECT_EQ(l.gyro_increment_lsb_rad(), 1e-9);
}

TEST(ImuCodec, EveryBitFlipIsCaughtAndNeverDecoded) {
  const link::ImuLink l = imucal_can();
  link::Values v;
  v.sequence = 42;
  v.gyro = {5e-9, 6e-9, 7e-9};
  const auto good = link::encode(l, 0, v);
  for (int bit = 0; bit < 512; ++bit) {
    auto b = good;
    b[static_cast<std::size_t>(bit / 8)] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    EXPECT_NE(link::decode(l, b, 0).status, link::DecodeStatus::ok) << "bit " << bit;
  }
  // Found by header, a flipped header bit is no message at all, or a bad checksum: never data.
  auto b = good;
  b[0] ^= 0x04;
  EXPECT_NE(link::decode(l, b).status, link::DecodeStatus::ok);
}

TEST(ImuCodec, TemperaturePagesRoundTrip) {
  const link::ImuLink l = imucal_can();
  link::Values v;
  v.sequence = 7;
  v.time_raw = 123456789;
  for (std::size_t k = 0; k < 24; ++k) v.coil_C[k] = 20.0 + 0.01 * static_cast<double>(k);
  v.coil_C[5] = std::nan("");
  v.accel_sensor_C = {30.0, 31.0, 32.0};
  const link::Decoded p0 = link::decode(l, link::encode(l, 1, v));
  const link::Decoded p1 = link::decode(l, link::encode(l, 2, v));
  ASSERT_EQ(p0.status, link::DecodeStatus::ok);
  ASSERT_EQ(p1.status, link::DecodeStatus::ok);
  EXPECT_EQ(p0.message, 1u);  // found by its header 02 00
  EXPECT_EQ(p1.message, 2u);  // 02 01
  EXPECT_NEAR(p0.values.coil_C[23], 20.23, 1e-9);
  EXPECT_TRUE(std::isnan(p0.values.coil_C[5]));
  EXPECT_NEAR(p1.values.accel_sensor_C[2], 32.0, 1e-9);
  EXPECT_EQ(p1.values.sequence, 7u);
}

TEST(ImuCodec, StreamDecoderResynchronisesAfterGarbageABadCrcAndADroppedByte) {
  const link::ImuLink kvh = link::load_imu_link("kvh-1750");
  auto frame = [&](std::uint64_t seq) {
    link::Values v;
    v.sequence = seq;
    v.status = 0x77;
    v.gyro = {1e-6 * static_cast<double>(seq), 0, 0};
    return link::encode(kvh, 0, v);
  };
  std::vector<std::uint8_t> stream = {0x01, 0xFE, 0x81, 0x00};  // garbage, with a half header
  auto append = [&](const std::vector<std::uint8_t>& f) { stream.insert(stream.end(), f.begin(), f.end()); };
  append(frame(1));
  auto bad = frame(2);
  bad[10] ^= 0x01;  // fails its CRC
  append(bad);
  auto short_frame = frame(3);
  short_frame.erase(short_frame.begin() + 7);  // a byte lost on the line
  append(short_frame);
  append(frame(4));
  link::StreamDecoder dec(kvh);
  std::vector<std::uint64_t> good;
  int bad_crc = 0;
  // Fed in awkward pieces: one byte, then 7, ... (a header split across reads must still match).
  for (std::size_t at = 0, n = 1; at < stream.size(); at += n, n = n % 9 + 2) {
    dec.feed(std::span(stream).subspan(at, std::min(n, stream.size() - at)));
    for (const link::Decoded& d : decoded_frames(dec)) {
      if (d.status == link::DecodeStatus::ok) good.push_back(d.values.sequence);
      if (d.status == link::DecodeStatus::bad_checksum) ++bad_crc;
    }
  }
  EXPECT_EQ(good, (std::vector<std::uint64_t>{1, 4}));
  EXPECT_EQ(bad_crc, 2);  // frame 2, and frame 3 running into frame 4's header
  EXPECT_GE(dec.resyncs(), 2u);
  EXPECT_GE(dec.bytes_discarded(), 4u + 36u + 35u);
  EXPECT_EQ(dec.buffered(), 0u);
}

TEST(ImuCodec, SequenceTrackerUnwrapsShortCountersAndTellsGapsFromStaleFrames) {
  link::SequenceTracker t(128);
  EXPECT_EQ(t.feed(120, 0).kind, link::SequenceTracker::Kind::first);
  for (std::uint64_t k = 121; k < 128; ++k) EXPECT_EQ(t.feed(k, 1).kind, link::SequenceTracker::Kind::next);
  auto s = t.feed(0, 1);  // wraps
  EXPECT_EQ(s.kind, link::SequenceTracker::Kind::next);
  EXPECT_EQ(s.count, 128u);
  s = t.feed(5, 5);  // 4 lost
  EXPECT_EQ(s.kind, link::SequenceTracker::Kind::gap);
  EXPECT_EQ(s.lost, 4u);
  EXPECT_EQ(t.feed(5, 0.1).kind, link::SequenceTracker::Kind::stale);  // a repeat
  EXPECT_EQ(t.feed(3, 0.1).kind, link::SequenceTracker::Kind::stale);  // older
  {
    // On a line (in order), a step back of a short counter is a gap: bytes are never reordered.
    link::SequenceTracker line(128);
    (void)line.feed(5, 0, true);
    s = line.feed(3, 0.1, true);
    EXPECT_EQ(s.kind, link::SequenceTracker::Kind::gap);
    EXPECT_EQ(s.lost, 125u);
  }
  // A silence of ~1000 periods: the counter wrapped 7 times; the time says how many.
  s = t.feed((6 + 999) % 128, 1000);
  EXPECT_EQ(s.kind, link::SequenceTracker::Kind::gap);
  EXPECT_EQ(s.lost, 999u);
  // A 32-bit counter needs no time: 2^31 ahead or more is stale.
  link::SequenceTracker w(std::uint64_t{1} << 32);
  (void)w.feed(0xFFFFFFFE, 0);
  EXPECT_EQ(w.feed(0xFFFFFFFF, 0).kind, link::SequenceTracker::Kind::next);
  EXPECT_EQ(w.feed(0, 0).count, 0x100000000u);
  EXPECT_EQ(w.feed(0xFFFFFFF0, 0).kind, link::SequenceTracker::Kind::stale);
}

TEST(ImuLink, BuiltInDescriptionsLoadAndStateTheirSource) {
  for (const std::string& name : link::builtin_imu_link_names()) {
    const link::ImuLink l = link::load_imu_link(name);
    EXPECT_EQ(l.name, name);
    EXPECT_FALSE(l.source.empty());
  }
  EXPECT_NE(link::load_imu_link("kvh-1750").source.find("Rev B"), std::string::npos);
  const link::ImuLink kvh = link::load_imu_link("kvh-1750");
  EXPECT_EQ(kvh.transport, link::Transport::serial);
  EXPECT_EQ(kvh.serial.baud, 921600u);
  EXPECT_FALSE(kvh.gyro_increment_lsb_rad());  // floats: stored as doubles
  EXPECT_TRUE(link::load_imu_link("imucal-can").gyro_lsb_per_unit());
}

TEST(ImuLink, RejectsBadDescriptionsNamingTheKeyPath) {
  const std::string good = link::builtin_imu_link_json("kvh-1750");
  auto error_of = link_error_of;
  auto with = [&](const std::string& from, const std::string& to) { return replaced(good, from, to); };
  EXPECT_NE(error_of(with("\"float32\", \"unit\": \"rad\"}", "\"float24\", \"unit\": \"rad\"}")).find("messages[0].fields[0].type"), std::string::npos);
  EXPECT_NE(error_of(with("\"unit\": \"g\"", "\"unit\": \"furlong\"")).find("messages[0].fields[3].unit"), std::string::npos);
  EXPECT_NE(error_of(with("\"offset\": 30", "\"offset\": 35")).find("beyond the frame's length"), std::string::npos);
  EXPECT_NE(error_of(with("\"offset\": 30", "\"offset\": 29")).find("overlaps"), std::string::npos);
  EXPECT_NE(error_of(with("\"wrap\": 128", "\"wrap\": 300")).find("fields[7].wrap"), std::string::npos);
  EXPECT_NE(error_of(with("\"crc-32/mpeg-2\"", "\"crc-31\"")).find("checksum.preset"), std::string::npos);
  EXPECT_NE(error_of(with("\"baud\": 921600", "\"baud\": 921600, \"bauds\": 1")).find("transport: unknown key \"bauds\""), std::string::npos);
  EXPECT_NE(error_of(with("\"role\": \"sequence\", \"offset\": 29, \"type\": \"uint8\", \"wrap\": 128",
                          "\"role\": \"latency\", \"offset\": 29, \"type\": \"uint8\", \"unit\": \"us\"")).find("needs a sequence field"), std::string::npos);
  EXPECT_NE(error_of(with("\"header\": \"FE 81 FF 55\"", "\"header\": \"FE\"")).find("sync header of at least 2 bytes"), std::string::npos);
  EXPECT_NE(error_of(with("\"lsb\": 0.01", "\"lsb\": \"per-unit\"")).find("integer gyro or accelerometer increments"), std::string::npos);
  // Per-unit LSBs: required where the description leaves them to the unit, refused elsewhere.
  link::ImuLink can = link::load_imu_link("imucal-can");
  EXPECT_THROW(link::resolve_per_unit_lsb(can, std::nullopt, 1e-8), std::invalid_argument);
  link::ImuLink kvh = link::load_imu_link("kvh-1750");
  EXPECT_THROW(link::resolve_per_unit_lsb(kvh, 1e-9, std::nullopt), std::invalid_argument);
}

// An identity message carries the unit's serial number (ascii, padded) and nothing else; a
// character that is not printable ASCII makes the frame damaged, never a serial.
TEST(ImuLink, AnIdentityMessageCarriesTheSerialNumber) {
  const link::ImuLink l = imucal_can();
  ASSERT_TRUE(l.reports_serial());
  EXPECT_FALSE(link::load_imu_link("kvh-1750").reports_serial());
  std::size_t identity = l.messages.size();
  for (std::size_t i = 0; i < l.messages.size(); ++i)
    if (l.messages[i].kind == link::MessageKind::identity) identity = i;
  ASSERT_LT(identity, l.messages.size());
  link::Values v;
  v.serial = "FOG-0042";
  std::vector<std::uint8_t> frame = link::encode(l, identity, v);
  link::Decoded d = link::decode(l, frame, identity);
  ASSERT_EQ(d.status, link::DecodeStatus::ok);
  EXPECT_EQ(d.values.serial, "FOG-0042");
  // Found by its header too, as a stream or CAN id lookup would.
  EXPECT_EQ(link::decode(l, frame).values.serial, "FOG-0042");
  // A serial as long as the field, then a control character with a valid checksum.
  v.serial = std::string(18, 'A');
  EXPECT_EQ(link::decode(l, link::encode(l, identity, v), identity).values.serial, std::string(18, 'A'));
  v.serial = "FOG\x01";
  EXPECT_EQ(link::decode(l, link::encode(l, identity, v), identity).status, link::DecodeStatus::bad_value);

  auto error_of = link_error_of;
  const std::string text = link::builtin_imu_link_json("imucal-can");
  auto with = [&](const std::string& from, const std::string& to) { return replaced(text, from, to); };
  EXPECT_NE(error_of(with("\"type\": \"ascii\", \"count\": 18", "\"type\": \"uint8\", \"count\": 18")).find("the serial field is ascii"), std::string::npos);
  EXPECT_NE(error_of(with("\"type\": \"ascii\", \"count\": 18", "\"type\": \"ascii\"")).find("needs count"), std::string::npos);
  EXPECT_NE(error_of(with("\"role\": \"serial\"", "\"role\": \"sequence\"")).find("identity message carries the serial field"), std::string::npos);
  EXPECT_NE(error_of(with("\"kind\": \"identity\"", "\"kind\": \"who\"")).find("\"identity\""), std::string::npos);
}

// What a classic assembler made of some frames: the frames (by index) that completed a message,
// and those messages. A function of its own, so that the test below is a few straight lines (the
// optional-access analysis of the static check ran for minutes on the fed optionals in its loops).
namespace {

struct Reassembled {
  std::vector<std::size_t> completed_at;
  std::vector<std::vector<std::uint8_t>> messages;
};

Reassembled feed_all(can::ClassicAssembler& as, const std::vector<can::LinkFrame>& frames) {
  Reassembled out;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    std::optional<std::vector<std::uint8_t>> message = as.feed(frames[i]);
    if (!message) continue;
    out.completed_at.push_back(i);
    out.messages.push_back(std::move(*message));
  }
  return out;
}

}  // namespace

TEST(CanProtocol, ClassicFallbackReassemblesAndAbandonsBrokenSets) {
  const link::ImuLink l = imucal_can();
  link::Values v;
  v.sequence = 0x1234;
  const auto rec = link::encode(l, 0, v);
  const auto parts = can::classic_frames(0x110, 0x34, rec);
  ASSERT_EQ(parts.size(), 10u);
  EXPECT_EQ(parts[9].len, 2);  // last slice carries one byte
  can::ClassicAssembler as(0x110, 64);
  // The message comes with its last part, not before.
  const Reassembled whole = feed_all(as, parts);
  EXPECT_EQ(whole.completed_at, std::vector<std::size_t>{9});
  ASSERT_EQ(whole.messages.size(), 1u);
  EXPECT_EQ(whole.messages[0], rec);
  EXPECT_EQ(as.incomplete(), 0u);

  // A lost middle part: the record is abandoned, never patched from the next sample.
  std::vector<can::LinkFrame> lost_middle = parts;
  lost_middle.erase(lost_middle.begin() + 4);
  EXPECT_TRUE(feed_all(as, lost_middle).completed_at.empty());
  EXPECT_EQ(as.incomplete(), 1u);
  // Parts of another sample (different sequence byte) interleaved: abandoned as well.
  const auto other = can::classic_frames(0x110, 0x35, rec);
  std::vector<can::LinkFrame> mixed(parts.begin(), parts.begin() + 5);
  mixed.insert(mixed.end(), other.begin() + 5, other.end());
  EXPECT_TRUE(feed_all(as, mixed).completed_at.empty());
  EXPECT_EQ(as.incomplete(), 2u);
  // And a clean set afterwards goes through.
  const Reassembled again = feed_all(as, parts);
  EXPECT_EQ(again.completed_at, std::vector<std::size_t>{9});
  ASSERT_EQ(again.messages.size(), 1u);
  EXPECT_EQ(again.messages[0], rec);
}

TEST(CanProtocol, WireFramesRoundTrip) {
  const link::ImuLink l = imucal_can();
  const auto rec = link::encode(l, 0, link::Values{});
  const auto wire = can::to_wire(can::fd_frame(0x100, rec));
  ASSERT_EQ(wire.size(), can::kCanFdMtu);
  const auto back = can::parse_wire(wire);
  ASSERT_TRUE(back);
  EXPECT_TRUE(back->fd);
  EXPECT_EQ(back->can_id, 0x100u);
  EXPECT_EQ(back->len, 64);
  EXPECT_TRUE(std::equal(rec.begin(), rec.end(), back->data.begin()));
  const std::uint8_t start[] = {1, 0, 0, 0, 0, 0, 0, 0};
  const auto cmd = can::to_wire(can::classic_frame(0x080, start));
  ASSERT_EQ(cmd.size(), can::kCanMtu);
  const auto c = can::parse_wire(cmd);
  ASSERT_TRUE(c);
  EXPECT_FALSE(c->fd);
  EXPECT_EQ(c->data[0], 1);
  EXPECT_FALSE(can::parse_wire(std::vector<std::uint8_t>(40, 0)));
}

// Fuzz: random and mutated frames through the CAN wire parser, the classic assembler and the
// decoder. Nothing crashes; a mutated frame never decodes as valid with different content.
TEST(ImuCodecFuzz, RandomAndMutatedCanFrames) {
  std::mt19937_64 rng(1234);
  const link::ImuLink l = imucal_can();
  can::ClassicAssembler as(0x110, 64);
  link::Values base;
  base.sequence = 99;
  base.gyro = {1e-9, 2e-9, 3e-9};
  const auto good = link::encode(l, 0, base);
  int decoded_ok = 0;
  for (int i = 0; i < 30000; ++i) {
    std::vector<std::uint8_t> bytes;
    switch (rng() % 4) {
      case 0: bytes.resize(rng() % 100); for (auto& b : bytes) b = static_cast<std::uint8_t>(rng()); break;
      case 1: bytes = can::to_wire(can::fd_frame(0x100, good)); break;
      case 2: bytes = can::to_wire(can::classic_frames(0x110, 99, good)[rng() % 10]); break;
      default: bytes.resize(rng() % 2 ? can::kCanMtu : can::kCanFdMtu); for (auto& b : bytes) b = static_cast<std::uint8_t>(rng()); break;
    }
    const int flips = static_cast<int>(rng() % 3);
    for (int k = 0; k < flips && !bytes.empty(); ++k) bytes[rng() % bytes.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    const auto f = can::parse_wire(bytes);
    if (!f) continue;
    std::optional<std::vector<std::uint8_t>> rec;
    if (as.owns(f->can_id)) rec = as.feed(*f);
    else if (f->fd) rec = std::vector<std::uint8_t>(f->data.begin(), f->data.begin() + f->len);
    if (!rec) continue;
    const link::Decoded d = link::decode(l, *rec);
    if (d.status == link::DecodeStatus::ok && d.message == 0) {
      ++decoded_ok;
      // The only valid frame in play is `good` (random bytes passing CRC-32 and the header are a
      // 2^-48 event).
      EXPECT_EQ(*rec, good);
      EXPECT_EQ(d.values.sequence, 99u);
    }
  }
  EXPECT_GT(decoded_ok, 100);
}

// Fuzz: a KVH byte stream with random garbage, cut frames and bit flips, fed in random pieces.
// Every frame the decoder accepts is one that was sent intact, in order.
TEST(ImuCodecFuzz, RandomByteStreamsDecodeOnlyIntactFrames) {
  std::mt19937_64 rng(4321);
  const link::ImuLink kvh = link::load_imu_link("kvh-1750");
  std::vector<std::uint8_t> stream;
  std::vector<std::uint64_t> intact;
  for (std::uint64_t seq = 0; seq < 4000; ++seq) {
    link::Values v;
    v.sequence = seq;
    v.status = 0x77;
    v.gyro = {static_cast<double>(seq), 0, 0};
    auto f = link::encode(kvh, 0, v);
    switch (rng() % 6) {
      case 0: f[rng() % f.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255); break;
      case 1: f.erase(f.begin() + static_cast<std::ptrdiff_t>(rng() % f.size())); break;
      case 2: for (int k = static_cast<int>(rng() % 20); k > 0; --k) stream.push_back(static_cast<std::uint8_t>(rng())); [[fallthrough]];
      default: intact.push_back(seq); break;
    }
    stream.insert(stream.end(), f.begin(), f.end());
  }
  link::StreamDecoder dec(kvh);
  std::vector<std::uint64_t> got;
  for (std::size_t at = 0; at < stream.size();) {
    const std::size_t n = std::min<std::size_t>(1 + rng() % 100, stream.size() - at);
    dec.feed(std::span(stream).subspan(at, n));
    at += n;
    for (const link::Decoded& d : decoded_frames(dec))
      if (d.status == link::DecodeStatus::ok) got.push_back(static_cast<std::uint64_t>(d.values.gyro[0]));
  }
  // Intact frames are all found (a cut frame may swallow the header of the one after it only
  // when that one is damaged too; here each damaged frame is followed by whole bytes).
  for (std::size_t i = 1; i < got.size(); ++i) EXPECT_GT(got[i], got[i - 1]);
  std::size_t found = 0;
  for (std::uint64_t s : intact) found += std::binary_search(got.begin(), got.end(), s) ? 1 : 0;
  EXPECT_EQ(got.size(), found);                         // nothing but intact frames
  EXPECT_GT(found, intact.size() * 95 / 100);           // and almost all of them
}

// ------------------------------------------------------------------------------------------------
// Table dialects

namespace {

const dialect::Dialect& acl() { return dialect::imucal_acl(); }

std::string test_dialect_text() {
  std::ifstream in(imucaltest::test_data_dir() + "/table-dialect-test-rtc.json");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A dialect only the tests define (tests/data/table-dialect-test-rtc.json).
const dialect::Dialect& rtc() {
  static const dialect::Dialect d = dialect::dialect_from_json(test_dialect_text());
  return d;
}

dialect::Command command(dialect::Op op, int axis = 0, TableMode mode = TableMode::off, std::array<double, 3> args = {}) {
  dialect::Command c;
  c.op = op;
  c.axis = axis;
  c.mode = mode;
  c.args = args;
  return c;
}

dialect::Refusal refusal_of(const dialect::Dialect& d, std::string_view line) {
  const auto r = dialect::parse_command(d, line);
  return std::holds_alternative<dialect::ParseError>(r) ? std::get<dialect::ParseError>(r).refusal : dialect::Refusal::none;
}

// Every command the driver sends, with values that need their digits.
std::vector<dialect::Command> every_command() {
  using dialect::Op;
  std::vector<dialect::Command> all = {
      command(Op::identify), command(Op::interlock_close), command(Op::interlock_open), command(Op::interlock_reset),
      command(Op::mode, 2, TableMode::synthesis), command(Op::demand_position, 0, TableMode::off, {-123.25}),
      command(Op::demand_rate, 1, TableMode::off, {0.5}), command(Op::demand_oscillation, 2, TableMode::off, {1.25, 0.5, -90}),
      command(Op::limit_position, 1, TableMode::rate, {-10.5, 20}), command(Op::limit_rate, 0, TableMode::position, {50}),
      command(Op::limit_accel, 2, TableMode::synthesis, {100}), command(Op::watchdog, 0, TableMode::off, {0.25}),
      command(Op::read_positions), command(Op::read_status)};
  return all;
}

}  // namespace

TEST(TableDialect, ImucalAclCommandsAreTheDocumentedText) {
  using dialect::Op;
  EXPECT_EQ(dialect::format_command(acl(), command(Op::demand_oscillation, 1, TableMode::off, {1.25, 0.5, -90.0})),
            ":DEM:OSC 2,1.25,0.5,-90");
  EXPECT_EQ(dialect::format_command(acl(), command(Op::limit_position, 1, TableMode::rate, {-10.5, 20.0})),
            ":LIM:POS 2,RATE,-10.5,20");
  dialect::Command on = command(Op::checksum);
  on.flag = true;
  EXPECT_EQ(dialect::format_command(acl(), on), ":SYST:CHEC ON");
  // Keywords in any case, blanks around fields, a '\r' before the line end.
  const auto p = dialect::parse_command(acl(), " :lim:pos 2, rate ,-10.5,20\r");
  ASSERT_TRUE(std::holds_alternative<dialect::Command>(p));
  const auto& q = std::get<dialect::Command>(p);
  EXPECT_EQ(q.op, Op::limit_position);
  EXPECT_EQ(q.axis, 1);
  EXPECT_EQ(q.mode, TableMode::rate);
  EXPECT_DOUBLE_EQ(q.args[0], -10.5);
  EXPECT_DOUBLE_EQ(q.args[1], 20.0);
}

TEST(TableDialect, EveryCommandRoundTripsThroughEitherDialect) {
  for (const dialect::Dialect* d : {&acl(), &rtc()})
    for (const dialect::Command& c : every_command()) {
      const std::string line = dialect::format_command(*d, c);
      const auto p = dialect::parse_command(*d, line + d->line_end);
      ASSERT_TRUE(std::holds_alternative<dialect::Command>(p)) << d->name << ": " << line;
      const auto& q = std::get<dialect::Command>(p);
      EXPECT_EQ(q.op, c.op) << line;
      EXPECT_EQ(q.axis, c.axis) << line;
      EXPECT_EQ(q.mode, c.mode) << line;
      EXPECT_EQ(q.args, c.args) << line;
    }
  // The test dialect as written: tokens, fixed decimals, the placeholder before the keyword.
  using dialect::Op;
  EXPECT_EQ(dialect::format_command(rtc(), command(Op::limit_position, 1, TableMode::rate, {-10.5, 20.0})),
            "B LIMIT V POS -10.500000..20.000000");
  EXPECT_EQ(dialect::format_command(rtc(), command(Op::mode, 2, TableMode::off)), "C MODE=0");
  EXPECT_EQ(rtc().line_end, "\r\n");
  // Its commands are case-sensitive.
  EXPECT_EQ(refusal_of(rtc(), "b goto 1"), dialect::Refusal::syntax);
}

TEST(TableDialect, CommandErrorsCarryRefusals) {
  using dialect::Refusal;
  EXPECT_EQ(refusal_of(acl(), ":FOO 1"), Refusal::syntax);
  EXPECT_EQ(refusal_of(acl(), ":DEM:POS 4,10"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":DEM:POS 1,abc"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":DEM:POS 1,nan"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":DEM:POS 1"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":MODE 1,FAST"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":SYST:CHEC MAYBE"), Refusal::argument);
  EXPECT_EQ(refusal_of(acl(), ":READ:POS?"), Refusal::none);
  EXPECT_EQ(refusal_of(rtc(), "D GOTO 1"), Refusal::argument);  // no axis D
  EXPECT_EQ(refusal_of(rtc(), "A SPIN fast"), Refusal::argument);
  EXPECT_EQ(refusal_of(rtc(), "JUMP"), Refusal::syntax);
  EXPECT_EQ(refusal_of(rtc(), "WHERE"), Refusal::none);
}

TEST(TableDialect, RepliesRoundTripWithAndWithoutChecksum) {
  dialect::Reply r;
  r.kind = dialect::Reply::Kind::positions;
  r.time_us = 123456789012;
  r.angle_deg = {1.5, -0.25, 359.9999999};
  r.rate_dps = {10.0, 0.0, -3.0};
  const std::string body = dialect::format_reply(acl(), r);
  EXPECT_EQ(body, "POS 123456789012,1.5,-0.25,359.9999999,10,0,-3");
  for (bool sum : {false, true}) {
    std::string line = dialect::frame_line(acl(), body, sum);
    line.pop_back();  // the line end
    const auto p = dialect::parse_reply(acl(), line, dialect::Reply::Kind::positions, sum);
    ASSERT_TRUE(p) << p.error().message;
    EXPECT_EQ(p->time_us, r.time_us);
    EXPECT_EQ(p->angle_deg, r.angle_deg);
    EXPECT_EQ(p->rate_dps, r.rate_dps);
  }
  dialect::Reply s;
  s.kind = dialect::Reply::Kind::status;
  s.time_us = 5'250'000;
  s.interlock = InterlockState::closed;
  s.modes = {TableMode::rate, TableMode::off, TableMode::synthesis};
  s.flags = {dialect::StatusFlags{false, false, false, true}, dialect::StatusFlags{true, true, false, false}, {}};
  EXPECT_EQ(dialect::format_reply(acl(), s), "STAT 5250000,CLOSED,RATE,OFF,SYNT,8,3,0");
  EXPECT_EQ(dialect::format_reply(rtc(), s), "#5.250000 ARMED V/1 0/12 S/0");
  for (const dialect::Dialect* d : {&acl(), &rtc()}) {
    const auto ps = dialect::parse_reply(*d, dialect::format_reply(*d, s), dialect::Reply::Kind::status, false);
    ASSERT_TRUE(ps) << d->name << ": " << ps.error().message;
    EXPECT_EQ(ps->interlock, InterlockState::closed);
    EXPECT_EQ(ps->modes, s.modes);
    EXPECT_EQ(ps->flags, s.flags);
    EXPECT_EQ(ps->time_us, s.time_us);
    const auto pr = dialect::parse_reply(*d, dialect::format_reply(*d, r), dialect::Reply::Kind::positions, false);
    ASSERT_TRUE(pr) << d->name << ": " << pr.error().message;
    EXPECT_EQ(pr->time_us, r.time_us);
    for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(pr->angle_deg[k], r.angle_deg[k], 1e-6);
  }
  // Error replies: the code as written and what it means; an unknown code is a plain refusal.
  const auto e = dialect::parse_reply(acl(), "ERR 200,interlock open", dialect::Reply::Kind::ok, false);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->kind, dialect::Reply::Kind::error);
  EXPECT_EQ(e->refusal, dialect::Refusal::interlock_open);
  EXPECT_EQ(e->code, "200");
  const auto e2 = dialect::parse_reply(rtc(), "!E11 too far", dialect::Reply::Kind::ok, false);
  ASSERT_TRUE(e2);
  EXPECT_EQ(e2->refusal, dialect::Refusal::limit_exceeded);
  EXPECT_EQ(e2->text, "too far");
  const auto e3 = dialect::parse_reply(rtc(), "!E99 overheated", dialect::Reply::Kind::ok, false);
  ASSERT_TRUE(e3);
  EXPECT_EQ(e3->refusal, dialect::Refusal::none);
  // A reply of another kind than expected is garbled.
  EXPECT_EQ(dialect::parse_reply(acl(), "OK", dialect::Reply::Kind::positions, false).code(), DriverErrc::protocol_error);
  EXPECT_EQ(dialect::parse_reply(rtc(), ">", dialect::Reply::Kind::status, false).code(), DriverErrc::protocol_error);
  EXPECT_EQ(dialect::parse_reply(acl(), "OK*00", dialect::Reply::Kind::ok, true).code(), DriverErrc::crc_error);
  EXPECT_TRUE(dialect::parse_reply(acl(), "OK*04", dialect::Reply::Kind::ok, true));  // 0x4F ^ 0x4B
}

TEST(TableDialect, ChecksumCatchesEverySingleByteCorruption) {
  dialect::Reply r;
  r.kind = dialect::Reply::Kind::positions;
  r.time_us = 42;
  r.angle_deg = {12.5, 45.0, 90.125};
  std::string line = dialect::frame_line(acl(), dialect::format_reply(acl(), r), true);
  line.pop_back();
  for (std::size_t i = 0; i < line.size(); ++i)
    for (int delta : {1, 2, 7, 64}) {
      std::string bad = line;
      bad[i] = static_cast<char>(bad[i] ^ delta);
      const auto p = dialect::parse_reply(acl(), bad, dialect::Reply::Kind::positions, true);
      EXPECT_FALSE(p) << bad;
    }
}

TEST(TableDialect, BuiltInDialectStatesItsSource) {
  ASSERT_EQ(dialect::builtin_dialect_names(), std::vector<std::string>{"imucal-acl"});
  EXPECT_EQ(acl().name, "imucal-acl");
  EXPECT_NE(acl().source.find("Acutrol"), std::string::npos);
  EXPECT_TRUE(acl().has_reply_checksum);
  EXPECT_FALSE(rtc().has_reply_checksum);
  EXPECT_THROW(dialect::load_dialect("no-such-dialect"), std::invalid_argument);
}

TEST(TableDialect, BadDescriptionsAreRefusedNamingEveryProblem) {
  auto problems_of = [](const std::function<void(nlohmann::json&)>& damage) {
    nlohmann::json j = nlohmann::json::parse(test_dialect_text());
    damage(j);
    try {
      (void)dialect::dialect_from_json(j.dump());
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(problems_of([](nlohmann::json&) {}), "");
  auto expect = [&](const std::function<void(nlohmann::json&)>& damage, const std::vector<std::string>& parts) {
    const std::string m = problems_of(damage);
    for (const std::string& p : parts) EXPECT_NE(m.find(p), std::string::npos) << "'" << p << "' not in: " << m;
  };
  expect([](nlohmann::json& j) { j["commands"].erase("read_status"); }, {"dialect.commands.read_status is required"});
  expect([](nlohmann::json& j) { j["commands"]["demand_rate"] = "{axis} SPIN {speed}"; },
         {"dialect.commands.demand_rate: unknown placeholder {speed} (expected {axis}, {rate_dps})",
          "dialect.commands.demand_rate lacks {rate_dps}"});
  expect([](nlohmann::json& j) { j["commands"]["mode"] = "{axis}{mode}"; },
         {"dialect.commands.mode: {axis} and {mode} need literal text between them"});
  expect([](nlohmann::json& j) { j["axes"]["inner"] = "a"; }, {"dialect.axes.inner is the same as dialect.axes.outer"});
  expect([](nlohmann::json& j) { j["errors"]["wrong_mode"] = "E1"; }, {"dialect.errors.wrong_mode is the same as dialect.errors.syntax"});
  expect([](nlohmann::json& j) { j["time_unit"] = "min"; }, {"dialect.time_unit is \"min\""});
  expect([](nlohmann::json& j) { j["replies"]["positions"] = "@{time} {angle_deg.outer}"; },
         {"dialect.replies.positions lacks {rate_dps.inner}"});
  expect([](nlohmann::json& j) { j["status_flags"]["fault"] = 9; }, {"dialect.status_flags.fault shares bits"});
  expect([](nlohmann::json& j) { j["line_end"] = "\r"; }, {"dialect.line_end must be"});
  expect([](nlohmann::json& j) { j["reply_checksum"] = {{"on", "CS ON"}, {"kind", "crc-16"}, {"separator", "*"}}; },
         {"dialect.reply_checksum.kind is \"crc-16\""});
  expect([](nlohmann::json& j) { j["speed"] = 1; }, {"dialect: unknown key \"speed\""});
  // Every problem at once, under the dialect's name.
  const std::string both = problems_of([](nlohmann::json& j) {
    j["commands"].erase("watchdog");
    j["modes"].erase("rate");
  });
  EXPECT_EQ(both.rfind("table dialect 'test-rtc': ", 0), 0u) << both;
  EXPECT_NE(both.find("dialect.commands.watchdog is required"), std::string::npos) << both;
  EXPECT_NE(both.find("dialect.modes.rate is required"), std::string::npos) << both;
}

// Fuzz: random printable and binary lines, and mutations of valid ones, through both parsers of
// both dialects.
TEST(TableDialectFuzz, RandomLinesNeverCrashAndValidOnesRoundTrip) {
  std::mt19937_64 rng(99);
  const char alphabet[] = ":*?,.=/#@!> -+0123456789eEABCDEFGHIKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz\r\t";
  const std::vector<std::string> seeds = {
      "OK", "ERR 201,limit", "POS 1,2,3,4,5,6,7", "STAT 5,CLOSED,OFF,POS,RATE,0,8,F", "IDN IMUCAL", ":DEM:POS 1,45",
      ":MODE 3,SYNT", ":DEM:OSC 1,1,2,3", ":LIM:ACC 2,POS,100", ":CONF:WDOG 0.5", ":SYST:CHEC ON", ">", "!E11 far",
      "@1.5 A 1 2 B 3 4 C 5 6", "#2.0 ARMED V/1 0/12 S/0", "B LIMIT V POS -10.5..20", "A SINE A=1 F=2 PH=3", "C MODE=S"};
  int commands_ok = 0;
  const std::array<dialect::Reply::Kind, 5> kinds = {dialect::Reply::Kind::ok, dialect::Reply::Kind::error,
                                                     dialect::Reply::Kind::positions, dialect::Reply::Kind::status,
                                                     dialect::Reply::Kind::identity};
  for (int i = 0; i < 40000; ++i) {
    std::string line;
    if (rng() % 2) {
      line = seeds[rng() % seeds.size()];
      const int n = static_cast<int>(rng() % 4);
      for (int k = 0; k < n && !line.empty(); ++k) {
        const std::size_t at = rng() % line.size();
        switch (rng() % 3) {
          case 0: line[at] = alphabet[rng() % (sizeof alphabet - 1)]; break;
          case 1: line.erase(at, 1); break;
          default: line.insert(at, 1, static_cast<char>(rng() % 256)); break;
        }
      }
    } else {
      line.resize(rng() % 80);
      for (char& c : line) c = rng() % 8 ? alphabet[rng() % (sizeof alphabet - 1)] : static_cast<char>(rng() % 256);
    }
    const dialect::Dialect& d = rng() % 2 ? acl() : rtc();
    (void)dialect::parse_reply(d, line, kinds[rng() % kinds.size()], rng() % 2 == 0);
    const auto c = dialect::parse_command(d, line);
    if (const auto* cmd = std::get_if<dialect::Command>(&c)) {
      ++commands_ok;
      // A command that parses formats to text that parses to the same command (the test
      // dialect's fixed decimals round the numbers first).
      const auto again = dialect::parse_command(d, dialect::format_command(d, *cmd));
      ASSERT_TRUE(std::holds_alternative<dialect::Command>(again)) << line;
      const auto& b = std::get<dialect::Command>(again);
      EXPECT_EQ(b.op, cmd->op);
      EXPECT_EQ(b.axis, cmd->axis);
      for (std::size_t k = 0; k < 3; ++k)
        EXPECT_NEAR(b.args[k], cmd->args[k], d.decimals ? 0.5e-6 * (1 + std::fabs(cmd->args[k]) * 1e-9) : 0.0) << line;
    }
  }
  EXPECT_GT(commands_ok, 100);
}

// ------------------------------------------------------------------------------------------------
// Clock model

TEST(ClockModel, LowerEnvelopeRemovesOneSidedJitterAndFindsDrift) {
  // Device runs 40 ppm fast; host receive = true time + 30 us floor + exponential jitter (mean
  // 80 us) + rare 5 ms outliers. The model must land within a few us of true + floor.
  std::mt19937_64 rng(5);
  std::exponential_distribution<double> jitter(1.0 / 80e3);
  ClockFit fit;
  const double drift = 40e-6;
  const std::int64_t host0 = 1'700'000'000'000'000'000LL, dev0 = 5'000'000'000LL;
  double worst = 0.0;
  for (int k = 0; k < 30000; ++k) {  // 30 s at 1 kHz
    const std::int64_t true_host = host0 + std::int64_t{k} * 1'000'000;
    const auto dev = dev0 + static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e6 * (1.0 + drift)));
    double delay = 30e3 + jitter(rng);
    if (rng() % 500 == 0) delay += 5e6;
    const auto rx = true_host + static_cast<std::int64_t>(delay);
    fit.add(dev, rx, rx - dev);
    if (k > 5000) worst = std::max(worst, std::fabs(static_cast<double>(fit.map(dev) - (true_host + 30'000))));
  }
  EXPECT_LT(worst, 5e3) << "ns";
  EXPECT_NEAR(fit.state().drift_ppm, -40.0, 1.0);  // host runs slow relative to the device
  EXPECT_TRUE(fit.state().valid);
}

TEST(ClockModel, BlocksDelayedWholeByALoadedHostDoNotTiltTheLine) {
  // 6 s at 1 kHz, device 40 ppm fast. From 4 s on the host is loaded: the sender is descheduled
  // so that every frame of a block is 50-300 us late, a different amount per block. The line must
  // rest on the prompt blocks (a least-squares line through the block minima was off by 40 ppm).
  std::mt19937_64 rng(11);
  std::exponential_distribution<double> jitter(1.0 / 20e3);
  std::uniform_real_distribution<double> block_lateness(50e3, 300e3);
  ClockFit fit;
  const double drift = 40e-6;
  double lateness = 0.0;
  for (int k = 0; k < 6000; ++k) {
    const std::int64_t true_host = 1'000'000'000'000LL + std::int64_t{k} * 1'000'000;
    const auto dev = static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e6 * (1.0 + drift)));
    if (k % 100 == 0) lateness = k >= 4000 ? block_lateness(rng) : 0.0;
    const auto rx = true_host + static_cast<std::int64_t>(10e3 + lateness + jitter(rng));
    fit.add(dev, rx, rx - dev);
  }
  EXPECT_NEAR(fit.state().drift_ppm, -40.0, 1.0);
  EXPECT_NEAR(static_cast<double>(fit.map(6'000'000'000LL) - 1'000'000'000'000LL - 6'000'000'000LL) / 1e3,
              10.0 - 6000.0 * drift * 1e3, 3.0)
      << "us: the model at the end of the run, against truth plus the 10 us floor";
}

TEST(ClockModel, TheDriversChangeOnlyTheFieldsTheyName) {
  // The table's and the IMU's fits set block span, window and delay kind; the loaded-host filter
  // (prompt tolerance) and the jump threshold are the model's. A positional initialiser once
  // shifted the threshold into the tolerance (50 ms), which left whole delayed blocks in the fit
  // (found while looking for why TimeBase.ShortCampaignThroughAllThreeDriversAt1kHz misaligned by
  // 0.3-2 ms now and then on a loaded machine; the cause was the table's send stamp, taken after
  // Asio had sent: drivers/tcp_table.cpp).
  const ClockFitConfig model;
  for (const ClockFitConfig& c : {TcpTableConfig{}.clock, LinkImuConfig{}.clock}) {
    EXPECT_EQ(c.prompt_tolerance_ns, model.prompt_tolerance_ns);
    EXPECT_EQ(c.reset_threshold_ns, model.reset_threshold_ns);
    EXPECT_EQ(c.late_confirm_ns, model.late_confirm_ns);
    EXPECT_EQ(c.round_trip_floor_ns, model.round_trip_floor_ns);
  }
  EXPECT_FALSE(TcpTableConfig{}.clock.lower_envelope);
  EXPECT_TRUE(LinkImuConfig{}.clock.lower_envelope);
}

TEST(ClockModel, SymmetricRoundTripFitAndResetOnJump) {
  ClockFitConfig cfg;
  cfg.lower_envelope = false;
  cfg.block_span_ns = 500'000'000;
  ClockFit fit(cfg);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> err(-20e3, 20e3);
  for (int k = 0; k < 2000; ++k) {  // 100 Hz reads for 20 s
    const std::int64_t dev = std::int64_t{k} * 10'000'000;
    const std::int64_t host = 1'000'000'000'000LL + dev + static_cast<std::int64_t>(err(rng));
    fit.add(dev, host, static_cast<std::int64_t>(rng() % 100'000));
  }
  EXPECT_NEAR(static_cast<double>(fit.map(20'000'000'000LL) - (1'000'000'000'000LL + 20'000'000'000LL)), 0.0, 20e3);
  // The device restarts its clock: the fit follows at once.
  fit.add(0, 2'000'000'000'000LL, 0);
  EXPECT_EQ(fit.resets(), 1u);
  EXPECT_EQ(fit.map(1000), 2'000'000'000'000LL + 1000);
}

TEST(ClockModel, ASenderStalledForHalfASecondDoesNotRestartTheFit) {
  // 1 kHz receive stamps, 20 us floor plus jitter. At 3 s the sender is descheduled for 500 ms
  // and then sends its backlog at once: those frames arrive up to 500 ms late. The fit must keep
  // its model (a restart put it on the first late frame, and the backlog's sample times went out
  // by hundreds of milliseconds: a table-to-IMU misalignment of 690 us RMS over a 6 s campaign).
  std::mt19937_64 rng(17);
  std::exponential_distribution<double> jitter(1.0 / 20e3);
  ClockFit fit;
  const std::int64_t host0 = 1'000'000'000'000LL;
  double worst_us = 0.0;
  for (int k = 0; k < 6000; ++k) {
    const std::int64_t dev = std::int64_t{k} * 1'000'000;
    const std::int64_t true_host = host0 + dev;
    std::int64_t rx = true_host + static_cast<std::int64_t>(20e3 + jitter(rng));
    if (k >= 3000 && k < 3500) rx = host0 + 3'500'000'000LL + (k - 3000) * 2'000;  // the backlog
    fit.add(dev, rx, rx - dev);
    if (k > 1000) worst_us = std::max(worst_us, std::fabs(static_cast<double>(fit.map(dev) - true_host - 20'000) / 1e3));
  }
  EXPECT_EQ(fit.resets(), 0u);
  EXPECT_LT(worst_us, 10.0);
}

TEST(ClockModel, ALateObservationRestartsTheFitOnlyWhenEveryOneStaysLate) {
  // A device clock that stops for a second and resumes (every later stamp is a second late) is a
  // jump, confirmed after late_confirm_ns of device time; and a device clock that jumps forward
  // (stamps earlier than the model) is one at once.
  ClockFit fit;
  for (std::int64_t k = 0; k < 3000; ++k) fit.add(k * 1'000'000, 5'000'000'000LL + k * 1'000'000, 0);
  for (std::int64_t k = 3000; k < 4000; ++k) fit.add(k * 1'000'000, 6'000'000'000LL + k * 1'000'000, 0);
  EXPECT_EQ(fit.resets(), 0u) << "1 s of lateness is not yet a jump";
  for (std::int64_t k = 4000; k < 6000; ++k) fit.add(k * 1'000'000, 6'000'000'000LL + k * 1'000'000, 0);
  EXPECT_EQ(fit.resets(), 1u);
  EXPECT_NEAR(static_cast<double>(fit.map(6'000'000'000LL) - 12'000'000'000LL), 0.0, 1e3);
  fit.add(9'000'000'000LL, 12'001'000'000LL, 0);
  EXPECT_EQ(fit.resets(), 2u);
}

TEST(ClockModel, ASlowRoundTripIsNotAJump) {
  // A reply held up 400 ms by a loaded host: its midpoint may be 200 ms off, as its round trip
  // says; a jump is what the round trip cannot explain.
  ClockFitConfig cfg;
  cfg.lower_envelope = false;
  ClockFit fit(cfg);
  for (std::int64_t k = 0; k < 200; ++k) fit.add(k * 10'000'000, 7'000'000'000LL + k * 10'000'000, 100'000);
  fit.add(2'000'000'000LL, 7'000'000'000LL + 2'000'000'000LL + 190'000'000LL, 400'000'000);
  EXPECT_EQ(fit.resets(), 0u);
  EXPECT_NEAR(static_cast<double>(fit.map(2'010'000'000LL) - 9'010'000'000LL), 0.0, 1e3);
  fit.add(2'020'000'000LL, 7'000'000'000LL + 2'020'000'000LL + 190'000'000LL, 100'000);
  EXPECT_EQ(fit.resets(), 1u);
}
