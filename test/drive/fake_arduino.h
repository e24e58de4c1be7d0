// A pseudo-terminal that stands in for the Arduino: it answers hello lines with the ready line,
// parses every line the host writes with the shared protocol unit, acknowledges commands and keeps
// them (with arrival times) for the test to check.
#pragma once

#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "apps/arduino/act_rover/rover_protocol.h"

namespace act::drive::test {

using Clock = std::chrono::steady_clock;

struct ReceivedLine {
  Clock::time_point when;
  RoverMessage message;
};

class FakeArduino {
 public:
  /// With `link_path`, the port is reached through a symlink there, so replace() can swap in a new
  /// pseudo-terminal at the same path (a board that was unplugged and plugged back in).
  explicit FakeArduino(std::string link_path = "");
  ~FakeArduino();
  FakeArduino(const FakeArduino&) = delete;
  FakeArduino& operator=(const FakeArduino&) = delete;

  /// The path the host opens.
  std::string port_path() const;
  /// Hangs up (the host's next write fails) and, with a symlink, attaches a fresh pseudo-terminal.
  void replace();
  /// Stops answering hello lines (a board that never becomes ready).
  void set_silent(bool silent);
  /// Stops acknowledging commands while still taking them (a board whose transmit line broke).
  void set_acking(bool acking);

  /// Every valid C and F line received so far; `generation` counts replace() calls at receipt.
  struct Command {
    Clock::time_point when;
    char type;
    uint16_t seq, steering_us, throttle_us;
    int generation;
  };
  std::vector<Command> commands() const;
  /// Lines that failed to parse (the host must never send one).
  std::vector<std::string> bad_lines() const;
  int hellos() const;

 private:
  void open_pty();
  void run();
  void handle(const char* line, size_t length);
  void reply(const RoverMessage& message);

  std::string link_path_;
  mutable std::mutex mutex_;
  int master_ = -1;            // guarded by mutex_
  int held_slave_ = -1;        // guarded by mutex_; keeps the pty alive between host opens
  std::string slave_path_;     // guarded by mutex_
  int generation_ = 0;         // guarded by mutex_
  bool silent_ = false;        // guarded by mutex_
  bool acking_ = true;         // guarded by mutex_
  bool stop_ = false;          // guarded by mutex_
  std::vector<Command> commands_;     // guarded by mutex_
  std::vector<std::string> bad_lines_;  // guarded by mutex_
  int hellos_ = 0;             // guarded by mutex_
  RoverLineReader reader_{};   // reader thread only
  std::thread thread_;
};

}  // namespace act::drive::test
