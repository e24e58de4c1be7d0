#include <algorithm>

#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

size_t gemm_f32_packed_floats(int nr, int n, int k) {
  const size_t panels = (static_cast<size_t>(n) + static_cast<size_t>(nr) - 1) / static_cast<size_t>(nr);
  return panels * static_cast<size_t>(nr) * static_cast<size_t>(k);
}

void gemm_f32_pack(int nr, int n, int k, const float* b, size_t ldb, float* packed) {
  for (int c0 = 0; c0 < n; c0 += nr) {
    for (int p = 0; p < k; ++p) {
      for (int j = 0; j < nr; ++j) {
        *packed++ = c0 + j < n ? b[static_cast<size_t>(c0 + j) * ldb + static_cast<size_t>(p)] : 0.0f;
      }
    }
  }
}

}  // namespace act::kernels
