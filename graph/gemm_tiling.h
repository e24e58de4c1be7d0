// How a GEMM's output [m x n] is split into thread-pool tasks. Whole rows of output, in multiples of
// the kernel's MR, when there are enough of them for at least 5 tiles per thread (XNNPACK's rule):
// each task's A strip stays in L1 while the packed weights stream past it once, and the many small
// tasks even out a worker that starts late. Else columns in multiples of NR (and rows in two when
// there are many). The int8 linears and act_kernel_bench's GEMM rows split this way; the float
// linears keep 128x128 tiles, whose float weights (4x the bytes) would stream from memory per task.
#pragma once

#include <algorithm>
#include <cstddef>

namespace act::graph {

struct GemmTiling {
  int m = 0, n = 0;
  int tile_m = 0, tile_n = 0, tiles_m = 1, tiles_n = 1;
  size_t count() const { return static_cast<size_t>(tiles_m) * static_cast<size_t>(tiles_n); }
  /// Task `task`'s output rectangle [m0, m1) x [n0, n1).
  void rect(size_t task, int& m0, int& m1, int& n0, int& n1) const {
    m0 = static_cast<int>(task / static_cast<size_t>(tiles_n)) * tile_m;
    n0 = static_cast<int>(task % static_cast<size_t>(tiles_n)) * tile_n;
    m1 = std::min(m, m0 + tile_m);
    n1 = std::min(n, n0 + tile_n);
  }
};

/// f32 output rows a one-thread task of `whole_rows` tiling holds: about half of a 1 MB L2.
inline constexpr int kRowStripBytes = 512 * 1024;

/// With `whole_rows` (the caller quantizes each task's rows right after it, while they are still in
/// cache), one thread runs strips of whole rows too, of at most kRowStripBytes of output each.
inline GemmTiling gemm_tiling(int m, int n, int mr, int nr, int threads, bool whole_rows = false) {
  const auto tiles = [](int total, int tile) { return (total + tile - 1) / tile; };
  if (threads <= 1) {
    if (!whole_rows) return {m, n, m, n, 1, 1};
    const int tm = std::min(m, std::max(mr, kRowStripBytes / (4 * n) / mr * mr));
    return {m, n, tm, n, tiles(m, tm), 1};
  }
  const int want = 5 * threads;
  if (m >= want * mr) {
    const int tm = (m / want + mr - 1) / mr * mr;
    return {m, n, tm, n, tiles(m, tm), 1};
  }
  const int tn = std::max(nr, (n / want + nr - 1) / nr * nr);
  const int tm = m >= 2 * mr * 8 ? (m / 2 + mr - 1) / mr * mr : m;
  return {m, n, tm, tn, tiles(m, tm), tiles(n, tn)};
}

}  // namespace act::graph
