#include "apps/bench_support.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>

namespace act {

nlohmann::ordered_json LatencySummary::to_json() const {
  return {{"count", count}, {"mean", mean}, {"std", stddev}, {"min", min}, {"p50", p50},
          {"p90", p90},     {"p95", p95},   {"p99", p99},    {"max", max}};
}

LatencySummary summarize(std::vector<double> samples) {
  LatencySummary s;
  s.count = samples.size();
  if (samples.empty()) return s;
  std::sort(samples.begin(), samples.end());
  double sum = 0;
  for (double v : samples) sum += v;
  s.mean = sum / static_cast<double>(samples.size());
  double sq = 0;
  for (double v : samples) sq += (v - s.mean) * (v - s.mean);
  s.stddev = samples.size() > 1 ? std::sqrt(sq / static_cast<double>(samples.size() - 1)) : 0.0;
  auto percentile = [&](double p) {
    const double pos = p / 100.0 * static_cast<double>(samples.size() - 1);
    const size_t lo = static_cast<size_t>(pos);
    const size_t hi = std::min(lo + 1, samples.size() - 1);
    return samples[lo] + (samples[hi] - samples[lo]) * (pos - static_cast<double>(lo));
  };
  s.min = samples.front();
  s.max = samples.back();
  s.p50 = percentile(50);
  s.p90 = percentile(90);
  s.p95 = percentile(95);
  s.p99 = percentile(99);
  // The mean of doubles can land a rounding step outside [min, max]; keep the invariant exact.
  s.mean = std::clamp(s.mean, s.min, s.max);
  return s;
}

namespace {

constexpr double kHistogramLow = 1e-3, kHistogramHigh = 1e6, kHistogramRatio = 1.01;
const int kHistogramBins = static_cast<int>(std::ceil(std::log(kHistogramHigh / kHistogramLow) / std::log(kHistogramRatio))) + 2;

}  // namespace

LatencyHistogram::LatencyHistogram() : bins_(static_cast<size_t>(kHistogramBins), 0) {}

int LatencyHistogram::bin_of(double value) {
  // Bin 0 holds everything below kHistogramLow (and zero), the last bin everything above kHistogramHigh.
  if (!(value > kHistogramLow)) return 0;
  const int bin = 1 + static_cast<int>(std::log(value / kHistogramLow) / std::log(kHistogramRatio));
  return std::min(bin, kHistogramBins - 1);
}

double LatencyHistogram::bin_center(int bin) {
  if (bin == 0) return 0.0;
  return kHistogramLow * std::pow(kHistogramRatio, bin - 0.5);
}

void LatencyHistogram::add(double value) {
  if (std::isnan(value)) return;
  ++bins_[static_cast<size_t>(bin_of(value))];
  ++count_;
  if (count_ == 1) {
    min_ = max_ = value;
  } else {
    min_ = std::min(min_, value);
    max_ = std::max(max_, value);
  }
  const double delta = value - mean_;
  mean_ += delta / static_cast<double>(count_);
  m2_ += delta * (value - mean_);
}

LatencySummary LatencyHistogram::summary() const {
  LatencySummary s;
  s.count = count_;
  if (count_ == 0) return s;
  s.mean = std::clamp(mean_, min_, max_);
  s.stddev = count_ > 1 ? std::sqrt(m2_ / static_cast<double>(count_ - 1)) : 0.0;
  s.min = min_;
  s.max = max_;
  // The value at order statistic round(p * (n - 1)): the center of the bin it falls in.
  auto percentile = [&](double p) {
    const auto rank = static_cast<uint64_t>(std::llround(p / 100.0 * static_cast<double>(count_ - 1)));
    uint64_t seen = 0;
    for (size_t b = 0; b < bins_.size(); ++b) {
      seen += bins_[b];
      if (seen > rank) return b + 1 == bins_.size() ? max_ : std::clamp(bin_center(static_cast<int>(b)), min_, max_);
    }
    return max_;
  };
  s.p50 = percentile(50);
  s.p90 = percentile(90);
  s.p95 = percentile(95);
  s.p99 = percentile(99);
  return s;
}

void LatencyHistogram::clear() {
  std::fill(bins_.begin(), bins_.end(), 0);
  count_ = 0;
  mean_ = m2_ = min_ = max_ = 0;
}

namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

std::string read_first_line(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return trim(line);
}

// All of a file ("" if unreadable); /proc files report no size, so read to the end.
std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

MachineInfo read_machine_info() {
  MachineInfo m;
  m.online_cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line, arm_part, hardware;
  while (std::getline(cpuinfo, line)) {
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = trim(line.substr(0, colon)), value = trim(line.substr(colon + 1));
    if ((key == "model name" || key == "Model") && m.cpu_model.empty()) m.cpu_model = value;
    if (key == "CPU part" && arm_part.empty()) arm_part = value;
    if (key == "Hardware" && hardware.empty()) hardware = value;
    if (key == "cpu MHz" && m.cpu_mhz == 0) m.cpu_mhz = std::atof(value.c_str());
    if ((key == "flags" || key == "Features") && m.cpu_flags.empty()) {
      std::istringstream flags(value);
      for (std::string f; flags >> f;) m.cpu_flags.push_back(f);
    }
  }
  if (m.cpu_model.empty()) m.cpu_model = !hardware.empty() ? hardware : (!arm_part.empty() ? "ARM CPU part " + arm_part : "unknown CPU");
  if (m.cpu_mhz == 0) {
    const std::string khz = read_first_line("/sys/devices/system/cpu/cpu0/cpufreq/scaling_cur_freq");
    if (!khz.empty()) m.cpu_mhz = std::atof(khz.c_str()) / 1000.0;
  }
  const std::string temp = read_first_line("/sys/class/thermal/thermal_zone0/temp");
  if (!temp.empty()) m.temperature_c = std::atof(temp.c_str()) / 1000.0;
  // Raspberry Pi firmware (vcgencmd get_throttled without vcgencmd).
  m.throttled = read_first_line("/sys/devices/platform/soc/soc:firmware/get_throttled");
  std::string process_name;
  std::ifstream status("/proc/self/status");
  for (std::string status_line; std::getline(status, status_line);) {
    if (status_line.rfind("Name:", 0) == 0) process_name = trim(status_line.substr(5));
  }
  m.emulation = detect_emulation(read_text("/proc/thread-self/maps") + read_text("/proc/self/smaps"),
                                 read_text("/proc/cpuinfo"), process_name);
  return m;
}

std::string detect_emulation(const std::string& maps, const std::string& cpuinfo, const std::string& process_name) {
  std::istringstream lines(maps);
  for (std::string line; std::getline(lines, line);) {
    const size_t slash = line.rfind('/');
    if (slash != std::string::npos && line.compare(slash + 1, 5, "qemu-") == 0) {
      return "qemu-user: " + line.substr(line.find('/')) + " is mapped into this process";
    }
  }
  if (process_name.rfind("qemu-", 0) == 0) return "qemu-user: this process is " + process_name;
#if defined(__aarch64__) || defined(__arm__)
  const bool other_cpu = cpuinfo.find("vendor_id") != std::string::npos;  // x86's /proc/cpuinfo
#elif defined(__x86_64__) || defined(__i386__)
  const bool other_cpu = cpuinfo.find("CPU implementer") != std::string::npos;  // ARM's
#else
  const bool other_cpu = false;
#endif
  if (other_cpu) return "an emulator: /proc/cpuinfo describes another architecture than this program's";
  return "";
}

nlohmann::ordered_json MachineInfo::to_json() const {
  nlohmann::ordered_json j = {{"cpu_model", cpu_model}, {"online_cores", online_cores}, {"cpu_flags", cpu_flags}};
  j["cpu_mhz"] = cpu_mhz > 0 ? nlohmann::ordered_json(cpu_mhz) : nlohmann::ordered_json();
  j["temperature_c"] = temperature_c >= 0 ? nlohmann::ordered_json(temperature_c) : nlohmann::ordered_json();
  j["throttled"] = throttled.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(throttled);
  j["emulated"] = !emulation.empty();
  j["emulation"] = emulation.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(emulation);
  return j;
}

std::string MachineInfo::one_line() const {
  std::ostringstream s;
  s << cpu_model << ", " << online_cores << " cores";
  if (cpu_mhz > 0) s << ", " << static_cast<int>(cpu_mhz) << " MHz";
  if (temperature_c >= 0) s << ", " << temperature_c << " C";
  if (!throttled.empty()) s << ", throttled=" << throttled;
  if (!emulation.empty()) s << ", EMULATED (" << emulation << "): timings are the emulator's, not this CPU's";
  return s.str();
}

size_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<size_t>(usage.ru_maxrss) * 1024;  // Linux reports kB
}

size_t current_rss_bytes() {
  std::ifstream statm("/proc/self/statm");
  size_t total_pages = 0, resident_pages = 0;
  if (!(statm >> total_pages >> resident_pages)) return 0;
  return resident_pages * static_cast<size_t>(sysconf(_SC_PAGESIZE));
}

}  // namespace act
