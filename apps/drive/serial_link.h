// The host end of the Arduino link: a termios serial port, the protocol handshake (ready line,
// failsafe values), commands with sequence numbers, ack bookkeeping, and reconnects after errors.
// --dry-run swaps in DryRunLink, which prints the same lines instead.
#pragma once

#include <chrono>
#include <cstdint>
#include <ostream>
#include <string>

#include "apps/arduino/act_rover/rover_protocol.h"
#include "apps/drive/calibration.h"

namespace act::drive {

using Clock = std::chrono::steady_clock;

/// A raw, non-blocking serial port (8N1, no flow control). Throws act::Error from open().
class SerialPort {
 public:
  SerialPort() = default;
  ~SerialPort() { close(); }
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  void open(const std::string& path, int baud);
  void close();
  int fd() const { return fd_; }
  /// Writes every byte, waiting at most `timeout` for the port to accept them. False and `error`
  /// set on failure (a vanished device, a full buffer that does not drain).
  bool write_all(const char* data, size_t size, std::chrono::milliseconds timeout, std::string& error);
  /// Reads what has arrived, waiting at most `timeout` for the first byte. Returns the byte count
  /// (0 = nothing), or -1 with `error` set when the port failed.
  long read_some(char* buffer, size_t capacity, std::chrono::milliseconds timeout, std::string& error);

 private:
  int fd_ = -1;
};

/// Where commands go: the serial link or, with --dry-run, standard output.
class ActuatorLink {
 public:
  virtual ~ActuatorLink() = default;
  /// Sends one command if the link is up; false when it is down (reconnecting) or the write failed.
  virtual bool send(PwmCommand command, Clock::time_point now) = 0;
  /// Reads acknowledgements and advances reconnects; called every control tick.
  virtual void poll(Clock::time_point now) = 0;
  /// Last words on every exit path: send `neutral`, wait briefly for its ack, close. Idempotent.
  virtual void shutdown(PwmCommand neutral) = 0;
  /// Counters for the summary, one line.
  virtual std::string summary() const = 0;
};

struct SerialLinkOptions {
  std::string path;
  int baud = 115200;
  /// How long to wait for the board's ready line after opening the port (classic boards reset).
  std::chrono::milliseconds ready_timeout{5000};
  /// When to start asking with hello lines (a board that did not reset says nothing by itself).
  std::chrono::milliseconds hello_delay{1000};
  std::chrono::milliseconds hello_interval{500};
  /// Pause between reconnect attempts after a serial error.
  std::chrono::milliseconds reconnect_interval{500};
  /// Longest a single command write may block the control loop.
  std::chrono::milliseconds write_timeout{20};
  /// Longest a sent command may go without any acknowledgement from the board before the link counts
  /// as lost: alarm, close, reconnect (the board, if it still listens, then times out to failsafe).
  std::chrono::milliseconds ack_timeout{ROVER_WATCHDOG_MS};
  /// The outputs the board falls back to by itself (sent as the F line after every handshake).
  PwmCommand failsafe;
};

class SerialLink : public ActuatorLink {
 public:
  SerialLink(SerialLinkOptions options, std::ostream& log);
  ~SerialLink() override;

  /// Opens the port and waits for the board's ready line, then sets its failsafe outputs and sends
  /// neutral. Throws act::Error naming the port and the likely cause when that fails.
  void connect();

  bool send(PwmCommand command, Clock::time_point now) override;
  void poll(Clock::time_point now) override;
  void shutdown(PwmCommand neutral) override;
  std::string summary() const override;

  bool ready() const { return state_ == State::kReady; }
  uint64_t ack_timeouts() const { return ack_timeouts_; }

 private:
  enum class State { kDisconnected, kWaitingReady, kReady };
  bool try_open(Clock::time_point now);
  void fail_link(const std::string& why, Clock::time_point now);
  bool send_message(char type, PwmCommand command);
  void handle_line(const RoverLineReader& reader);
  void read_input(std::chrono::milliseconds timeout, Clock::time_point now);
  void become_ready();
  void check_acks(Clock::time_point now);

  SerialLinkOptions options_;
  std::ostream& log_;
  SerialPort port_;
  State state_ = State::kDisconnected;
  bool connecting_ = false;  // inside connect(): errors end in its exception
  RoverLineReader reader_{};
  Clock::time_point opened_at_{}, last_hello_{}, next_attempt_{};
  uint16_t next_seq_ = 0;
  uint16_t last_sent_seq_ = 0;
  uint16_t last_acked_seq_ = 0xFFFF;
  bool awaiting_ack_ = false;          // a sent line has not been acknowledged yet
  Clock::time_point awaiting_since_{};  // since then, or since the last ack, whichever is later
  uint64_t commands_sent_ = 0, acks_ = 0, rejected_ = 0, reconnects_ = 0, errors_ = 0, watchdog_notices_ = 0,
           ack_timeouts_ = 0;
  std::string last_error_;
};

/// --dry-run: prints each protocol line (with a time stamp) instead of writing it to a port.
class DryRunLink : public ActuatorLink {
 public:
  explicit DryRunLink(std::ostream& out) : out_(out) {}
  bool send(PwmCommand command, Clock::time_point now) override;
  void poll(Clock::time_point) override {}
  void shutdown(PwmCommand neutral) override;
  std::string summary() const override;

 private:
  std::ostream& out_;
  Clock::time_point start_ = Clock::now();
  uint16_t next_seq_ = 0;
  uint64_t commands_ = 0;
  bool shut_down_ = false;
};

/// Formats a C (drive) or F (failsafe) line; returns its length.
size_t format_command(char type, uint16_t seq, PwmCommand command, char* out, size_t capacity);

}  // namespace act::drive
