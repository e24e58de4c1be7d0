// The Arduino sketch itself, compiled on the host against a stub of the Arduino API
// (test/drive/arduino_stub): ready line, acks, rejected lines, failsafe values, the 250 ms protocol
// watchdog and the hardware one.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "apps/arduino/act_rover/act_rover.ino"

namespace {

std::string line(RoverMessage m) {
  char out[ROVER_MAX_LINE + 1];
  const size_t n = rover_format(&m, out, sizeof out);
  return std::string(out, n);
}

std::string drive(uint16_t seq, uint16_t steering, uint16_t throttle) { return line({'C', 3, {seq, steering, throttle}}); }

// The board's output, parsed.
std::vector<RoverMessage> replies() {
  std::vector<RoverMessage> out;
  RoverLineReader reader;
  rover_reader_init(&reader);
  for (char c : Serial.take_output()) {
    if (!rover_reader_push(&reader, c)) continue;
    RoverMessage m{};
    EXPECT_EQ(rover_parse(reader.text, reader.length, &m), ROVER_OK) << reader.text;
    out.push_back(m);
  }
  return out;
}

// Timer1 runs at 2 MHz on a 16 MHz board: two ticks per microsecond.
uint16_t steering_us() { return static_cast<uint16_t>(OCR1A / 2); }
uint16_t throttle_us() { return static_cast<uint16_t>(OCR1B / 2); }

void run_for_ms(uint32_t ms) {
  for (uint32_t i = 0; i < ms; ++i) {
    ++arduino_stub::now_ms;
    loop();
  }
}

class Sketch : public ::testing::Test {
 protected:
  void SetUp() override {
    arduino_stub::now_ms = 1000;
    Serial.take_output();
    arduino_stub::wdt_timeout = -1;  // as at power-up: setup() must switch it on
    setup();
  }
};

TEST_F(Sketch, BootsNeutralWithA50HzFrameAndSaysReady) {
  EXPECT_EQ(steering_us(), 1500);
  EXPECT_EQ(throttle_us(), 1500);
  EXPECT_EQ(ICR1, 39999);  // 20 ms at 2 MHz
  EXPECT_EQ(Serial.baud(), 115200);
  const auto r = replies();
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].type, 'R');
  EXPECT_EQ(r[0].fields[0], ROVER_PROTOCOL_VERSION);
  EXPECT_EQ(r[0].fields[1], ROVER_WATCHDOG_MS);
  Serial.feed(line({'H', 0, {0, 0, 0}}));
  loop();
  const auto again = replies();
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(again[0].type, 'R');
}

TEST_F(Sketch, HardwareWatchdogIsOnAndEveryLoopPetsIt) {
  // A hung sketch would keep Timer1 on its last pulse: the AVR watchdog must reset it first.
  ASSERT_GT(arduino_stub::wdt_timeout_ms(), 0) << "setup() leaves the hardware watchdog off";
  EXPECT_LT(arduino_stub::wdt_timeout_ms(), static_cast<int>(ROVER_WATCHDOG_MS));
  const uint32_t resets = arduino_stub::wdt_resets;
  run_for_ms(300);
  EXPECT_EQ(arduino_stub::wdt_resets, resets + 300);
  EXPECT_EQ(arduino_stub::wdt_last_reset_ms, arduino_stub::now_ms);
}

TEST_F(Sketch, AppliesAndAcknowledgesDriveCommands) {
  replies();
  Serial.feed(drive(7, 1700, 1600));
  loop();
  EXPECT_EQ(steering_us(), 1700);
  EXPECT_EQ(throttle_us(), 1600);
  const auto r = replies();
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].type, 'A');
  EXPECT_EQ(r[0].fields[0], 7);
}

TEST_F(Sketch, RejectsCorruptedLinesAndKeepsItsOutputs) {
  Serial.feed(drive(1, 1600, 1550));
  loop();
  replies();
  std::string corrupted = drive(2, 1900, 1900);
  corrupted[4] = '9';  // seq 2 -> 9: the CRC no longer matches
  Serial.feed(corrupted + std::string(60, 'x') + "\n" + line({'A', 1, {3, 0, 0}}));
  loop();
  EXPECT_EQ(steering_us(), 1600);
  EXPECT_EQ(throttle_us(), 1550);
  const auto r = replies();
  ASSERT_EQ(r.size(), 3u);
  for (const auto& m : r) EXPECT_EQ(m.type, 'E');
  EXPECT_EQ(r[0].fields[0], ROVER_ERR_CHECKSUM);
  EXPECT_EQ(r[1].fields[0], ROVER_ERR_TOO_LONG);
  EXPECT_EQ(r[2].fields[0], ROVER_ERR_UNKNOWN_TYPE);  // a board-to-host message
}

TEST_F(Sketch, GoesToItsFailsafeOutputsAfter250msWithoutACommand) {
  Serial.feed(line({'F', 3, {0, 1480, 1520}}));  // the host's calibrated center / neutral
  Serial.feed(drive(1, 1800, 1700));
  loop();
  replies();
  run_for_ms(ROVER_WATCHDOG_MS);
  EXPECT_EQ(throttle_us(), 1700) << "still within the timeout";
  Serial.feed(drive(2, 1800, 1650));  // a command resets the timeout
  loop();
  run_for_ms(ROVER_WATCHDOG_MS);
  EXPECT_EQ(throttle_us(), 1650);
  run_for_ms(1);
  EXPECT_EQ(steering_us(), 1480);
  EXPECT_EQ(throttle_us(), 1520);
  auto r = replies();
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(r.back().type, 'N');
  run_for_ms(1000);
  EXPECT_TRUE(replies().empty()) << "N is sent once per timeout";
  // A corrupted line does not count as a command.
  std::string corrupted = drive(3, 1600, 1600);
  corrupted[corrupted.size() - 2] = corrupted[corrupted.size() - 2] == '0' ? '1' : '0';
  Serial.feed(corrupted);
  loop();
  EXPECT_EQ(throttle_us(), 1520);
}

}  // namespace
