#include "apps/drive/serial_link.h"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <iomanip>
#include <sstream>

#include "actengine/status.h"
#include "apps/drive/emergency_neutral.h"

namespace act::drive {
namespace {

speed_t baud_constant(int baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 500000: return B500000;
    case 1000000: return B1000000;
    default:
      fail(StatusCode::kInvalidArgument, "unsupported baud rate " + std::to_string(baud) +
                                              " (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 1000000)");
  }
}

int remaining_ms(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return left > 0 ? static_cast<int>(left) : 0;
}

const char* rover_error_name(unsigned code) {
  switch (code) {
    case ROVER_ERR_CHECKSUM: return "checksum mismatch";
    case ROVER_ERR_MALFORMED: return "malformed line";
    case ROVER_ERR_TOO_LONG: return "line too long";
    case ROVER_ERR_RANGE: return "pulse width out of range";
    case ROVER_ERR_UNKNOWN_TYPE: return "unknown message";
    default: return "unknown error";
  }
}

}  // namespace

size_t format_command(char type, uint16_t seq, PwmCommand command, char* out, size_t capacity) {
  RoverMessage message{type, 3, {seq, command.steering_us, command.throttle_us}};
  return rover_format(&message, out, capacity);
}

// ---- SerialPort ----

void SerialPort::open(const std::string& path, int baud) {
  close();
  const speed_t speed = baud_constant(baud);
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    std::string hint;
    if (err == ENOENT) hint = " (is the Arduino plugged in? act_drive --list-ports lists the serial ports found)";
    if (err == EACCES) hint = " (permission: add the user to the 'dialout' group)";
    if (err == EBUSY) hint = " (another program has it open)";
    fail(err == ENOENT ? StatusCode::kNotFound : StatusCode::kIoError,
         "cannot open serial port " + path + ": " + std::strerror(err) + hint);
  }
  termios tty{};
  if (::tcgetattr(fd, &tty) != 0) {
    const int err = errno;
    ::close(fd);
    fail(StatusCode::kInvalidArgument, "serial port " + path + " is not a terminal device: " + std::strerror(err));
  }
  ::cfmakeraw(&tty);
  tty.c_cflag |= CLOCAL | CREAD;
  tty.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | CRTSCTS);
  tty.c_cc[VMIN] = 0;
  tty.c_cc[VTIME] = 0;
  ::cfsetispeed(&tty, speed);
  ::cfsetospeed(&tty, speed);
  if (::tcsetattr(fd, TCSANOW, &tty) != 0) {
    const int err = errno;
    ::close(fd);
    fail(StatusCode::kIoError, "cannot configure serial port " + path + ": " + std::strerror(err));
  }
  ::tcflush(fd, TCIOFLUSH);  // drop whatever the board printed before we listened
  fd_ = fd;
}

void SerialPort::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool SerialPort::write_all(const char* data, size_t size, std::chrono::milliseconds timeout, std::string& error) {
  const auto deadline = Clock::now() + timeout;
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd_, data + done, size - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
      error = std::string("write failed: ") + std::strerror(errno);
      return false;
    }
    pollfd p{fd_, POLLOUT, 0};
    const int r = ::poll(&p, 1, remaining_ms(deadline));
    if (r == 0) {
      error = "write timed out after " + std::to_string(timeout.count()) + " ms (the port does not drain)";
      return false;
    }
    if (r < 0 && errno != EINTR) {
      error = std::string("poll failed: ") + std::strerror(errno);
      return false;
    }
    if (r > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
      error = "the port hung up";
      return false;
    }
  }
  return true;
}

long SerialPort::read_some(char* buffer, size_t capacity, std::chrono::milliseconds timeout, std::string& error) {
  pollfd p{fd_, POLLIN, 0};
  const int r = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (r < 0) {
    if (errno == EINTR) return 0;
    error = std::string("poll failed: ") + std::strerror(errno);
    return -1;
  }
  if (r == 0) return 0;
  if (!(p.revents & POLLIN) && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
    error = "the port hung up";
    return -1;
  }
  const ssize_t n = ::read(fd_, buffer, capacity);
  if (n < 0) {
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return 0;
    error = std::string("read failed: ") + std::strerror(errno);
    return -1;
  }
  return n;
}

// ---- SerialLink ----

SerialLink::SerialLink(SerialLinkOptions options, std::ostream& log) : options_(std::move(options)), log_(log) {
  rover_reader_init(&reader_);
  baud_constant(options_.baud);  // reject a bad baud rate before anything else
}

SerialLink::~SerialLink() {
  disarm_emergency_writes();
}

void SerialLink::connect() {
  // Failures here are reported by the exception below, not as "reconnecting" warnings.
  connecting_ = true;
  struct Done {
    bool& flag;
    ~Done() { flag = false; }
  } done{connecting_};
  const auto start = Clock::now();
  port_.open(options_.path, options_.baud);  // throws with the reason
  opened_at_ = start;
  last_hello_ = start;
  state_ = State::kWaitingReady;
  rover_reader_init(&reader_);
  while (state_ == State::kWaitingReady) {
    const auto now = Clock::now();
    if (now - start > options_.ready_timeout) {
      port_.close();
      state_ = State::kDisconnected;
      fail(StatusCode::kIoError,
           "no ready line from the board on " + options_.path + " within " +
               std::to_string(options_.ready_timeout.count()) + " ms at " + std::to_string(options_.baud) +
               " baud (is apps/arduino/act_rover uploaded, the baud rate the same, the port right?)");
    }
    poll(now);
    if (state_ == State::kDisconnected) fail(StatusCode::kIoError, "serial port " + options_.path + ": " + last_error_);
    if (state_ == State::kWaitingReady) read_input(std::chrono::milliseconds(10), now);
  }
}

bool SerialLink::try_open(Clock::time_point now) {
  try {
    port_.open(options_.path, options_.baud);
  } catch (const Error& e) {
    last_error_ = e.what();
    next_attempt_ = now + options_.reconnect_interval;
    return false;
  }
  opened_at_ = now;
  last_hello_ = now;
  rover_reader_init(&reader_);
  state_ = State::kWaitingReady;
  return true;
}

void SerialLink::fail_link(const std::string& why, Clock::time_point now) {
  disarm_emergency_writes();
  ++errors_;
  last_error_ = why;
  if (!connecting_) log_ << "act_drive: warning: serial " << options_.path << ": " << why << "; reconnecting every "
       << options_.reconnect_interval.count() << " ms (the board goes to failsafe by itself)\n";
  port_.close();
  state_ = State::kDisconnected;
  awaiting_ack_ = false;
  next_attempt_ = now + options_.reconnect_interval;
}

bool SerialLink::send_message(char type, PwmCommand command) {
  char line[ROVER_MAX_LINE + 1];
  const uint16_t seq = next_seq_++;
  const size_t length = format_command(type, seq, command, line, sizeof line);
  std::string error;
  if (!port_.write_all(line, length, options_.write_timeout, error)) {
    fail_link(error, Clock::now());
    return false;
  }
  last_sent_seq_ = seq;
  if (!awaiting_ack_) {
    awaiting_ack_ = true;
    awaiting_since_ = Clock::now();
  }
  if (type == 'C') ++commands_sent_;
  return true;
}

void SerialLink::become_ready() {
  const bool reconnected = commands_sent_ > 0;
  state_ = State::kReady;
  if (!send_message('F', options_.failsafe)) return;
  if (!send_message('C', options_.failsafe)) return;  // neutral first, on every (re)connect
  if (reconnected) {
    ++reconnects_;
    log_ << "act_drive: serial " << options_.path << " reconnected\n";
  }
  char line[ROVER_MAX_LINE + 1];
  const size_t length = format_command('C', 0, options_.failsafe, line, sizeof line);
  const EmergencyWrite neutral{port_.fd(), std::string_view(line, length)};
  arm_emergency_writes({&neutral, 1});
}

void SerialLink::handle_line(const RoverLineReader& reader) {
  RoverMessage message{};
  if (reader.overflow || rover_parse(reader.text, reader.length, &message) != ROVER_OK) {
    return;  // noise from the board's reset, or a corrupted ack: nothing to act on
  }
  switch (message.type) {
    case 'R':
      if (message.fields[0] != ROVER_PROTOCOL_VERSION) {
        log_ << "act_drive: warning: the board speaks protocol version " << message.fields[0] << ", this host "
             << ROVER_PROTOCOL_VERSION << " (re-upload apps/arduino/act_rover)\n";
      }
      if (state_ == State::kReady) {
        log_ << "act_drive: warning: the board on " << options_.path << " restarted (power dip?)\n";
      }
      become_ready();
      break;
    case 'A':
      ++acks_;
      last_acked_seq_ = message.fields[0];
      // The board is alive: the clock for the lines still in flight restarts from this ack.
      awaiting_ack_ = last_acked_seq_ != last_sent_seq_;
      awaiting_since_ = Clock::now();
      break;
    case 'E':
      if (++rejected_ <= 5) {
        log_ << "act_drive: warning: the board rejected a line: " << rover_error_name(message.fields[0])
             << (rejected_ == 5 ? " (further rejections are only counted)" : "") << "\n";
      }
      break;
    case 'N':
      if (++watchdog_notices_ <= 5) log_ << "act_drive: warning: the board's watchdog went to failsafe (commands late)\n";
      break;
    default:
      break;
  }
}

void SerialLink::read_input(std::chrono::milliseconds timeout, Clock::time_point now) {
  char buffer[256];
  for (;;) {
    std::string error;
    const long n = port_.read_some(buffer, sizeof buffer, timeout, error);
    if (n < 0) {
      fail_link(error, now);
      return;
    }
    if (n == 0) return;
    for (long i = 0; i < n; ++i) {
      if (rover_reader_push(&reader_, buffer[i])) handle_line(reader_);
    }
    timeout = std::chrono::milliseconds(0);
  }
}

void SerialLink::poll(Clock::time_point now) {
  if (state_ == State::kDisconnected) {
    if (now < next_attempt_ || !try_open(now)) return;
  }
  if (state_ == State::kWaitingReady) {
    if (now - opened_at_ > options_.ready_timeout) {
      fail_link("no ready line from the board within " + std::to_string(options_.ready_timeout.count()) + " ms", now);
      return;
    }
    if (now - opened_at_ >= options_.hello_delay && now - last_hello_ >= options_.hello_interval) {
      last_hello_ = now;
      char line[ROVER_MAX_LINE + 1];
      const RoverMessage hello{'H', 0, {0, 0, 0}};
      const size_t length = rover_format(&hello, line, sizeof line);
      std::string error;
      if (!port_.write_all(line, length, options_.write_timeout, error)) {
        fail_link(error, now);
        return;
      }
    }
  }
  read_input(std::chrono::milliseconds(0), now);
  check_acks(now);
}

void SerialLink::check_acks(Clock::time_point now) {
  if (state_ != State::kReady || !awaiting_ack_ || now - awaiting_since_ <= options_.ack_timeout) return;
  ++ack_timeouts_;
  fail_link("no acknowledgement from the board for " +
                std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(now - awaiting_since_).count()) +
                " ms (" + std::to_string(commands_sent_) + " commands sent, " + std::to_string(acks_) +
                " acked): its transmit line or the board itself is gone",
            now);
}

bool SerialLink::send(PwmCommand command, Clock::time_point now) {
  poll(now);
  if (state_ != State::kReady) return false;
  return send_message('C', command);
}

void SerialLink::shutdown(PwmCommand neutral) {
  if (state_ == State::kReady && send_message('C', neutral)) {
    // Wait briefly for the neutral command's ack so the board has really taken it.
    const auto deadline = Clock::now() + std::chrono::milliseconds(200);
    while (state_ == State::kReady && last_acked_seq_ != last_sent_seq_ && Clock::now() < deadline) {
      read_input(std::chrono::milliseconds(10), Clock::now());
    }
  }
  disarm_emergency_writes();
  port_.close();
  state_ = State::kDisconnected;
}

std::string SerialLink::summary() const {
  std::ostringstream s;
  s << "serial " << options_.path << ": " << commands_sent_ << " commands, " << acks_ << " acked, " << rejected_
    << " rejected by the board, " << watchdog_notices_ << " board watchdog timeouts, " << ack_timeouts_
    << " ack timeouts, " << errors_ << " errors, "
    << reconnects_ << " reconnects";
  return s.str();
}

// ---- DryRunLink ----

bool DryRunLink::send(PwmCommand command, Clock::time_point now) {
  char line[ROVER_MAX_LINE + 1];
  format_command('C', next_seq_++, command, line, sizeof line);
  out_ << std::fixed << std::setprecision(3) << std::chrono::duration<double>(now - start_).count() << " " << line;
  ++commands_;
  return true;
}

void DryRunLink::shutdown(PwmCommand neutral) {
  if (shut_down_) return;
  shut_down_ = true;
  send(neutral, Clock::now());
  out_.flush();
}

std::string DryRunLink::summary() const { return "dry run: " + std::to_string(commands_) + " commands printed"; }

}  // namespace act::drive
