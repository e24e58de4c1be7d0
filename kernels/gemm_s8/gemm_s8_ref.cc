// The scalar reference of the gemm_s8 family: the normative behaviour every ISA variant matches
// bit for bit (int32 accumulators and s8 outputs exactly; f32 outputs by the same float
// operations). Written for clarity, not speed. Layout: pack_w_s8_1x1_goi (one column per panel).
#include <cstring>

#include "kernels/common/check.h"
#include "kernels/common/requant_ref.h"
#include "kernels/gemm_s8/gemm_s8_variants.h"

namespace act::kernels {

namespace {

const GemmS8PackedHeader& header_of(const GemmS8Args& g) {
  return *static_cast<const GemmS8PackedHeader*>(g.packed_w);
}

void check_args(const GemmS8Args& g, size_t ldc, int m0, int m1, int n0, int n1) {
  const GemmS8PackedHeader& h = header_of(g);
  ACT_DCHECK(h.magic == kGemmS8PackedMagic && h.layout == GemmS8Layout::kRef1x1,
             "packed_w was not written by pack_w_s8_1x1_goi");
  ACT_DCHECK(h.n == g.n && h.k == g.k, "packed_w has another shape");
  ACT_DCHECK(g.k >= 1 && g.k <= kGemmS8MaxK, "bad k");
  ACT_DCHECK(g.a_segments != nullptr ? g.segment_k > 0 && g.segment_k % kGemmS8SegmentAlign == 0 && g.k % g.segment_k == 0
                                     : g.lda >= static_cast<size_t>(g.k),
             "bad lda or segment_k");
  ACT_DCHECK(ldc >= static_cast<size_t>(g.n), "ldc < n");
  ACT_DCHECK(0 <= m0 && m0 <= m1 && m1 <= g.m && 0 <= n0 && n0 <= n1 && n1 <= g.n, "rectangle outside C");
  (void)h, (void)ldc, (void)m0, (void)m1, (void)n0, (void)n1;
}

// A[m][k], from its rows or its segments.
int8_t a_at(const GemmS8Args& g, int m, int k) {
  if (g.a_segments == nullptr) return g.a[static_cast<size_t>(m) * g.lda + static_cast<size_t>(k)];
  const size_t segments_per_row = static_cast<size_t>(g.k / g.segment_k);
  return g.a_segments[static_cast<size_t>(m) * segments_per_row + static_cast<size_t>(k / g.segment_k)][k % g.segment_k];
}

// acc[m][n] = sum_k (A[m][k] - z_a) W[n][k] + bias[n], modulo 2^32, from the packed column:
// sum_k A W + kbias - (z_row - z_packed) ksum, which is the same number.
int32_t accumulate(const GemmS8Args& g, int m, int n) {
  const GemmS8PackedHeader& h = header_of(g);
  const auto* panel = static_cast<const uint8_t*>(g.packed_w) + sizeof(GemmS8PackedHeader) +
                      static_cast<size_t>(n) * h.panel_bytes;
  int32_t kbias, ksum;
  std::memcpy(&kbias, panel, 4);
  std::memcpy(&ksum, panel + 4, 4);
  const auto* w = reinterpret_cast<const int8_t*>(panel + 8);
  int64_t acc = kbias;
  for (int k = 0; k < g.k; ++k) acc += int32_t{a_at(g, m, k)} * int32_t{w[k]};
  if (g.a_row_zero_point != nullptr) acc -= (int64_t{g.a_row_zero_point[m]} - h.a_zero_point) * ksum;
  return static_cast<int32_t>(acc);  // modular, like the SIMD int32 lanes
}

void record(const GemmS8Args& g) {
  if (g.covered != nullptr) {
    g.covered->record(Isa::kRef, kPathFullTile | (g.a_row_zero_point != nullptr ? kPathRowZeroPoint : 0u) |
                                     (g.a_segments != nullptr ? kPathSegmentedA : 0u));
  }
}

}  // namespace

void gemm_s8s8_s8out_1x1c1_ref(const GemmS8Args& g, const GemmS8OutS8& o, int m0, int m1, int n0, int n1) {
  check_args(g, o.ldc, m0, m1, n0, n1);
  ACT_DCHECK(o.residual == nullptr || o.ldr == 0 || o.ldr >= static_cast<size_t>(g.n), "0 < ldr < n");
  ACT_DCHECK(-128 <= o.qmin && o.qmin <= o.qmax && o.qmax <= 127, "bad clamp");
  for (int m = m0; m < m1; ++m) {
    for (int n = n0; n < n1; ++n) {
      const int32_t acc = accumulate(g, m, n);
      int8_t q;
      if (o.a_row_scale != nullptr || o.bias != nullptr) {
        float v = ref::scale_acc_row(acc, o.a_row_scale != nullptr ? o.a_row_scale[m] : 1.0f, o.scale[n],
                                     o.bias != nullptr ? o.bias[n] : 0.0f);
        if (o.residual != nullptr) {
          v = ref::fp_barrier(v + ref::residual_term(o.residual[static_cast<size_t>(m) * o.ldr + n], o.residual_zero_point,
                                                     o.residual_scale));
        }
        q = ref::finish_s8(v, o.out_zero_point, o.qmin, o.qmax);
      } else if (o.residual != nullptr) {
        q = ref::requantize_s8_residual(acc, o.scale[n], o.residual[static_cast<size_t>(m) * o.ldr + n],
                                        o.residual_zero_point, o.residual_scale, o.out_zero_point, o.qmin, o.qmax);
      } else {
        q = ref::requantize_s8(acc, o.scale[n], o.out_zero_point, o.qmin, o.qmax);
      }
      o.c[static_cast<size_t>(m) * o.ldc + n] = q;
    }
  }
  record(g);
}

void gemm_s8s8_f32out_1x1c1_ref(const GemmS8Args& g, const GemmS8OutF32& o, int m0, int m1, int n0, int n1) {
  check_args(g, o.ldc, m0, m1, n0, n1);
  ACT_DCHECK(o.residual == nullptr || o.ldr == 0 || o.ldr >= static_cast<size_t>(g.n), "0 < ldr < n");
  for (int m = m0; m < m1; ++m) {
    const float a_scale = o.a_row_scale != nullptr ? o.a_row_scale[m] : o.a_scale;
    for (int n = n0; n < n1; ++n) {
      const int32_t acc = accumulate(g, m, n);
      const float bias = o.bias != nullptr ? o.bias[n] : 0.0f;
      const float res = o.residual != nullptr ? o.residual[static_cast<size_t>(m) * o.ldr + n] : 0.0f;
      o.c[static_cast<size_t>(m) * o.ldc + n] =
          ref::dequantize_f32(acc, a_scale, o.w_scale[n], bias, o.residual != nullptr, res, o.relu);
    }
  }
  record(g);
}

void gemm_s8s8_s32out_1x1c1_ref(const GemmS8Args& g, const GemmS8OutS32& o, int m0, int m1, int n0, int n1) {
  check_args(g, o.ldc, m0, m1, n0, n1);
  for (int m = m0; m < m1; ++m) {
    for (int n = n0; n < n1; ++n) o.c[static_cast<size_t>(m) * o.ldc + n] = accumulate(g, m, n);
  }
  record(g);
}

const GemmS8Kernels* gemm_s8_table_ref() {
  static constexpr GemmS8Kernels kTable = {
      Isa::kRef,
      GemmS8Layout::kRef1x1,
      1,
      1,
      1,
      "pack_w_s8_1x1_goi",
      "gemm_s8s8_s8out_1x1c1_ref",
      "gemm_s8s8_f32out_1x1c1_ref",
      "gemm_s8s8_s32out_1x1c1_ref",
      [](int n, int k) { return gemm_s8_packed_size(GemmS8Layout::kRef1x1, n, k); },
      pack_w_s8_1x1_goi,
      pack_wt_s8_1x1_goi,
      gemm_s8s8_s8out_1x1c1_ref,
      gemm_s8s8_f32out_1x1c1_ref,
      gemm_s8s8_s32out_1x1c1_ref,
  };
  return &kTable;
}

}  // namespace act::kernels
