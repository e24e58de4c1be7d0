// SerialLink against a pseudo-terminal Arduino: when the board stops acknowledging, the host raises
// the alarm and drops the link within the board's own watchdog time, then reconnects neutral first.
#include <gtest/gtest.h>

#include <sstream>
#include <thread>

#include "apps/drive/serial_link.h"
#include "drive/drive_test_util.h"
#include "drive/fake_arduino.h"

namespace act::drive::test {
namespace {

constexpr PwmCommand kNeutral{1500, 1500};
constexpr PwmCommand kDriving{1600, 1700};

// Sends kDriving every 33 ms (30 Hz) until `until` or until the link is down; returns when it went down.
std::optional<Clock::time_point> drive_until(SerialLink& link, Clock::time_point until) {
  while (Clock::now() < until) {
    const auto now = Clock::now();
    if (!link.send(kDriving, now)) return now;
    std::this_thread::sleep_for(std::chrono::milliseconds(33));
  }
  return std::nullopt;
}

TEST(SerialLink, AlarmsAndDropsTheLinkWhenAcksStop) {
  FakeArduino board;
  std::ostringstream log;
  SerialLinkOptions options;
  options.path = board.port_path();
  options.hello_delay = std::chrono::milliseconds(0);
  options.failsafe = kNeutral;
  SerialLink link(options, log);
  link.connect();
  ASSERT_TRUE(link.ready());

  // Acknowledged commands: the link stays up.
  EXPECT_FALSE(drive_until(link, Clock::now() + std::chrono::milliseconds(600)).has_value()) << log.str();
  EXPECT_EQ(link.ack_timeouts(), 0u);

  // The board still takes commands but its acks stop: down within the ack timeout plus a tick.
  board.set_acking(false);
  const auto acks_stopped = Clock::now();
  const auto down = drive_until(link, acks_stopped + std::chrono::milliseconds(1500));
  ASSERT_TRUE(down.has_value()) << "the link stayed up without acks\n" << log.str();
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(*down - acks_stopped).count();
  report_fault_timing("the board's acks stop", static_cast<double>(ms),
                      "the alarm and the dropped link (the board then fails safe 250 ms after its last command)");
  EXPECT_LE(ms, ROVER_WATCHDOG_MS + 2 * 33 + 50) << log.str();
  EXPECT_GE(link.ack_timeouts(), 1u);
  EXPECT_NE(log.str().find("no acknowledgement from the board"), std::string::npos) << log.str();
  EXPECT_NE(link.summary().find("ack timeouts"), std::string::npos) << link.summary();

  // Acks come back: it reconnects, and the first command after the handshake is neutral.
  board.set_acking(true);
  const size_t before = board.commands().size();
  const auto deadline = Clock::now() + std::chrono::seconds(5);
  while (!link.ready() && Clock::now() < deadline) {
    link.poll(Clock::now());
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(link.ready()) << log.str();
  const auto commands = board.commands();
  ASSERT_GE(commands.size(), before + 2);
  EXPECT_EQ(commands[before].type, 'F');
  EXPECT_EQ(commands[before + 1].type, 'C');
  EXPECT_EQ(commands[before + 1].steering_us, 1500);
  EXPECT_EQ(commands[before + 1].throttle_us, 1500);
  link.shutdown(kNeutral);
}

}  // namespace
}  // namespace act::drive::test
