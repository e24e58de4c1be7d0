// A persistent pool of worker threads for splitting one op into tiles. The calling thread works
// too, so ThreadPool(1) runs everything inline with no other thread. Each thread owns a contiguous
// range of a section's tasks and claims them from its front; when its range is empty it steals from
// the back of the others', so uneven tiles balance themselves (as pthreadpool does). Owning ranges
// keeps data on its core: consecutive ops split their rows alike, so a thread mostly reads rows it
// wrote itself, from its own L2. Not reentrant: one parallel_for at a time per pool.
//
// Waking costs next to nothing (as in pthreadpool and ruy): after a parallel section, workers spin on
// an atomic for up to kSpinMicroseconds before they sleep on a condition variable, and the caller
// spins as long for them to finish. ACT runs well over a hundred ops per inference back to back, so
// workers are nearly always still spinning when the next op starts; between inferences (a control
// loop's tens of milliseconds) they sleep and leave the cores to the camera and control threads.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace act {

/// Where each thread spent one parallel section: [start, end) from its first task claimed to its
/// last finished (steady_clock), with the section's tag (the op's index). Recorded only when a
/// ThreadSpans is attached (profiling); each thread appends to its own list, so no locking.
struct ThreadSpan {
  int tag = 0;
  std::chrono::steady_clock::time_point start, end;
};
struct ThreadSpans {
  int tag = 0;                                  ///< set by the caller before each parallel section
  std::vector<std::vector<ThreadSpan>> by_thread;  ///< [thread index] -> spans, in time order
};

class ThreadPool {
 public:
  static constexpr int kSpinMicroseconds = 100;
  /// The most threads a pool has (act::kMaxThreads in the public API: every --threads and threads=).
  static constexpr int kMaxThreads = 256;

  /// `threads` in 1..kMaxThreads is the total including the caller; 0 means one per online core
  /// (at most kMaxThreads). Throws act::Error: kInvalidArgument outside 0..kMaxThreads, kIoError when
  /// the OS refuses a thread (the workers already started are stopped and joined first).
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }

  /// Runs task(i) for i in [0, n_tasks), spread over the pool; returns when all are done.
  /// `task` receives (task index, thread index in [0, threads())) so it can use per-thread scratch.
  void parallel_for(size_t n_tasks, const std::function<void(size_t task, int thread)>& task);

  /// Records every thread's span of each parallel section into `spans` (sized to threads() here),
  /// or stops recording (nullptr). Call between parallel sections only.
  void record_spans(ThreadSpans* spans);

  /// Online cores of this machine (at least 1).
  static int hardware_threads();
  /// The pool size `threads` asks for (0 = one per online core, capped at kMaxThreads); throws
  /// act::Error(kInvalidArgument) below 0 or above kMaxThreads, naming the limit.
  static int checked_threads(int threads);

 private:
  void stop_workers();
  void worker_loop(int thread_index);
  void run_tasks(int thread_index);
  /// Spins until `done()` or kSpinMicroseconds pass; true when done() became true.
  template <class Done>
  static bool spin_until(Done done);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const std::function<void(size_t, int)>* task_ = nullptr;
  ThreadSpans* spans_ = nullptr;
  /// A thread's tasks [front, back) of the current section, on a cache line of its own. A thief
  /// takes from the back, leaving a late owner the front (the rows next to its last op's).
  struct alignas(64) TaskRange {
    std::atomic<uint64_t> front_back{0};  // front in the low 32 bits, back (exclusive) in the high
  };
  std::vector<TaskRange> ranges_;
  /// The next task of `range` from its front (owner) or back (thief); false when it is empty.
  static bool claim(TaskRange& range, bool from_front, size_t& task);

  std::atomic<size_t> generation_{0};    // bumped (under mutex_) to start a section
  std::atomic<int> busy_workers_{0};     // workers still in the current section
  std::atomic<bool> stopping_{false};
};

}  // namespace act
