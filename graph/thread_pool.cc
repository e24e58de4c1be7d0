#include "graph/thread_pool.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <system_error>

#include "actengine/status.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

namespace act {
namespace {

// Tells the core this is a spin-wait (frees the sibling hyperthread, saves power).
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

// Pauses before the spin starts yielding: about a microsecond, long enough for a thread on another
// core to arrive.
constexpr unsigned kPureSpins = 64;

}  // namespace

int ThreadPool::hardware_threads() { return std::max(1u, std::thread::hardware_concurrency()); }

int ThreadPool::checked_threads(int threads) {
  if (threads < 0) fail(StatusCode::kInvalidArgument, "threads must be >= 0 (0 = all cores), got " + std::to_string(threads));
  if (threads > kMaxThreads) {
    fail(StatusCode::kInvalidArgument, "threads = " + std::to_string(threads) + " is above the limit of " +
                                          std::to_string(kMaxThreads) + " (0 = one per online core)");
  }
  return threads == 0 ? std::min(hardware_threads(), kMaxThreads) : threads;
}

ThreadPool::ThreadPool(int threads) : ranges_(static_cast<size_t>(checked_threads(threads))) {
  const int total = static_cast<int>(ranges_.size());
  workers_.reserve(static_cast<size_t>(total - 1));
  try {
    for (int i = 1; i < total; ++i) workers_.emplace_back([this, i] { worker_loop(i); });
  } catch (const std::system_error& e) {
    // The OS refused a thread (EAGAIN: RLIMIT_NPROC, a cgroup's pids.max, a full process table). The
    // workers already started are stopped and joined, so nothing is left running or joinable.
    const size_t started = workers_.size();
    stop_workers();
    fail(StatusCode::kIoError, "cannot start thread " + std::to_string(started + 2) + " of " + std::to_string(total) +
                                  ": the operating system refused it (" + e.what() + "); use fewer threads");
  }
}

ThreadPool::~ThreadPool() { stop_workers(); }

void ThreadPool::stop_workers() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_.store(true, std::memory_order_relaxed);  // published by the generation's release
    generation_.fetch_add(1, std::memory_order_release);  // ends the spinning of idle workers
  }
  wake_.notify_all();
  for (auto& w : workers_) w.join();
  workers_.clear();
}

template <class Done>
bool ThreadPool::spin_until(Done done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::microseconds(kSpinMicroseconds);
  for (unsigned i = 1;; ++i) {
    if (done()) return true;
    if (i < kPureSpins) {
      cpu_relax();
      continue;
    }
    // Past the first microseconds, yield: when the thread we wait for shares this core (more
    // runnable threads than cores), it runs now instead of after our spin.
    std::this_thread::yield();
    if (std::chrono::steady_clock::now() >= deadline) return done();
  }
}

void ThreadPool::record_spans(ThreadSpans* spans) {
  if (spans != nullptr) spans->by_thread.resize(static_cast<size_t>(threads()));
  spans_ = spans;
}

bool ThreadPool::claim(TaskRange& range, bool from_front, size_t& task) {
  uint64_t bounds = range.front_back.load(std::memory_order_relaxed);
  for (;;) {
    const uint64_t front = bounds & 0xffffffffu, back = bounds >> 32;
    if (front >= back) return false;
    const uint64_t next = from_front ? (back << 32) | (front + 1) : ((back - 1) << 32) | front;
    if (range.front_back.compare_exchange_weak(bounds, next, std::memory_order_relaxed)) {
      task = static_cast<size_t>(from_front ? front : back - 1);
      return true;
    }
  }
}

void ThreadPool::run_tasks(int thread_index) {
  std::chrono::steady_clock::time_point start;
  bool claimed_any = false;
  const size_t threads = ranges_.size();
  for (size_t k = 0; k < threads; ++k) {
    const bool own = k == 0;
    TaskRange& range = ranges_[(static_cast<size_t>(thread_index) + k) % threads];
    size_t i;
    while (claim(range, own, i)) {
      if (spans_ != nullptr && !claimed_any) start = std::chrono::steady_clock::now();
      claimed_any = true;
      (*task_)(i, thread_index);
    }
  }
  if (spans_ != nullptr && claimed_any) {
    spans_->by_thread[static_cast<size_t>(thread_index)].push_back({spans_->tag, start, std::chrono::steady_clock::now()});
  }
}

void ThreadPool::worker_loop(int thread_index) {
  size_t seen_generation = 0;
  for (;;) {
    const auto started = [&] { return generation_.load(std::memory_order_acquire) != seen_generation; };
    if (!spin_until(started)) {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, started);
    }
    seen_generation = generation_.load(std::memory_order_acquire);
    if (stopping_.load(std::memory_order_relaxed)) return;
    run_tasks(thread_index);
    if (busy_workers_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      std::lock_guard<std::mutex> lock(mutex_);  // the caller may be asleep on done_
      done_.notify_one();
    }
  }
}

void ThreadPool::parallel_for(size_t n_tasks, const std::function<void(size_t, int)>& task) {
  if (n_tasks == 0) return;
  if (workers_.empty() || n_tasks == 1) {
    const auto start = std::chrono::steady_clock::now();
    for (size_t i = 0; i < n_tasks; ++i) task(i, 0);
    if (spans_ != nullptr) spans_->by_thread[0].push_back({spans_->tag, start, std::chrono::steady_clock::now()});
    return;
  }
  if (n_tasks > UINT32_MAX) throw std::length_error("ThreadPool::parallel_for: more than 2^32 - 1 tasks");
  task_ = &task;
  const size_t threads = ranges_.size();
  for (size_t t = 0; t < threads; ++t) {
    const uint64_t front = n_tasks * t / threads, back = n_tasks * (t + 1) / threads;
    ranges_[t].front_back.store((back << 32) | front, std::memory_order_relaxed);  // published by the generation
  }
  busy_workers_.store(static_cast<int>(workers_.size()), std::memory_order_relaxed);
  {
    // Under the mutex, so a worker about to sleep sees either the new generation or the notify.
    std::lock_guard<std::mutex> lock(mutex_);
    generation_.fetch_add(1, std::memory_order_release);
  }
  wake_.notify_all();
  run_tasks(0);
  const auto finished = [&] { return busy_workers_.load(std::memory_order_acquire) == 0; };
  if (!spin_until(finished)) {
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, finished);
  }
  task_ = nullptr;
}

}  // namespace act
