// A persistent pool of worker threads for splitting one op into tiles. The calling thread works
// too, so ThreadPool(1) runs everything inline with no other thread. Tasks are claimed from an atomic
// counter, so uneven tiles balance themselves. Not reentrant: one parallel_for at a time per pool.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace act {

class ThreadPool {
 public:
  /// `threads` >= 1 is the total including the caller; 0 means one per online core.
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }

  /// Runs task(i) for i in [0, n_tasks), spread over the pool; returns when all are done.
  /// `task` receives (task index, thread index in [0, threads())) so it can use per-thread scratch.
  void parallel_for(size_t n_tasks, const std::function<void(size_t task, int thread)>& task);

  /// Online cores of this machine (at least 1).
  static int hardware_threads();

 private:
  void worker_loop(int thread_index);
  void run_tasks(int thread_index);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const std::function<void(size_t, int)>* task_ = nullptr;
  size_t n_tasks_ = 0;
  std::atomic<size_t> next_task_{0};
  size_t generation_ = 0;
  int busy_workers_ = 0;
  bool stopping_ = false;
};

}  // namespace act
