#include <algorithm>

#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

size_t gemm_f32_packed_floats(int nr, int n, int k) {
  const size_t panels = (static_cast<size_t>(n) + static_cast<size_t>(nr) - 1) / static_cast<size_t>(nr);
  return panels * static_cast<size_t>(nr) * static_cast<size_t>(k);
}

void gemm_f32_pack(int nr, int n, int k, const float* b, size_t ldb, float* packed) {
  const size_t panel = static_cast<size_t>(nr) * static_cast<size_t>(k);
  for (int c0 = 0; c0 < n; c0 += nr, packed += panel) {
    // Column by column: B's rows are read in order (attention packs its keys on every run).
    for (int j = 0; j < nr; ++j) {
      if (c0 + j >= n) {
        for (int p = 0; p < k; ++p) packed[static_cast<size_t>(p) * nr + j] = 0.0f;
        continue;
      }
      const float* column = b + static_cast<size_t>(c0 + j) * ldb;
      for (int p = 0; p < k; ++p) packed[static_cast<size_t>(p) * nr + j] = column[p];
    }
  }
}

void gemm_f32_unpack(int nr, int n, int k, const float* packed, float* b) {
  const size_t panel = static_cast<size_t>(nr) * static_cast<size_t>(k);
  for (int c = 0; c < n; ++c) {
    const float* column = packed + static_cast<size_t>(c / nr) * panel + static_cast<size_t>(c % nr);
    float* row = b + static_cast<size_t>(c) * static_cast<size_t>(k);
    for (int p = 0; p < k; ++p) row[p] = column[static_cast<size_t>(p) * nr];
  }
}

void gemm_f32_pack_transposed(int nr, int n, int k, const float* bt, size_t ldb, float* packed) {
  for (int c0 = 0; c0 < n; c0 += nr) {
    const int cols = std::min(nr, n - c0);
    for (int p = 0; p < k; ++p) {
      const float* row = bt + static_cast<size_t>(p) * ldb + static_cast<size_t>(c0);
      std::copy(row, row + cols, packed);
      std::fill(packed + cols, packed + nr, 0.0f);
      packed += nr;
    }
  }
}

}  // namespace act::kernels
