// The shared serial protocol unit (compiled into the Arduino sketch too).
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "apps/arduino/act_rover/rover_protocol.h"

namespace {

std::string format(RoverMessage m) {
  char line[ROVER_MAX_LINE + 1];
  const size_t n = rover_format(&m, line, sizeof line);
  return std::string(line, n);
}

RoverError parse(const std::string& line, RoverMessage* out) {
  std::string body = line;
  if (!body.empty() && body.back() == '\n') body.pop_back();
  return rover_parse(body.c_str(), body.size(), out);
}

TEST(RoverProtocol, FormatsAndParsesEveryMessageType) {
  const RoverMessage messages[] = {{'C', 3, {7, 1500, 1600}}, {'F', 3, {65535, 800, 2200}}, {'H', 0, {0, 0, 0}},
                                   {'R', 2, {1, 250, 0}},      {'A', 1, {42, 0, 0}},        {'E', 1, {1, 0, 0}},
                                   {'N', 0, {0, 0, 0}}};
  for (const RoverMessage& m : messages) {
    const std::string line = format(m);
    ASSERT_FALSE(line.empty()) << m.type;
    EXPECT_EQ(line.back(), '\n');
    EXPECT_LE(line.size(), size_t{ROVER_MAX_LINE});
    RoverMessage back{};
    ASSERT_EQ(parse(line, &back), ROVER_OK) << line;
    EXPECT_EQ(back.type, m.type);
    ASSERT_EQ(back.field_count, m.field_count);
    for (int i = 0; i < m.field_count; ++i) EXPECT_EQ(back.fields[i], m.fields[i]);
  }
}

TEST(RoverProtocol, ReadmeExamplesAreExact) {
  EXPECT_EQ(format({'H', 0, {0, 0, 0}}), "$H*FF\n");
  EXPECT_EQ(format({'R', 2, {1, 250, 0}}), "$R,1,250*F2\n");
  EXPECT_EQ(format({'C', 3, {17, 1500, 1650}}), "$C,17,1500,1650*8B\n");
  EXPECT_EQ(format({'A', 1, {17, 0, 0}}), "$A,17*5D\n");
}

TEST(RoverProtocol, KnownLineAndCrc) {
  // CRC-8/SMBUS (poly 0x07, init 0) check value of "123456789" is 0xF4.
  EXPECT_EQ(rover_crc8("123456789", 9), 0xF4);
  EXPECT_EQ(format({'C', 3, {1, 1500, 1500}}), "$C,1,1500,1500*" + [] {
    char hex[3];
    std::snprintf(hex, sizeof hex, "%02X", rover_crc8("C,1,1500,1500", 13));
    return std::string(hex);
  }() + "\n");
}

TEST(RoverProtocol, RejectsEverySingleByteCorruption) {
  const std::string line = format({'C', 3, {123, 1500, 1700}});
  const std::string body = line.substr(0, line.size() - 1);
  for (size_t i = 0; i < body.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::string bad = body;
      bad[i] = static_cast<char>(bad[i] ^ (1 << bit));
      if (bad[i] == '\n' || bad[i] == '\r') continue;  // would end the line early: a different, shorter line
      RoverMessage m{};
      EXPECT_NE(rover_parse(bad.c_str(), bad.size(), &m), ROVER_OK) << "byte " << i << " bit " << bit << ": " << bad;
    }
  }
}

TEST(RoverProtocol, ClassifiesBadLines) {
  RoverMessage m{};
  EXPECT_EQ(parse("hello", &m), ROVER_ERR_MALFORMED);
  EXPECT_EQ(parse("$C,1,1500,1500*zz", &m), ROVER_ERR_MALFORMED);
  std::string wrong_crc = format({'C', 3, {1, 1500, 1500}});
  wrong_crc[wrong_crc.size() - 2] = wrong_crc[wrong_crc.size() - 2] == '0' ? '1' : '0';
  EXPECT_EQ(parse(wrong_crc, &m), ROVER_ERR_CHECKSUM);
  auto with_crc = [](const std::string& body) {
    char hex[3];
    std::snprintf(hex, sizeof hex, "%02X", rover_crc8(body.c_str(), body.size()));
    return "$" + body + "*" + hex;
  };
  EXPECT_EQ(parse(with_crc("C,1,1500,2300"), &m), ROVER_ERR_RANGE);
  EXPECT_EQ(parse(with_crc("C,1,700,1500"), &m), ROVER_ERR_RANGE);
  EXPECT_EQ(parse(with_crc("Z,1"), &m), ROVER_ERR_UNKNOWN_TYPE);
  EXPECT_EQ(parse(with_crc("C,1,1500"), &m), ROVER_ERR_UNKNOWN_TYPE);
  EXPECT_EQ(parse(with_crc("C,1,,1500"), &m), ROVER_ERR_MALFORMED);
  EXPECT_EQ(parse(with_crc("C,1,1500,-1"), &m), ROVER_ERR_MALFORMED);
  EXPECT_EQ(parse(with_crc("A,65536"), &m), ROVER_ERR_MALFORMED);
  EXPECT_EQ(parse(with_crc("A,000001"), &m), ROVER_ERR_MALFORMED);
  EXPECT_EQ(parse(std::string(ROVER_MAX_LINE + 5, 'x'), &m), ROVER_ERR_TOO_LONG);
  EXPECT_EQ(parse(with_crc("A,7") + "\r", &m), ROVER_OK);
  EXPECT_EQ(m.fields[0], 7);
}

TEST(RoverProtocol, ReaderSplitsLinesAndFlagsOverlongOnes) {
  RoverLineReader r;
  rover_reader_init(&r);
  std::vector<std::string> lines;
  std::vector<int> overflow;
  const std::string stream = "$A,1*00\n\n" + std::string(100, 'y') + "\nabc\n";
  for (char c : stream) {
    if (rover_reader_push(&r, c)) {
      lines.emplace_back(r.text, r.length);
      overflow.push_back(r.overflow);
    }
  }
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0], "$A,1*00");
  EXPECT_EQ(lines[1], "");
  EXPECT_EQ(overflow, (std::vector<int>{0, 0, 1, 0}));
  EXPECT_EQ(lines[3], "abc");
}

TEST(RoverProtocol, WatchdogHandlesClockWrap) {
  EXPECT_FALSE(rover_watchdog_expired(1000, 1000 + ROVER_WATCHDOG_MS));
  EXPECT_TRUE(rover_watchdog_expired(1000, 1001 + ROVER_WATCHDOG_MS));
  EXPECT_FALSE(rover_watchdog_expired(0xFFFFFF80u, 0x10u));  // 144 ms across the wrap
  EXPECT_TRUE(rover_watchdog_expired(0xFFFFFF80u, 0x80u));   // 256 ms across the wrap
}

}  // namespace
