// The scalar reference of the packed FP32 GEMM: each output one sum over k in order (separate
// multiplies and adds), then the epilogue.
#include "kernels/fp32/gemm_f32.h"

#include "kernels/fp32/elementwise_f32.h"

namespace act::kernels {

#include "kernels/fp32/winograd_f32_transforms.inc"

namespace {

constexpr int kRefNr = 8;

struct ScalarLanes {
  using V = float;
  static constexpr int kWidth = 1;
  static float load(const float* p) { return *p; }
  static void store(float v, float* p) { *p = v; }
  static float relu(float v) { return v < 0.0f ? 0.0f : v; }
};
using Winograd = WinogradTransforms<ScalarLanes>;

float a_at(const GemmF32PackedArgs& g, int i, int p) {
  if (g.a_segments == nullptr) return g.a[static_cast<size_t>(i) * g.lda + static_cast<size_t>(p)];
  const int segments = g.k / g.segment_k;
  return g.a_segments[static_cast<size_t>(i) * static_cast<size_t>(segments) + static_cast<size_t>(p / g.segment_k)][p % g.segment_k];
}

void gemm_packed_ref(const GemmF32PackedArgs& g) {
  const GemmF32Epilogue& e = g.epilogue;
  for (int i = 0; i < g.m; ++i) {
    float* ci = g.c + static_cast<size_t>(i) * g.ldc;
    for (int j = 0; j < g.n; ++j) {
      const int col = g.col0 + j;
      const float* panel = g.packed_b + static_cast<size_t>(col / kRefNr) * static_cast<size_t>(g.k) * kRefNr +
                           static_cast<size_t>(col % kRefNr);
      float sum = 0.0f;
      for (int p = 0; p < g.k; ++p) sum += a_at(g, i, p) * panel[static_cast<size_t>(p) * kRefNr];
      if (e.bias) sum += e.bias[static_cast<size_t>(i) * e.bias_ld + static_cast<size_t>(j)];
      if (e.residual) sum += e.residual[static_cast<size_t>(i) * e.residual_ld + static_cast<size_t>(j)];
      if (e.activation == GemmF32Activation::kRelu) sum = sum < 0.0f ? 0.0f : sum;
      ci[j] = sum;
    }
    if (e.activation == GemmF32Activation::kGelu) elementwise_f32_table_ref()->gelu(static_cast<size_t>(g.n), ci);
  }
}

}  // namespace

const GemmF32Kernels* gemm_f32_table_ref() {
  static const GemmF32Kernels table{Isa::kRef, "gemm_f32 1x8 ref", 1, kRefNr, gemm_packed_ref, Winograd::input,
                                    Winograd::output};
  return &table;
}

}  // namespace act::kernels
