// A max-pool run by the convolution that feeds it (the stem's, int8 and float): one walk over bands
// of conv rows for both, so that only the element type, the conv call and the pool call differ.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstring>

#include "graph/gemm_tiling.h"
#include "graph/thread_pool.h"
#include "kernels/common/conv2d_shape.h"
#include "kernels/fp32/fp32_kernels.h"
#include "kernels/pool_s8/maxpool_s8.h"

namespace act::graph {

/// The geometry of a max-pool over a conv's output.
struct FusedMaxPool {
  int kernel = 0, stride = 0, pad = 0, out_h = 0, out_w = 0;

  static FusedMaxPool over(const kernels::Conv2dShape& conv, int kernel, int stride, int pad) {
    return {kernel, stride, pad, kernels::Conv2dShape::out_dim(conv.out_h, kernel, stride, pad, 1),
            kernels::Conv2dShape::out_dim(conv.out_w, kernel, stride, pad, 1)};
  }
  /// Pooled rows per band: as many as keep a band of conv rows (`row_bytes` each) within about
  /// 192 KB, in L2 with the conv's patches and weights (the int8 stem's: 4 pooled rows, 9 conv
  /// rows, 184 KB; the float stem's: 1, 3 rows, 240 KB), at least one.
  int pooled_rows_per_band(size_t row_bytes) const {
    constexpr size_t kBandBytes = 192 * 1024;
    const int fit = static_cast<int>(kBandBytes / row_bytes);
    return std::max(1, (fit - kernel) / stride + 1);
  }
  /// Bytes of the band of conv rows that `pooled_rows` pooled rows read at most.
  size_t band_bytes(size_t row_bytes) const {
    return static_cast<size_t>((pooled_rows_per_band(row_bytes) - 1) * stride + kernel) * row_bytes;
  }
  /// Pooled rows [q0, q1) of the output of `conv`, whose rows from conv_row0 on are at conv_rows.
  void pool_rows(const kernels::MaxPoolS8Kernels& k, const kernels::Conv2dShape& conv, const int8_t* conv_rows,
                 int8_t* pooled, int q0, int q1, int conv_row0) const {
    kernels::maxpool_nhwc_s8(k, conv.out_h, conv.out_w, conv.out_c, kernel, stride, pad, out_w, conv_rows, pooled, q0, q1,
                             conv_row0);
  }
  void pool_rows(const kernels::ElementwiseF32Kernels& k, const kernels::Conv2dShape& conv, const float* conv_rows,
                 float* pooled, int q0, int q1, int conv_row0) const {
    kernels::maxpool_nhwc_f32(k, conv.out_h, conv.out_w, conv.out_c, kernel, stride, pad, out_w, conv_rows, pooled, q0, q1,
                              conv_row0);
  }
};

/// Computes a conv's output band by band and pools it, the whole output never in memory. Tasks of
/// whole pooled rows (one on one thread; two per thread on more, so that a late worker is caught up
/// by the others: each task recomputes the conv rows it shares with the task before); a task walks its rows a band at a time: the conv rows those read go into its band (the
/// rows the last band shares with this one moved to its front, not computed again), then are pooled
/// from there.
///   band_of(thread)                          -> the thread's band (band_bytes(row_bytes) bytes)
///   conv_pixels(band, first, count, band_row0, thread): conv output pixels [first, first + count)
///                                               into the band, which holds rows from band_row0 on
///   pool_rows(band, q0, q1, band_row0)      : pooled rows [q0, q1) from the band
template <class BandOf, class ConvPixels, class PoolRows>
void run_in_pooled_bands(ThreadPool& pool, const FusedMaxPool& mp, const kernels::Conv2dShape& s, size_t element_bytes,
                         int tile_quantum, int tile_pixels, const BandOf& band_of, const ConvPixels& conv_pixels,
                         const PoolRows& pool_rows) {
  const size_t row_bytes = static_cast<size_t>(s.out_w) * static_cast<size_t>(s.out_c) * element_bytes;
  const int rows_per_band = mp.pooled_rows_per_band(row_bytes);
  const int tasks = std::min(mp.out_h, pool.threads() == 1 ? 1 : 2 * pool.threads());
  pool.parallel_for(static_cast<size_t>(tasks), [&](size_t task, int thread) {
    const int p_begin = static_cast<int>(task) * mp.out_h / tasks, p_end = (static_cast<int>(task) + 1) * mp.out_h / tasks;
    std::byte* band = band_of(thread);
    int band_begin = 0, band_end = 0;  // conv rows [band_begin, band_end) are in the band
    for (int q0 = p_begin; q0 < p_end; q0 += rows_per_band) {
      const int q1 = std::min(p_end, q0 + rows_per_band);
      const int lo = std::max(0, q0 * mp.stride - mp.pad), hi = std::min(s.out_h, (q1 - 1) * mp.stride - mp.pad + mp.kernel);
      const int kept = std::max(0, band_end - lo);
      if (kept > 0) std::memmove(band, band + static_cast<size_t>(lo - band_begin) * row_bytes, static_cast<size_t>(kept) * row_bytes);
      // The new rows in tiles of even size (a band's 2560 int8 stem pixels in 14 of ~183, not 13 of 192 and 64).
      const int first = (lo + kept) * s.out_w;
      const EvenSplit tiles = split_evenly(hi * s.out_w - first, tile_quantum, tile_pixels, 1);
      for (int t = 0; t < tiles.parts; ++t) {
        int t0, t1;
        tiles.range(t, t0, t1);
        conv_pixels(band, first + t0, t1 - t0, lo, thread);
      }
      band_begin = lo;
      band_end = hi;
      pool_rows(band, q0, q1, lo);
    }
  });
}

/// Pools a conv's whole output (when something else reads it too), in tasks of a few pooled rows.
template <class PoolRows>
void run_pool_in_row_tasks(ThreadPool& pool, const FusedMaxPool& mp, const PoolRows& pool_rows) {
  constexpr int kRowsPerTask = 4;
  pool.parallel_for(static_cast<size_t>((mp.out_h + kRowsPerTask - 1) / kRowsPerTask), [&](size_t task, int) {
    const int r0 = static_cast<int>(task) * kRowsPerTask;
    pool_rows(r0, std::min(mp.out_h, r0 + kRowsPerTask));
  });
}

}  // namespace act::graph
