#include "graph/peak_together.h"

#include <algorithm>
#include <latch>
#include <thread>
#include <vector>

#include "graph/thread_pool.h"

namespace act::graph {

int peak_probe_threads(int threads) { return std::clamp(threads, 1, ThreadPool::hardware_threads()); }

double measure_peak_gmacs_together(const kernels::PeakProbe& probe, int threads) {
  const int n = peak_probe_threads(threads);
  if (n == 1) return kernels::measure_peak_gmacs(probe);
  std::vector<double> readings(static_cast<size_t>(n), 0.0);
  std::latch start(n);  // every thread starts its warm-up at once, so that the timed runs overlap
  const auto read = [&](int i) {
    start.arrive_and_wait();
    readings[static_cast<size_t>(i)] = kernels::measure_peak_gmacs(probe);
  };
  std::vector<std::thread> others;
  others.reserve(static_cast<size_t>(n - 1));
  for (int i = 1; i < n; ++i) others.emplace_back(read, i);
  read(0);
  for (std::thread& t : others) t.join();
  double total = 0.0;
  for (double r : readings) total += r;
  return total;
}

}  // namespace act::graph
