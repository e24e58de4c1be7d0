#include "drive/fake_arduino.h"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace act::drive::test {

FakeArduino::FakeArduino(std::string link_path) : link_path_(std::move(link_path)) {
  rover_reader_init(&reader_);
  {
    std::lock_guard lock(mutex_);
    open_pty();
  }
  thread_ = std::thread([this] { run(); });
}

FakeArduino::~FakeArduino() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  thread_.join();
  if (master_ >= 0) ::close(master_);
  if (held_slave_ >= 0) ::close(held_slave_);
  if (!link_path_.empty()) std::filesystem::remove(link_path_);
}

void FakeArduino::open_pty() {
  master_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (master_ < 0 || ::grantpt(master_) != 0 || ::unlockpt(master_) != 0) throw std::runtime_error("posix_openpt failed");
  slave_path_ = ::ptsname(master_);
  // Hold the slave open in raw mode: no echo before the host configures it, no hang-up between opens.
  held_slave_ = ::open(slave_path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  termios tty{};
  ::tcgetattr(held_slave_, &tty);
  ::cfmakeraw(&tty);
  ::tcsetattr(held_slave_, TCSANOW, &tty);
  if (!link_path_.empty()) {
    const std::string temp = link_path_ + ".new";
    std::filesystem::remove(temp);
    std::filesystem::create_symlink(slave_path_, temp);
    std::filesystem::rename(temp, link_path_);
  }
}

std::string FakeArduino::port_path() const {
  std::lock_guard lock(mutex_);
  return link_path_.empty() ? slave_path_ : link_path_;
}

void FakeArduino::replace() {
  std::lock_guard lock(mutex_);
  ::close(master_);
  ::close(held_slave_);
  master_ = held_slave_ = -1;
  ++generation_;
  if (!link_path_.empty()) open_pty();
}

void FakeArduino::set_silent(bool silent) {
  std::lock_guard lock(mutex_);
  silent_ = silent;
}

void FakeArduino::set_acking(bool acking) {
  std::lock_guard lock(mutex_);
  acking_ = acking;
}

std::vector<FakeArduino::Command> FakeArduino::commands() const {
  std::lock_guard lock(mutex_);
  return commands_;
}

std::vector<std::string> FakeArduino::bad_lines() const {
  std::lock_guard lock(mutex_);
  return bad_lines_;
}

int FakeArduino::hellos() const {
  std::lock_guard lock(mutex_);
  return hellos_;
}

void FakeArduino::run() {
  for (;;) {
    char buffer[256];
    ssize_t n = 0;
    {
      std::lock_guard lock(mutex_);
      if (stop_) return;
      if (master_ >= 0) {
        pollfd p{master_, POLLIN, 0};
        if (::poll(&p, 1, 0) > 0 && (p.revents & POLLIN)) n = ::read(master_, buffer, sizeof buffer);
      }
    }
    if (n <= 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    for (ssize_t i = 0; i < n; ++i) {
      if (rover_reader_push(&reader_, buffer[i])) {
        handle(reader_.overflow ? "overflow" : reader_.text, reader_.overflow ? 8 : reader_.length);
      }
    }
  }
}

void FakeArduino::handle(const char* line, size_t length) {
  RoverMessage message{};
  const RoverError error = rover_parse(line, length, &message);
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  if (error != ROVER_OK || (message.type != 'C' && message.type != 'F' && message.type != 'H')) {
    bad_lines_.emplace_back(line, length);
    return;
  }
  if (message.type == 'H') {
    ++hellos_;
    if (!silent_) reply({'R', 2, {ROVER_PROTOCOL_VERSION, ROVER_WATCHDOG_MS, 0}});
    return;
  }
  commands_.push_back({now, message.type, message.fields[0], message.fields[1], message.fields[2], generation_});
  if (acking_) reply({'A', 1, {message.fields[0], 0, 0}});
}

void FakeArduino::reply(const RoverMessage& message) {
  char line[ROVER_MAX_LINE + 1];
  const size_t length = rover_format(&message, line, sizeof line);
  if (master_ >= 0 && ::write(master_, line, length) != static_cast<ssize_t>(length)) {
    std::fprintf(stderr, "FakeArduino: reply write failed\n");
  }
}

}  // namespace act::drive::test
