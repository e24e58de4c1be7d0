// quant on AArch64 NEON (the kNeon variant). 16 floats per step:
// fmaxnm/fminnm clamp (NaN -> -128, like the reference), fcvtns rounds half to even, sqxtn narrows.
// Ragged tails go through a stack buffer and the same vector code (quant_s8_tail.inc).
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/quant/quant_s8_variants.h"

#if defined(__aarch64__)

#include <arm_neon.h>

#include <cstring>

namespace act::kernels {

namespace {

#include "kernels/quant/quant_s8_tail.inc"

int32x4_t quantize4(const float* x, float32x4_t inv, float32x4_t z, float32x4_t lo, float32x4_t hi) {
  float32x4_t v = vmulq_f32(vld1q_f32(x), inv);
  v = vaddq_f32(v, z);
  v = vmaxnmq_f32(v, lo);  // fmaxnm returns the number when the other operand is a NaN
  v = vminnmq_f32(v, hi);
  return vcvtnq_s32_f32(v);
}

void quantize16(const float* x, float32x4_t inv, float32x4_t z, float32x4_t lo, float32x4_t hi, int8_t* y) {
  const int16x8_t a = vcombine_s16(vqmovn_s32(quantize4(x, inv, z, lo, hi)), vqmovn_s32(quantize4(x + 4, inv, z, lo, hi)));
  const int16x8_t b =
      vcombine_s16(vqmovn_s32(quantize4(x + 8, inv, z, lo, hi)), vqmovn_s32(quantize4(x + 12, inv, z, lo, hi)));
  vst1q_s8(y, vcombine_s8(vqmovn_s16(a), vqmovn_s16(b)));
}

void quantize_f32_s8_neon(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  const float32x4_t inv = vdupq_n_f32(inv_scale), z = vdupq_n_f32(static_cast<float>(zero_point));
  const float32x4_t lo = vdupq_n_f32(-128.0f), hi = vdupq_n_f32(127.0f);
  blocks_zero_padded<16>(n, x, y, [&](const float* xb, int8_t* yb) { quantize16(xb, inv, z, lo, hi, yb); });
}

void dequantize16(const int8_t* q, float32x4_t z, float32x4_t s, float* y) {
  const int8x16_t b = vld1q_s8(q);
  const int16x8_t h0 = vmovl_s8(vget_low_s8(b)), h1 = vmovl_s8(vget_high_s8(b));
  const int32x4_t w[4] = {vmovl_s16(vget_low_s16(h0)), vmovl_s16(vget_high_s16(h0)), vmovl_s16(vget_low_s16(h1)),
                          vmovl_s16(vget_high_s16(h1))};
  for (int j = 0; j < 4; ++j) vst1q_f32(y + 4 * j, vmulq_f32(vsubq_f32(vcvtq_f32_s32(w[j]), z), s));
}

void dequantize_s8_f32_neon(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  const float32x4_t z = vdupq_n_f32(static_cast<float>(zero_point)), s = vdupq_n_f32(scale);
  blocks_zero_padded<16>(n, q, y, [&](const int8_t* qb, float* yb) { dequantize16(qb, z, s, yb); });
}

// fminnm / fmaxnm ignore a NaN operand, as the reference's compare does; the tail is NaN-padded.
void minmax_f32_neon(size_t n, const float* x, float* lo, float* hi) {
  float32x4_t mn0 = vdupq_n_f32(__builtin_inff()), mn1 = mn0;
  float32x4_t mx0 = vdupq_n_f32(-__builtin_inff()), mx1 = mx0;
  blocks_nan_padded<8>(n, x, [&](const float* xb) {
    const float32x4_t a = vld1q_f32(xb), b = vld1q_f32(xb + 4);
    mn0 = vminnmq_f32(mn0, a);
    mx0 = vmaxnmq_f32(mx0, a);
    mn1 = vminnmq_f32(mn1, b);
    mx1 = vmaxnmq_f32(mx1, b);
  });
  *lo = vminnmvq_f32(vminnmq_f32(mn0, mn1));
  *hi = vmaxnmvq_f32(vmaxnmq_f32(mx0, mx1));
}

void quantize_rows_symmetric_f32_s8_neon(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                         float* row_scale) {
  quantize_rows_symmetric_with<minmax_f32_neon, quantize_f32_s8_neon>(rows, cols, x, ldx, y, ldy, row_scale);
}

// 16 columns at a time (four vectors): their minmax down the rows, 16 scales, then the same rows
// quantized with four vectors of inverse scales; each row is visited twice per block (attention's
// rows lie pages apart: a visit is a TLB lookup). A ragged block's vectors go through a NaN-padded
// stack copy.
void quantize_columns_symmetric_f32_s8_neon(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                            float* col_scale) {
  constexpr int kVectors = 4, kBlock = 4 * kVectors;
  const float32x4_t zero = vdupq_n_f32(0.0f), lo = vdupq_n_f32(-128.0f), hi = vdupq_n_f32(127.0f);
  for (int c0 = 0; c0 < cols; c0 += kBlock) {
    const int width = cols - c0 < kBlock ? cols - c0 : kBlock;
    const auto load = [&](int r, int j) {
      const float* xv = x + static_cast<size_t>(r) * ldx + c0 + 4 * j;
      const int left = width - 4 * j;
      if (left >= 4) return vld1q_f32(xv);
      float t[4];
      for (float& v : t) v = __builtin_nanf("");
      if (left > 0) std::memcpy(t, xv, static_cast<size_t>(left) * sizeof(float));
      return vld1q_f32(t);
    };
    float32x4_t mn[kVectors], mx[kVectors];
    for (int j = 0; j < kVectors; ++j) {
      mn[j] = vdupq_n_f32(__builtin_inff());
      mx[j] = vdupq_n_f32(-__builtin_inff());
    }
    for (int r = 0; r < rows; ++r) {
      for (int j = 0; j < kVectors; ++j) {
        const float32x4_t a = load(r, j);
        mn[j] = vminnmq_f32(mn[j], a);  // fminnm skips a NaN, as minmax does
        mx[j] = vmaxnmq_f32(mx[j], a);
      }
    }
    float lo_c[kBlock], hi_c[kBlock], inv_c[kBlock] = {};
    for (int j = 0; j < kVectors; ++j) {
      vst1q_f32(lo_c + 4 * j, mn[j]);
      vst1q_f32(hi_c + 4 * j, mx[j]);
    }
    for (int c = 0; c < width; ++c) col_scale[c0 + c] = symmetric_scale_s8(lo_c[c], hi_c[c], &inv_c[c]);
    float32x4_t inv[kVectors];
    for (int j = 0; j < kVectors; ++j) inv[j] = vld1q_f32(inv_c + 4 * j);
    for (int r = 0; r < rows; ++r) {
      int16x4_t h[kVectors];
      for (int j = 0; j < kVectors; ++j) {
        float32x4_t v = vaddq_f32(vmulq_f32(load(r, j), inv[j]), zero);  // the rule, as quantize4
        v = vminnmq_f32(vmaxnmq_f32(v, lo), hi);
        h[j] = vqmovn_s32(vcvtnq_s32_f32(v));
      }
      const int8x16_t b = vcombine_s8(vqmovn_s16(vcombine_s16(h[0], h[1])), vqmovn_s16(vcombine_s16(h[2], h[3])));
      int8_t* yr = y + static_cast<size_t>(r) * ldy + c0;
      if (width == kBlock) {
        vst1q_s8(yr, b);
      } else {
        int8_t t[kBlock];
        vst1q_s8(t, b);
        std::memcpy(yr, t, static_cast<size_t>(width));
      }
    }
  }
}

}  // namespace

const QuantS8Kernels* quant_s8_table_neon() {
  static constexpr QuantS8Kernels kTable = {Isa::kNeon,
                                            "quantize_f32_s8_neon",
                                            "dequantize_s8_f32_neon",
                                            "minmax_f32_neon",
                                            "quantize_rows_symmetric_f32_s8_neon",
                                            "quantize_columns_symmetric_f32_s8_neon",
                                            quantize_f32_s8_neon,
                                            dequantize_s8_f32_neon,
                                            minmax_f32_neon,
                                            quantize_rows_symmetric_f32_s8_neon,
                                            quantize_columns_symmetric_f32_s8_neon};
  return &kTable;
}

}  // namespace act::kernels

#else  // not AArch64

namespace act::kernels {
const QuantS8Kernels* quant_s8_table_neon() { return nullptr; }
}  // namespace act::kernels

#endif
