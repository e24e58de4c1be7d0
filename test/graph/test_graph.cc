// The memory planner and the thread pool.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <set>
#include <thread>

#include "graph/gemm_tiling.h"
#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "graph/peak_together.h"
#include "graph/thread_pool.h"

namespace act::graph {
namespace {

TEST(ThreadPool, RunsEveryTaskOnceWithValidThreadIndices) {
  for (int threads : {1, 2, 4}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    for (size_t n : {size_t{0}, size_t{1}, size_t{3}, size_t{1000}}) {
      std::vector<std::atomic<int>> hits(n);
      std::atomic<bool> bad_thread{false};
      pool.parallel_for(n, [&](size_t i, int t) {
        hits[i]++;
        if (t < 0 || t >= threads) bad_thread = true;
      });
      for (size_t i = 0; i < n; ++i) EXPECT_EQ(hits[i].load(), 1);
      EXPECT_FALSE(bad_thread);
    }
  }
}

// Waits (yielding) until `ready` holds, for at most 10 s: false if it never did, so that a pool that
// fails to share its tasks fails the test instead of hanging it.
template <class Ready>
bool wait_until(Ready ready) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!ready()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::yield();
  }
  return true;
}

// Thread t starts with the front of its own range, [t n / T, (t + 1) n / T): each first task waits
// until every thread has started one, so no thread can empty its range and steal before the others
// claim their first.
TEST(ThreadPool, EachThreadStartsWithItsOwnRange) {
  for (int threads : {2, 4}) {
    ThreadPool pool(threads);
    for (size_t n : {size_t{4}, size_t{9}, size_t{64}}) {
      std::vector<std::atomic<size_t>> first(static_cast<size_t>(threads));
      for (auto& f : first) f = SIZE_MAX;
      std::atomic<int> started{0};
      std::atomic<bool> timed_out{false};
      pool.parallel_for(n, [&](size_t i, int t) {
        size_t none = SIZE_MAX;
        if (first[static_cast<size_t>(t)].compare_exchange_strong(none, i)) {
          started++;
          if (!wait_until([&] { return started.load() == threads; })) timed_out = true;
        }
      });
      ASSERT_FALSE(timed_out) << threads << " threads, " << n << " tasks: a thread never started";
      for (size_t t = 0; t < first.size(); ++t) {
        EXPECT_EQ(first[t].load(), n * t / static_cast<size_t>(threads)) << threads << " threads, " << n << " tasks";
      }
    }
  }
}

// A thread stuck in its first task has the rest of its range taken by the others, from the back:
// its first task waits for all of them, which only thieves can run.
TEST(ThreadPool, OthersStealTheRestOfAStuckThreadsRange) {
  ThreadPool pool(2);
  constexpr size_t kTasks = 16, kSecondHalf = kTasks / 2;
  std::vector<std::atomic<int>> ran_on(kTasks);
  for (auto& r : ran_on) r = -1;
  std::atomic<size_t> done{0};
  std::atomic<bool> timed_out{false};
  pool.parallel_for(kTasks, [&](size_t i, int t) {
    ran_on[i] = t;
    if (i == kSecondHalf && t == 1 && !wait_until([&] { return done.load() == kTasks - 1; })) timed_out = true;
    done++;
  });
  ASSERT_FALSE(timed_out) << "the stuck thread's range was not stolen";
  for (size_t i = 0; i < kTasks; ++i) ASSERT_NE(ran_on[i].load(), -1) << "task " << i;
  if (ran_on[kSecondHalf] == 1) {  // thread 1 got to its range first: thread 0 ran all the rest
    for (size_t i = 0; i < kTasks; ++i) {
      if (i != kSecondHalf) {
        EXPECT_EQ(ran_on[i].load(), 0) << "task " << i;
      }
    }
  }
}

// Sections back to back (workers still spinning) and after pauses longer than the spin (workers
// asleep on the condition variable) all run every task once; pools are destroyed in both states.
TEST(ThreadPool, WakesSpinningAndSleepingWorkers) {
  for (int round = 0; round < 3; ++round) {
    ThreadPool pool(3);
    for (int section = 0; section < 600; ++section) {
      const size_t n = 2 + static_cast<size_t>(section % 7);
      std::vector<std::atomic<int>> hits(n);
      pool.parallel_for(n, [&](size_t i, int) { hits[i]++; });
      for (size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "section " << section << " task " << i;
      if (section % 100 == 99) {
        std::this_thread::sleep_for(std::chrono::microseconds(5 * ThreadPool::kSpinMicroseconds));
      }
    }
    if (round == 1) std::this_thread::sleep_for(std::chrono::microseconds(5 * ThreadPool::kSpinMicroseconds));
  }
}

// With spans attached, each thread that worked on a section records one span with the section's
// tag; detached, nothing is recorded.
TEST(ThreadPool, RecordsEachThreadsSpanOfASection) {
  ThreadPool pool(2);
  ThreadSpans spans;
  pool.record_spans(&spans);
  ASSERT_EQ(spans.by_thread.size(), 2u);
  for (int tag : {7, 8}) {
    spans.tag = tag;
    // Each task waits for the other to start, so both threads must take one.
    std::atomic<int> started{0};
    pool.parallel_for(2, [&](size_t, int) {
      started++;
      while (started.load() < 2) std::this_thread::yield();
    });
  }
  for (const auto& thread_spans : spans.by_thread) {
    ASSERT_EQ(thread_spans.size(), 2u);
    for (size_t s = 0; s < 2; ++s) {
      EXPECT_EQ(thread_spans[s].tag, 7 + static_cast<int>(s));
      EXPECT_LE(thread_spans[s].start, thread_spans[s].end);
    }
    EXPECT_LE(thread_spans[0].end, thread_spans[1].start);
  }
  pool.record_spans(nullptr);
  pool.parallel_for(4, [](size_t, int) {});
  EXPECT_EQ(spans.by_thread[0].size() + spans.by_thread[1].size(), 4u);
}

// A probe that notes the threads it runs on: a busy loop of `iterations` steps, 1000 "MACs" each.
std::mutex probe_threads_mutex;
std::set<std::thread::id> probe_threads;
uint64_t thread_noting_probe(uint64_t iterations) {
  {
    std::lock_guard<std::mutex> lock(probe_threads_mutex);
    probe_threads.insert(std::this_thread::get_id());
  }
  volatile uint64_t steps = 0;
  for (uint64_t i = 0; i < iterations; ++i) steps = steps + 1;
  return iterations * 1000;
}

TEST(PeakTogether, ReadsTheProbeOnEveryThreadUpToOnePerCore) {
  const kernels::PeakProbe probe{"thread_noting", kernels::Isa::kRef, kernels::PeakKind::kInt8, thread_noting_probe, false};
  for (int threads : {1, 2, 64}) {
    probe_threads.clear();
    EXPECT_GT(measure_peak_gmacs_together(probe, threads), 0.0) << threads;
    // 64 threads on a machine of fewer cores are read as its cores.
    EXPECT_EQ(probe_threads.size(), static_cast<size_t>(std::min(threads, ThreadPool::hardware_threads()))) << threads;
  }
}

// Every output element in exactly one task; row bands start on multiples of MR and are at most
// tile_m rows; with enough rows 5 row bands per thread (or, for weights past L2 and tasks that need
// not finish rows, a band per thread in 5 column blocks); with few, column blocks for every thread.
void expect_tiling_covers_once(int m, int n, int mr, int threads, bool whole_rows, size_t weight_bytes) {
  SCOPED_TRACE(testing::Message() << "m " << m << " n " << n << " mr " << mr << " threads " << threads << " whole_rows "
                                  << whole_rows << " weight_bytes " << weight_bytes);
  const GemmTiling t = gemm_tiling(m, n, mr, 16, threads, whole_rows, weight_bytes);
  // Rectangles inside the output that do not overlap and add up to its area cover it exactly once
  // (counting each output's hits took 33 s under qemu).
  struct Rect {
    int m0, m1, n0, n1;
  };
  std::vector<Rect> tiles;
  int64_t area = 0;
  for (size_t task = 0; task < t.count(); ++task) {
    Rect r;
    t.rect(task, r.m0, r.m1, r.n0, r.n1);
    ASSERT_EQ(r.m0 % mr, 0);
    ASSERT_TRUE(0 <= r.m0 && r.m0 < r.m1 && r.m1 <= m && 0 <= r.n0 && r.n0 < r.n1 && r.n1 <= n);
    ASSERT_LE(r.m1 - r.m0, t.rows.max_size());
    for (const Rect& o : tiles) {
      ASSERT_FALSE(r.m0 < o.m1 && o.m0 < r.m1 && r.n0 < o.n1 && o.n0 < r.n1) << "task " << task << " overlaps an earlier one";
    }
    tiles.push_back(r);
    area += int64_t{r.m1 - r.m0} * (r.n1 - r.n0);
  }
  ASSERT_EQ(area, int64_t{m} * n);
  if (threads <= 1) return;
  const int tasks = kGemmTasksPerThread;
  const bool many_rows = m >= (whole_rows ? 1 : 2) * tasks * threads * mr;
  if (many_rows && (whole_rows || weight_bytes <= kL2WeightBytes)) {
    EXPECT_EQ(t.rows.parts, tasks * threads);
    EXPECT_EQ(t.cols.parts, 1);
  } else if (many_rows) {  // weights past L2: a row band per thread, in 5 column blocks
    EXPECT_EQ(t.rows.parts, threads);
    EXPECT_EQ(t.cols.parts, std::min((n + 15) / 16, tasks));
  } else {  // few rows: every thread gets columns
    EXPECT_LE(t.rows.parts, 2);
    EXPECT_EQ(t.cols.parts, std::min((n + 15) / 16, tasks * threads));
  }
}

TEST(GemmTiling, CoversEachOutputOnceInBandsOfWholeGroups) {
  for (int mr : {1, 4, 6}) {
    for (int m : {1, 5, 6, 7, 59, 100, 302, 1200}) {
      for (int n : {16, 64, 512, 1536, 3200}) {
        for (int threads : {1, 2, 3, 4}) {
          for (bool whole_rows : {false, true}) {
            for (size_t weight_bytes : {size_t{0}, size_t{2} << 20}) {
              expect_tiling_covers_once(m, n, mr, threads, whole_rows, weight_bytes);
            }
          }
        }
      }
    }
  }
}

// Ranges that tile [0, total) in order, start on whole quanta, hold at most max_size items, differ
// by at most a quantum (only the last may be shorter still, by the part of a quantum past total),
// and come in a multiple of the thread count unless every quantum is a range already.
TEST(EvenSplit, TilesTheRangeInNearEqualPartsSharedByTheThreads) {
  for (int quantum : {1, 6, 12, 24}) {
    for (int total : {1, 7, 12, 300, 302, 1200, 4800, 19200, 76800}) {
      for (int max_size : {quantum, 4 * quantum, 108, 192}) {
        for (int threads : {1, 2, 3, 4}) {
          const EvenSplit split = split_evenly(total, quantum, max_size, threads);
          const int units = (total + quantum - 1) / quantum;
          SCOPED_TRACE(testing::Message() << "total " << total << " quantum " << quantum << " max " << max_size
                                          << " threads " << threads << " parts " << split.parts);
          ASSERT_GE(split.parts, 1);
          ASSERT_LE(split.parts, units);
          if (split.parts < units) {  // else every quantum is a range of its own already
            EXPECT_EQ(split.parts % threads, 0);
          }
          int expected_begin = 0, smallest = total, largest = 0;
          for (int i = 0; i < split.parts; ++i) {
            int begin, end;
            split.range(i, begin, end);
            ASSERT_EQ(begin, expected_begin);
            ASSERT_EQ(begin % quantum, 0);
            ASSERT_LT(begin, end);
            ASSERT_LE(end - begin, split.max_size());
            ASSERT_LE(end - begin, std::max(quantum, max_size / quantum * quantum));
            if (i + 1 < split.parts) {
              ASSERT_EQ((end - begin) % quantum, 0);
              smallest = std::min(smallest, end - begin);
            }
            largest = std::max(largest, end - begin);
            expected_begin = end;
          }
          EXPECT_EQ(expected_begin, total);
          if (split.parts > 1) {
            EXPECT_LE(largest - smallest, quantum);
          }
          // The pool's per-thread shares (thread t runs parts [t p / T, (t + 1) p / T)) hold
          // numbers of quanta that differ by at most one.
          if (split.parts % threads == 0) {
            int fewest = units, most = 0;
            for (int t = 0; t < threads; ++t) {
              int begin, end, unused;
              split.range(split.parts * t / threads, begin, unused);
              split.range(split.parts * (t + 1) / threads - 1, unused, end);
              const int share = (end - begin + quantum - 1) / quantum;
              fewest = std::min(fewest, share);
              most = std::max(most, share);
            }
            EXPECT_LE(most - fewest, 1);
          }
        }
      }
    }
  }
}

// parallel_ranges visits every item of [0, total) exactly once, in ranges of at most max_size items
// that start on whole quanta, with thread indices of the pool.
TEST(ParallelRanges, EveryItemOnceInBoundedRangesOnThePoolsThreads) {
  for (int threads : {1, 2, 3}) {
    ThreadPool pool(threads);
    for (int total : {1, 14, 100, 302}) {
      for (int quantum : {1, 6}) {
        std::vector<std::atomic<int>> visits(static_cast<size_t>(total));
        std::atomic<bool> bad_range{false}, bad_thread{false};
        parallel_ranges(pool, total, quantum, 32, [&](int begin, int end, int thread) {
          if (begin % quantum != 0 || end - begin > 32 || begin >= end) bad_range = true;
          if (thread < 0 || thread >= threads) bad_thread = true;
          for (int i = begin; i < end; ++i) visits[static_cast<size_t>(i)]++;
        });
        SCOPED_TRACE(testing::Message() << "threads " << threads << " total " << total << " quantum " << quantum);
        EXPECT_FALSE(bad_range);
        EXPECT_FALSE(bad_thread);
        for (const auto& v : visits) ASSERT_EQ(v.load(), 1);
      }
    }
  }
}

// A chain a -> b -> c -> d of LayerNorms: the planner may reuse a's memory for c, never for b.
TEST(GraphPlanner, ReusesDeadBuffersAndKeepsLiveOnesApart) {
  Graph g;
  const int rows = 4, cols = 64;
  std::vector<float> gamma(cols, 1.0f), beta(cols, 0.0f);
  const ValueId a = g.add_input("a", {rows, cols});
  ValueId prev = a;
  std::vector<ValueId> chain = {a};
  for (int i = 0; i < 4; ++i) {
    std::string name = "v";  // (not "v" + to_string: GCC 12 warns falsely with -Wrestrict)
    name += std::to_string(i);
    const ValueId next = g.add_value(name, {rows, cols});
    g.add_op(std::make_unique<LayerNormOp>(rows, cols, gamma.data(), beta.data(), prev, next));
    chain.push_back(next);
    prev = next;
  }
  g.mark_output(prev);
  g.plan(1, false);
  // Input and output are pinned; consecutive values (live at the same op) never share memory.
  for (size_t i = 1; i < chain.size(); ++i) EXPECT_NE(g.value(chain[i]).offset, g.value(chain[i - 1]).offset);
  std::set<size_t> distinct;
  for (ValueId v : chain) distinct.insert(g.value(v).offset);
  EXPECT_LT(distinct.size(), chain.size()) << "no buffer was reused";
  const size_t planned = g.arena_bytes();
  g.plan(1, true);
  distinct.clear();
  for (ValueId v : chain) distinct.insert(g.value(v).offset);
  EXPECT_EQ(distinct.size(), chain.size());
  EXPECT_GT(g.arena_bytes(), planned);
}

// A row view is its parent's rows: the producer writes them in place, a concatenation skips them,
// and the parent is kept from the view's first write on (a temporary made between the view's write
// and the parent's own op must not share its memory).
TEST(GraphPlanner, RowViewsAreTheirParentsRowsAndKeepItAlive) {
  Graph g;
  const int cols = 16, rows = 3, lead = 2;
  std::vector<float> gamma(cols, 1.0f), beta(cols, 0.0f), constant(static_cast<size_t>(lead) * cols);
  for (size_t i = 0; i < constant.size(); ++i) constant[i] = static_cast<float>(i) - 7.5f;
  const ValueId a = g.add_input("a", {rows, cols});
  const ValueId parent = g.add_value("parent", {lead + rows, cols});
  const ValueId view = g.add_row_view("view", parent, lead, rows);
  const ValueId temp = g.add_value("temp", {rows, cols});  // dead before the parent's own op
  const ValueId temp2 = g.add_value("temp2", {rows, cols});
  const ValueId out = g.add_value("out", {lead + 2 * rows, cols});
  g.add_op(std::make_unique<LayerNormOp>(rows, cols, gamma.data(), beta.data(), a, view));
  g.add_op(std::make_unique<LayerNormOp>(rows, cols, gamma.data(), beta.data(), a, temp));
  g.add_op(std::make_unique<LayerNormOp>(rows, cols, gamma.data(), beta.data(), temp, temp2));
  g.add_op(std::make_unique<ConcatRowsOp>(
      cols, std::vector<ConcatRowsOp::Part>{{MatrixRef::of_constant(constant.data(), cols), lead}, {MatrixRef::of(view, cols), rows}},
      parent));
  g.add_op(std::make_unique<ConcatRowsOp>(
      cols, std::vector<ConcatRowsOp::Part>{{MatrixRef::of(parent, cols), lead + rows}, {MatrixRef::of(temp2, cols), rows}}, out));
  g.mark_output(out);
  g.plan(1, false);
  EXPECT_EQ(g.data(view), g.data(parent) + lead * cols);
  const auto overlap = [&](ValueId x, ValueId y) {
    const float *x0 = g.data(x), *y0 = g.data(y);
    const float *x1 = x0 + g.value(x).elements, *y1 = y0 + g.value(y).elements;
    return x0 < y1 && y0 < x1;
  };
  EXPECT_FALSE(overlap(parent, temp)) << "the parent is live from its view's write on";
  std::vector<float> x(static_cast<size_t>(rows) * cols);
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<float>((i * 7) % 11);
  std::copy(x.begin(), x.end(), g.data(a));
  ThreadPool pool(1);
  g.run(pool, kernels::kernel_config_for(kernels::Isa::kRef));
  const float* o = g.data(out);
  EXPECT_TRUE(std::equal(constant.begin(), constant.end(), o)) << "the leading rows";
  for (int r = 0; r < rows; ++r) {  // the view's rows: the LayerNorm of a's, in place
    const float* xr = x.data() + static_cast<size_t>(r) * cols;
    double mean = 0, var = 0;
    for (int c = 0; c < cols; ++c) mean += xr[c];
    mean /= cols;
    for (int c = 0; c < cols; ++c) var += (xr[c] - mean) * (xr[c] - mean);
    var /= cols;
    for (int c = 0; c < cols; ++c) {
      EXPECT_NEAR(o[static_cast<size_t>(lead + r) * cols + c], (xr[c] - mean) / std::sqrt(var + kLayerNormEps), 1e-5)
          << "row " << r << " col " << c;
    }
  }
}

}  // namespace
}  // namespace act::graph
