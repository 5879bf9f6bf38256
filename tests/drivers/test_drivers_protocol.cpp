// The pure wire layer: word-order helpers, register maps, the CAN record codec and classic-CAN
// reassembly, the ACL command/reply codec, the clock model; plus randomized fuzz tests of every
// parser (fixed seed, bounded iterations).
#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "drivers/acl_protocol.hpp"
#include "drivers/can_protocol.hpp"
#include "drivers/clock_model.hpp"
#include "drivers/register_map.hpp"
#include "drivers/word_order.hpp"

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
  EXPECT_EQ(m.process_value, 2820);
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
  EXPECT_EQ(m.address_end(), 2822);
}

TEST(RegisterMap, BuiltInEzt570iStyleAndEncoding) {
  const RegisterMap m = load_register_map("csz-ezt570i");
  EXPECT_EQ(m.encoding, ValueEncoding::scaled_i16);
  EXPECT_DOUBLE_EQ(m.scale, 10.0);
  EXPECT_TRUE(m.ramp_rate_per_min);
  const auto regs = encode_value(m, -12.34);
  ASSERT_TRUE(regs);
  ASSERT_EQ(regs->size(), 1u);
  EXPECT_DOUBLE_EQ(*decode_value(m, *regs), -12.3);
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
  EXPECT_NE(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":0},"process_value":1,"setpoint":2})")
                .find("scale"),
            std::string::npos);
  EXPECT_NE(msg(R"({"format":"imucal-chamber-map/1","value":{"type":"int16","scale":10},"process_value":1,"setpoint":2,
                   "alarms":[{"name":"a","address":3}]})")
                .find("alarm 'a'"),
            std::string::npos);
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

TEST(CanProtocol, Crc32CheckValue) {
  const char* s = "123456789";
  EXPECT_EQ(can::crc32(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(s), 9)), 0xCBF43926u);
}

TEST(CanProtocol, SampleRecordLayoutIsBigEndianAsDocumented) {
  can::SampleRecord r;
  r.status = 0x0102;
  r.sequence = 0x0A0B0C0D;
  r.latency_us = 250;
  r.device_time_ns = 0x0011223344556677ULL;
  r.gyro_counts = {1, -1, 0x12345678};
  r.accel_counts = {-2, 3, INT32_MIN};
  r.gyro_temp_cC = 2534;
  r.accel_temp_cC = -1;
  const auto b = can::encode(r);
  EXPECT_EQ(b[0], can::kTypeSample);
  EXPECT_EQ(b[1], can::kLayoutVersion);
  EXPECT_EQ(b[2], 0x01);
  EXPECT_EQ(b[3], 0x02);
  EXPECT_EQ(b[4], 0x0A);
  EXPECT_EQ(b[7], 0x0D);
  EXPECT_EQ(b[11], 250);
  EXPECT_EQ(b[12], 0x00);
  EXPECT_EQ(b[19], 0x77);
  EXPECT_EQ(b[23], 0x01);                                  // gyro x = 1
  EXPECT_EQ(b[24], 0xFF);                                  // gyro y = -1
  EXPECT_EQ(b[28], 0x12);                                  // gyro z
  EXPECT_EQ(b[32], 0xFF);                                  // accel x = -2
  EXPECT_EQ(b[40], 0x80);                                  // accel z = INT32_MIN
  EXPECT_EQ((b[44] << 8) | b[45], 2534);
  for (std::size_t i = 48; i < 60; ++i) EXPECT_EQ(b[i], 0);  // reserved
  const std::uint32_t crc = (std::uint32_t{b[60]} << 24) | (std::uint32_t{b[61]} << 16) | (std::uint32_t{b[62]} << 8) | b[63];
  EXPECT_EQ(crc, can::crc32(std::span<const std::uint8_t>(b.data(), 60)));
  can::Record out;
  ASSERT_EQ(can::decode(b, out), can::DecodeStatus::ok);
  const auto& d = std::get<can::SampleRecord>(out);
  EXPECT_EQ(d.sequence, r.sequence);
  EXPECT_EQ(d.device_time_ns, r.device_time_ns);
  EXPECT_EQ(d.gyro_counts, r.gyro_counts);
  EXPECT_EQ(d.accel_counts, r.accel_counts);
  EXPECT_EQ(d.accel_temp_cC, -1);
}

TEST(CanProtocol, TemperatureRecordRoundTrip) {
  can::TemperatureRecord t;
  t.page = 1;
  t.sequence = 65535;
  t.device_time_ns = 123456789;
  t.values_cC.fill(can::kNoTemperature);
  t.values_cC[0] = 2500;
  t.values_cC[2] = -4000;
  can::Record out;
  ASSERT_EQ(can::decode(can::encode(t), out), can::DecodeStatus::ok);
  const auto& d = std::get<can::TemperatureRecord>(out);
  EXPECT_EQ(d.page, 1);
  EXPECT_EQ(d.sequence, 65535);
  EXPECT_EQ(d.values_cC, t.values_cC);
}

TEST(CanProtocol, EveryBitFlipIsCaughtByTheCrc) {
  can::SampleRecord r;
  r.sequence = 77;
  r.gyro_counts = {100, 200, 300};
  const auto good = can::encode(r);
  for (std::size_t bit = 0; bit < 64 * 8; ++bit) {
    auto b = good;
    b[bit / 8] = static_cast<std::uint8_t>(b[bit / 8] ^ (1u << (bit % 8)));
    can::Record out;
    EXPECT_EQ(can::decode(b, out), can::DecodeStatus::bad_crc) << "bit " << bit;
  }
}

TEST(CanProtocol, WireFramesRoundTrip) {
  can::SampleRecord r;
  r.sequence = 5;
  const auto rec = can::encode(r);
  const auto fd = can::fd_frame(can::kIdSampleFd, rec);
  const auto wire = can::to_wire(fd);
  ASSERT_EQ(wire.size(), can::kCanFdMtu);
  const auto back = can::parse_wire(wire);
  ASSERT_TRUE(back);
  EXPECT_TRUE(back->fd);
  EXPECT_EQ(back->can_id, can::kIdSampleFd);
  EXPECT_EQ(back->len, 64);
  EXPECT_EQ(back->data, rec);
  const auto cmd = can::to_wire(can::command_frame(can::kCommandStart));
  ASSERT_EQ(cmd.size(), can::kCanMtu);
  const auto c = can::parse_wire(cmd);
  ASSERT_TRUE(c);
  EXPECT_FALSE(c->fd);
  EXPECT_EQ(c->data[0], can::kCommandStart);
  EXPECT_FALSE(can::parse_wire(std::vector<std::uint8_t>(40, 0)));
}

TEST(CanProtocol, ClassicFallbackReassemblesAndAbandonsBrokenSets) {
  can::SampleRecord r;
  r.sequence = 0x1234;
  const auto rec = can::encode(r);
  const auto parts = can::classic_frames(can::kIdSampleClassic, 0x34, rec);
  EXPECT_EQ(parts[9].len, 2);  // last slice carries one byte
  can::ClassicAssembler as(can::kIdSampleClassic);
  std::optional<std::array<std::uint8_t, 64>> got;
  for (const auto& p : parts) {
    ASSERT_FALSE(got);
    got = as.feed(p);
  }
  ASSERT_TRUE(got);
  EXPECT_EQ(*got, rec);
  EXPECT_EQ(as.incomplete(), 0u);

  // A lost middle part: the record is abandoned, never patched from the next sample.
  for (std::size_t i = 0; i < 10; ++i) {
    if (i != 4) {
      EXPECT_FALSE(as.feed(parts[i]));
    }
  }
  EXPECT_EQ(as.incomplete(), 1u);
  // Parts of another sample (different sequence byte) interleaved: abandoned as well.
  const auto other = can::classic_frames(can::kIdSampleClassic, 0x35, rec);
  for (std::size_t i = 0; i < 5; ++i) EXPECT_FALSE(as.feed(parts[i]));
  for (std::size_t i = 5; i < 10; ++i) EXPECT_FALSE(as.feed(other[i]));
  EXPECT_EQ(as.incomplete(), 2u);
  // And a clean set afterwards goes through.
  for (std::size_t i = 0; i < 10; ++i) got = as.feed(parts[i]);
  ASSERT_TRUE(got);
  EXPECT_EQ(*got, rec);
}

// Fuzz: random and mutated frames through the wire parser, the classic assembler and the record
// decoder. Nothing crashes; a mutated record never decodes as valid with different content.
TEST(CanProtocolFuzz, RandomAndMutatedFrames) {
  std::mt19937_64 rng(1234);
  can::ClassicAssembler as(can::kIdSampleClassic);
  can::SampleRecord base;
  base.sequence = 99;
  base.gyro_counts = {1, 2, 3};
  const auto good = can::encode(base);
  int decoded_ok = 0;
  for (int i = 0; i < 30000; ++i) {
    std::vector<std::uint8_t> bytes;
    switch (rng() % 4) {
      case 0: bytes.resize(rng() % 100); for (auto& b : bytes) b = static_cast<std::uint8_t>(rng()); break;
      case 1: bytes = can::to_wire(can::fd_frame(can::kIdSampleFd, good)); break;
      case 2: bytes = can::to_wire(can::classic_frames(can::kIdSampleClassic, 99, good)[rng() % 10]); break;
      default: bytes.resize(rng() % 2 ? can::kCanMtu : can::kCanFdMtu); for (auto& b : bytes) b = static_cast<std::uint8_t>(rng()); break;
    }
    // Mutate a few bytes.
    const int flips = static_cast<int>(rng() % 3);
    for (int k = 0; k < flips && !bytes.empty(); ++k) bytes[rng() % bytes.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    const auto f = can::parse_wire(bytes);
    if (!f) continue;
    std::optional<std::array<std::uint8_t, 64>> rec;
    if (as.owns(f->can_id)) rec = as.feed(*f);
    else if (f->fd && f->len == 64) rec = f->data;
    if (!rec) continue;
    can::Record out;
    if (can::decode(*rec, out) == can::DecodeStatus::ok) {
      ++decoded_ok;
      if (const auto* s = std::get_if<can::SampleRecord>(&out)) {
        // The only valid record in play is `good` (a random 64-byte record passing CRC-32 and
        // type checks is a 2^-32 event).
        EXPECT_EQ(*rec, good);
        EXPECT_EQ(s->sequence, 99u);
      }
    }
  }
  EXPECT_GT(decoded_ok, 100);
}

// ------------------------------------------------------------------------------------------------
// ACL

TEST(AclProtocol, CommandsRoundTripThroughTheirText) {
  acl::Command c;
  c.op = acl::Op::demand_oscillation;
  c.axis = 2;
  c.args = {1.25, 0.5, -90.0};
  EXPECT_EQ(acl::format_command(c), ":DEM:OSC 2,1.25,0.5,-90");
  c.op = acl::Op::limit_position;
  c.mode = TableMode::rate;
  c.args = {-10.5, 20.0, 0.0};
  EXPECT_EQ(acl::format_command(c), ":LIM:POS 2,RATE,-10.5,20");
  const auto p = acl::parse_command(" :lim:pos 2, rate ,-10.5,20\r");
  ASSERT_TRUE(std::holds_alternative<acl::Command>(p));
  const auto& q = std::get<acl::Command>(p);
  EXPECT_EQ(q.op, acl::Op::limit_position);
  EXPECT_EQ(q.mode, TableMode::rate);
  EXPECT_DOUBLE_EQ(q.args[0], -10.5);
}

TEST(AclProtocol, CommandErrorsCarryCodes) {
  auto code = [](std::string_view line) {
    const auto r = acl::parse_command(line);
    return std::holds_alternative<acl::ParseError>(r) ? std::get<acl::ParseError>(r).code : 0;
  };
  EXPECT_EQ(code(":FOO 1"), acl::kErrSyntax);
  EXPECT_EQ(code(":DEM:POS 4,10"), acl::kErrArgument);
  EXPECT_EQ(code(":DEM:POS 1,abc"), acl::kErrArgument);
  EXPECT_EQ(code(":DEM:POS 1,nan"), acl::kErrArgument);
  EXPECT_EQ(code(":DEM:POS 1"), acl::kErrArgument);
  EXPECT_EQ(code(":MODE 1,FAST"), acl::kErrArgument);
  EXPECT_EQ(code(":READ:POS?"), 0);
}

TEST(AclProtocol, RepliesParseWithAndWithoutChecksum) {
  acl::Reply r;
  r.kind = acl::Reply::Kind::positions;
  r.time_us = 123456789012;
  r.angle_deg = {1.5, -0.25, 359.9999999};
  r.rate_dps = {10.0, 0.0, -3.0};
  const std::string body = acl::format_reply(r);
  for (bool sum : {false, true}) {
    std::string line = acl::frame_line(body, sum);
    line.pop_back();  // the terminator
    const auto p = acl::parse_reply(line, sum);
    ASSERT_TRUE(p) << p.error().message;
    EXPECT_EQ(p->kind, acl::Reply::Kind::positions);
    EXPECT_EQ(p->time_us, r.time_us);
    EXPECT_EQ(p->angle_deg, r.angle_deg);
    EXPECT_EQ(p->rate_dps, r.rate_dps);
  }
  acl::Reply s;
  s.kind = acl::Reply::Kind::status;
  s.interlock = InterlockState::closed;
  s.modes = {TableMode::rate, TableMode::off, TableMode::synthesis};
  s.flags = {acl::flag::kMoving, acl::flag::kAtLimit | acl::flag::kFault, 0};
  const auto ps = acl::parse_reply(acl::format_reply(s), false);
  ASSERT_TRUE(ps);
  EXPECT_EQ(ps->interlock, InterlockState::closed);
  EXPECT_EQ(ps->modes, s.modes);
  EXPECT_EQ(ps->flags, s.flags);
  const auto e = acl::parse_reply("ERR 200,interlock open", false);
  ASSERT_TRUE(e);
  EXPECT_EQ(e->error_code, 200);
  EXPECT_EQ(acl::parse_reply("OK*00", true).code(), DriverErrc::crc_error);
  EXPECT_TRUE(acl::parse_reply("OK*04", true));  // 0x4F ^ 0x4B
}

TEST(AclProtocol, ChecksumCatchesEverySingleByteCorruption) {
  acl::Reply r;
  r.kind = acl::Reply::Kind::positions;
  r.time_us = 42;
  r.angle_deg = {12.5, 45.0, 90.125};
  std::string line = acl::frame_line(acl::format_reply(r), true);
  line.pop_back();
  for (std::size_t i = 0; i < line.size(); ++i)
    for (int delta : {1, 2, 7, 64}) {
      std::string bad = line;
      bad[i] = static_cast<char>(bad[i] ^ delta);
      const auto p = acl::parse_reply(bad, true);
      EXPECT_FALSE(p) << bad;
    }
}

// Fuzz: random printable and binary lines, and mutations of valid replies, through both parsers.
TEST(AclProtocolFuzz, RandomLinesNeverCrashAndValidOnesRoundTrip) {
  std::mt19937_64 rng(99);
  const char alphabet[] = ":*?,. -+0123456789eEABCDEFGHIKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz\r\t";
  const std::vector<std::string> seeds = {"OK", "ERR 201,limit", "POS 1,2,3,4,5,6,7", "STAT 5,CLOSED,OFF,POS,RATE,0,8,F",
                                          "IDN IMUCAL", ":DEM:POS 1,45", ":MODE 3,SYNT", ":DEM:OSC 1,1,2,3",
                                          ":LIM:ACC 2,POS,100", ":CONF:WDOG 0.5", ":SYST:CHEC ON"};
  int commands_ok = 0;
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
    (void)acl::parse_reply(line, rng() % 2 == 0);
    const auto c = acl::parse_command(line);
    if (const auto* cmd = std::get_if<acl::Command>(&c)) {
      ++commands_ok;
      // A command that parses formats to text that parses to the same command.
      const auto again = acl::parse_command(acl::format_command(*cmd));
      ASSERT_TRUE(std::holds_alternative<acl::Command>(again)) << line;
      const auto& b = std::get<acl::Command>(again);
      EXPECT_EQ(b.op, cmd->op);
      EXPECT_EQ(b.axis, cmd->axis);
      EXPECT_EQ(b.args, cmd->args);
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
