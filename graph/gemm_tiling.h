// How a GEMM's output [m x n] is split into thread-pool tasks. Whole rows of output, in multiples of
// the kernel's MR, when there are enough of them for 5 tasks of two MR or more per thread: each
// task's A strip stays in L1 while the packed weights stream past it once, and the many small tasks
// even out a worker that starts late (weights past L2: a row band per thread in 5 column blocks, so
// that they are not streamed once per task). Else columns in multiples of NR (and rows in two when
// there are many). The int8 linears and act_kernel_bench's GEMM rows split this way; the convolutions
// split their output pixels, and the float linears their columns, with the same EvenSplit.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace act::graph {

/// `total` items cut into `parts` ranges of whole `quantum`s (the last range may end short of one)
/// whose sizes differ by at most one quantum, the larger ones spread evenly: the thread pool gives
/// each thread a contiguous share of the parts, and the shares of a split into a multiple of the
/// thread count differ by at most one quantum too. (Fixed-size tiles left a remainder: layer3's
/// 1200 pixels in 11 tiles of 108 and one of 12 gave one of two threads a whole tile more; the
/// larger parts first gave layer4's 25 quanta in 8 parts as 13 to one thread and 12 to the other.)
struct EvenSplit {
  int total = 0, quantum = 1, parts = 1;
  /// Range i: [begin, end).
  void range(int i, int& begin, int& end) const {
    begin = std::min(total, quantum * units_before(i));
    end = std::min(total, quantum * units_before(i + 1));
  }
  /// The size of the largest range.
  int max_size() const {
    const int units = (total + quantum - 1) / quantum;
    return std::min(total, quantum * ((units + parts - 1) / parts));
  }

 private:
  /// Quanta in ranges [0, i): i whole shares of units / parts, and the i-th part of the remainder,
  /// rounded down (each range takes one unit of the remainder where that count steps up).
  int units_before(int i) const {
    const int units = (total + quantum - 1) / quantum;
    return i * (units / parts) + static_cast<int>(static_cast<int64_t>(i) * (units % parts) / parts);
  }
};

/// The split of `total` into ranges of at most `max_size` items (a multiple of `quantum`): as few
/// as that allows, rounded up to a multiple of `threads` while every range keeps a quantum.
inline EvenSplit split_evenly(int total, int quantum, int max_size, int threads) {
  const int units = (total + quantum - 1) / quantum;
  const int max_units = std::max(1, max_size / quantum);
  int parts = (units + max_units - 1) / max_units;
  if (threads > 1) parts = std::min(units, (parts + threads - 1) / threads * threads);
  return {total, quantum, std::max(1, parts)};
}

/// Runs f(begin, end, thread) over [0, total) in tasks of at most `max_size` items (whole
/// `quantum`s), as many tasks per thread: the per-row and element-wise ops' split (fixed 32-row
/// tasks gave the decoder's 100 rows to two threads as 64 and 36, and its LayerNorm 1.5x on two).
template <class Pool, class F>
void parallel_ranges(Pool& pool, int total, int quantum, int max_size, F&& f) {
  const EvenSplit split = split_evenly(total, quantum, max_size, pool.threads());
  pool.parallel_for(static_cast<size_t>(split.parts), [&](size_t task, int thread) {
    int begin, end;
    split.range(static_cast<int>(task), begin, end);
    f(begin, end, thread);  // never empty: split_evenly gives every part at least one quantum
  });
}

struct GemmTiling {
  EvenSplit rows, cols;
  size_t count() const { return static_cast<size_t>(rows.parts) * static_cast<size_t>(cols.parts); }
  /// Task `task`'s output rectangle [m0, m1) x [n0, n1).
  void rect(size_t task, int& m0, int& m1, int& n0, int& n1) const {
    rows.range(static_cast<int>(task / static_cast<size_t>(cols.parts)), m0, m1);
    cols.range(static_cast<int>(task % static_cast<size_t>(cols.parts)), n0, n1);
  }
};

/// f32 output rows a one-thread task of `whole_rows` tiling holds: about half of a 1 MB L2.
inline constexpr int kRowStripBytes = 512 * 1024;

/// Tasks per thread of a GEMM split over several threads (the balance of a worker that starts late).
inline constexpr int kGemmTasksPerThread = 5;

/// Weights larger than this do not stay in a core's L2 (1 MB on Zen 4 and 5) from task to task.
inline constexpr size_t kL2WeightBytes = size_t{1} << 20;

/// With `whole_rows` (the caller quantizes each task's rows right after it, while they are still in
/// cache), one thread runs strips of whole rows too, of at most kRowStripBytes of output each.
/// `weight_bytes` (K x N int8): past kL2WeightBytes, many rows split in columns too (below).
inline GemmTiling gemm_tiling(int m, int n, int mr, int nr, int threads, bool whole_rows = false,
                              size_t weight_bytes = 0) {
  const EvenSplit all_cols{n, nr, 1};
  if (threads <= 1) {
    if (!whole_rows) return {{m, mr, 1}, all_cols};
    return {split_evenly(m, mr, std::max(mr, kRowStripBytes / (4 * n) / mr * mr), 1), all_cols};
  }
  const int want = kGemmTasksPerThread * threads;
  const int col_units = (n + nr - 1) / nr;
  // Rows while every task gets at least two row tiles. With fewer (the decoder's 100 rows: 17
  // tiles of 6 in 10 tasks, 7 of two tiles and 3 of one), the tasks are uneven by half and each
  // one streams all the weights for 6-12 rows; columns give each task a share of the weights.
  // Tasks that finish their rows keep rows down to one tile each: a pass of its own to finish them
  // cost more than the uneven tiles (the decoder's cross_out, 0.076 -> 0.083 ms on two threads).
  if (m >= (whole_rows ? 1 : 2) * want * mr) {
    // Weights past L2 (the FFN hidden layers' 1.6 MB), when the tasks need not finish rows: a row
    // band per thread cut in 5 column blocks, each task streaming a fifth of the weights, where 5
    // row tasks per thread streamed all of them 5 times per thread (encoder 0.78 -> 0.74 ms on two
    // threads). Two row tasks per thread for the row-finishing FFN outputs measured the same.
    if (whole_rows || weight_bytes <= kL2WeightBytes) return {{m, mr, want}, all_cols};
    return {{m, mr, threads}, {n, nr, std::min(col_units, kGemmTasksPerThread)}};
  }
  return {{m, mr, m >= 2 * mr * 8 ? 2 : 1}, {n, nr, std::max(1, std::min(col_units, want))}};
}

}  // namespace act::graph
