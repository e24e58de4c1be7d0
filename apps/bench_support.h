// Pieces of act_bench that are worth testing on their own: latency statistics and machine facts.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace act {

/// Summary of a sample of latencies (any unit). Percentiles by linear interpolation between order
/// statistics (numpy's default), so p50 <= p90 <= p95 <= p99 <= max always holds.
struct LatencySummary {
  size_t count = 0;
  double mean = 0, stddev = 0, min = 0, p50 = 0, p90 = 0, p95 = 0, p99 = 0, max = 0;
  nlohmann::ordered_json to_json() const;
};
LatencySummary summarize(std::vector<double> samples);

/// The same summary in constant memory, for runs of any length (act_drive runs for hours): count,
/// mean, standard deviation, min and max are exact; percentiles come from a histogram with bins 1 %
/// wide between 1e-3 and 1e6 (relative error <= 0.5 % in that range), clamped to [min, max] so the
/// order p50 <= ... <= max still holds.
class LatencyHistogram {
 public:
  LatencyHistogram();
  void add(double value);
  LatencySummary summary() const;
  void clear();

 private:
  static int bin_of(double value);
  static double bin_center(int bin);
  std::vector<uint64_t> bins_;  // sized once
  size_t count_ = 0;
  double mean_ = 0, m2_ = 0, min_ = 0, max_ = 0;  // Welford's running mean and sum of squares
};

/// What the benchmark ran on: CPU model, cores, flags, frequency; on a Raspberry Pi also the SoC
/// temperature and the firmware's throttling flags when the kernel exposes them.
struct MachineInfo {
  std::string cpu_model;
  int online_cores = 0;
  std::vector<std::string> cpu_flags;  ///< x86 "flags" / ARM "Features"
  double cpu_mhz = 0;                  ///< 0 when unknown
  double temperature_c = -1;           ///< < 0 when unknown
  std::string throttled;               ///< e.g. "0x0"; empty when unknown
  /// Why this process looks emulated (qemu-user: timings are the emulator's, not this CPU's); empty
  /// when it runs natively as far as can be told (detect_emulation).
  std::string emulation;
  nlohmann::ordered_json to_json() const;
  std::string one_line() const;
};
MachineInfo read_machine_info();

/// Evidence that this process runs under qemu-user, from what Linux shows of it: `maps` (the real
/// mappings of /proc/thread-self/maps and /proc/self/smaps, where qemu 7 leaves its own binary
/// visible: qemu-aarch64 or a binfmt interpreter qemu-*-static), `cpuinfo` (qemu before 8.1 passes
/// the host's through: an x86 CPU seen by an ARM binary) and `process_name` (/proc/self/status Name:
/// "qemu-aarch64" when started through it). "" when none says so.
std::string detect_emulation(const std::string& maps, const std::string& cpuinfo, const std::string& process_name);

/// Peak resident set size of this process, in bytes.
size_t peak_rss_bytes();
/// Current resident set size of this process, in bytes (from /proc/self/statm; 0 if unreadable).
size_t current_rss_bytes();

}  // namespace act
