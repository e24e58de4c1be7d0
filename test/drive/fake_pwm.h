// A fake /sys/class/pwm for act_drive --pwm: pwmchip0 with npwm, export and two exported channels
// whose attribute files are plain files. PwmSysfsLink and act_pwm_watchdog open them O_APPEND, so
// every value written is one line and the last line is the channel's current value. A thread
// watches both duty-cycle files and time-stamps each change, like the fake Arduino's commands.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "apps/drive/calibration.h"
#include "apps/drive/serial_link.h"

namespace act::drive::test {

class FakePwmTree {
 public:
  /// Both duty cycles (ns) after one of them changed, and when that was seen.
  struct Sample {
    Clock::time_point when;
    int64_t steering_ns = 0, throttle_ns = 0;
    bool is(PwmCommand c) const { return steering_ns == c.steering_us * 1000LL && throttle_ns == c.throttle_us * 1000LL; }
  };

  explicit FakePwmTree(const std::string& root, int channels = 2) : root_(root), chip_(root + "/pwmchip0") {
    std::filesystem::create_directories(chip_);
    std::ofstream(chip_ + "/npwm") << channels << "\n";
    std::ofstream(chip_ + "/export").flush();
    for (int c = 0; c < channels; ++c) {
      std::filesystem::create_directories(channel_dir(c));
      for (const char* file : {"period", "duty_cycle", "enable"}) std::ofstream(channel_dir(c) + "/" + file).flush();
    }
    watcher_ = std::thread([this] {
      while (!stop_.load()) {
        if (pause_.load()) {
          parked_.store(true);
          while (pause_.load() && !stop_.load()) std::this_thread::yield();
          parked_.store(false);
          continue;
        }
        scan();
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    });
  }
  ~FakePwmTree() {
    stop_.store(true);
    watcher_.join();
  }
  FakePwmTree(const FakePwmTree&) = delete;
  FakePwmTree& operator=(const FakePwmTree&) = delete;

  /// While alive, the watcher waits between scans (no allocation of its own in flight). A test that
  /// forks a child which runs C++ before exec (allocating) forks under one: a lock the watcher held
  /// at the fork would stay held in the child forever (the sanitizers' allocators are not fork-safe;
  /// the ASan stage hung in PwmWatchdog's child once).
  class ScanPause {
   public:
    explicit ScanPause(const FakePwmTree& tree) : tree_(tree) {
      tree_.pause_.store(true);
      while (!tree_.parked_.load()) std::this_thread::yield();
    }
    ~ScanPause() { tree_.pause_.store(false); }
    ScanPause(const ScanPause&) = delete;
    ScanPause& operator=(const ScanPause&) = delete;

   private:
    const FakePwmTree& tree_;
  };

  const std::string& root() const { return root_; }
  std::string channel_dir(int channel) const { return chip_ + "/pwm" + std::to_string(channel); }
  /// Every value written to a channel's attribute, in order.
  std::vector<int64_t> values(int channel, const std::string& attribute) const {
    std::ifstream in(channel_dir(channel) + "/" + attribute);
    std::vector<int64_t> out;
    for (int64_t v; in >> v;) out.push_back(v);
    return out;
  }
  std::vector<Sample> samples() const {
    std::lock_guard lock(mutex_);
    return samples_;
  }
  Sample current() const {
    std::lock_guard lock(mutex_);
    return samples_.empty() ? Sample{} : samples_.back();
  }
  /// The first sample at or after `since` that is `command`, waiting up to `limit` for it.
  std::optional<Sample> wait_for(PwmCommand command, Clock::time_point since, std::chrono::milliseconds limit) const {
    const auto deadline = Clock::now() + limit;
    for (;;) {
      {
        std::lock_guard lock(mutex_);
        for (const Sample& s : samples_) {
          if (s.when >= since && s.is(command)) return s;
        }
      }
      if (Clock::now() > deadline) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  /// Waits up to `limit` until the current duty cycles are not `command` (driving again).
  bool wait_until_not(PwmCommand command, std::chrono::milliseconds limit) const {
    return wait_until_current([&](const Sample& s) { return s.steering_ns > 0 && !s.is(command); }, limit);
  }
  /// Waits up to `limit` until the current duty cycles are `command` (the watcher scans every 200 us,
  /// but under load it can be late by more than any fixed sleep).
  bool wait_until_is(PwmCommand command, std::chrono::milliseconds limit) const {
    return wait_until_current([&](const Sample& s) { return s.is(command); }, limit);
  }

 private:
  template <class Pred>
  bool wait_until_current(Pred pred, std::chrono::milliseconds limit) const {
    const auto deadline = Clock::now() + limit;
    while (Clock::now() < deadline) {
      if (pred(current())) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return pred(current());
  }

  // Reads what was appended to each duty-cycle file since the last scan.
  void scan() {
    bool changed = false;
    for (int c = 0; c < 2; ++c) {
      std::ifstream in(channel_dir(c) + "/duty_cycle");
      in.seekg(static_cast<std::streamoff>(offset_[c]));
      std::string line;
      while (std::getline(in, line)) {
        if (in.eof()) break;  // a line still being written
        offset_[c] += line.size() + 1;
        last_[c] = std::stoll(line);
        changed = true;
      }
    }
    if (changed) {
      std::lock_guard lock(mutex_);
      samples_.push_back({Clock::now(), last_[0], last_[1]});
    }
  }

  std::string root_, chip_;
  size_t offset_[2] = {0, 0};
  int64_t last_[2] = {0, 0};
  mutable std::mutex mutex_;
  mutable std::atomic<bool> pause_{false}, parked_{false};
  std::vector<Sample> samples_;
  std::atomic<bool> stop_{false};
  std::thread watcher_;
};

}  // namespace act::drive::test
