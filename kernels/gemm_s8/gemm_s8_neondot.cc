// gemm_s8 on AArch64 with the dot-product extension: the 4x16c4 SDOT micro-kernel and the 1x16c4
// kernel for the last M % 4 rows. Compiled with -march=armv8.2-a+dotprod on AArch64 targets only;
// elsewhere this file is just the null table.
//
// sdot v.4s, w.16b, a.4b[l] multiplies, per int32 lane, 4 signed weight bytes by the 4 activation
// bytes of lane l and adds the sum to the accumulator (16 MACs per instruction). A rows are read in
// place, 16 bytes (4 k-groups) per load; each k-group's 16 columns x 4 bytes are 4 q registers of
// packed weights (pack_w_s8_16x4_goi), so no activation packing is needed (the property that
// lets an indirect convolution reuse this kernel; XNNPACK's 4x16c4-neondot has the same shape).
// 16 accumulators + 4 A registers + 4 weight registers = 24 of the 32 v registers.
//
// K tail: after the 16-byte steps, an 8-byte step and a 4-byte step; reads never pass the last
// k-group (at most 3 bytes past A[m][K-1], inside the 16-byte slack).
//
// Rules for ISA files (see README.md): only intrinsics and internal-linkage code here.
#include "kernels/gemm_s8/gemm_s8_variants.h"

#if defined(__aarch64__)

#include <arm_neon.h>

#include <cstring>
#include <type_traits>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {

constexpr int kMR = 4;
constexpr int kNR = 16;
constexpr int kKR = 4;
constexpr Isa kIsa = Isa::kNeonDot;
constexpr GemmS8Layout kLayout = GemmS8Layout::kNeon16x4;
constexpr bool own_layout(GemmS8Layout l) { return l == kLayout; }
constexpr size_t kPanelBlockBytes = size_t{256} << 10;  // half the A76's 512 KB L2

#include "kernels/gemm_s8/gemm_s8_driver.inc"

template <int R>
using TileAcc = int32x4_t[R][4];

// sdot by element: lane L of a 16-byte (q) or an 8-byte (d) A chunk.
template <int L>
int32x4_t dot_lane(int32x4_t acc, int8x16_t w, int8x16_t a) {
  return vdotq_laneq_s32(acc, w, a, L);
}
template <int L>
int32x4_t dot_lane(int32x4_t acc, int8x16_t w, int8x8_t a) {
  return vdotq_lane_s32(acc, w, a, L);
}

// One k-group (16 columns x 4 bytes) against lane L of each row's A chunk (int8x16_t or int8x8_t).
template <int R, int L, class Chunk>
inline void step(const int8_t* wg, const Chunk (&av)[R], int32x4_t (&acc)[R][4]) {
  const int8x16_t w0 = vld1q_s8(wg), w1 = vld1q_s8(wg + 16), w2 = vld1q_s8(wg + 32), w3 = vld1q_s8(wg + 48);
  for (int r = 0; r < R; ++r) {
    acc[r][0] = dot_lane<L>(acc[r][0], w0, av[r]);
    acc[r][1] = dot_lane<L>(acc[r][1], w1, av[r]);
    acc[r][2] = dot_lane<L>(acc[r][2], w2, av[r]);
    acc[r][3] = dot_lane<L>(acc[r][3], w3, av[r]);
  }
}

// out[r][j] = kbias + sum over k, A walked segment by segment (kp / segments bytes each). The
// accumulators are a local array (copied out once) so that GCC keeps them in registers; an
// out-parameter array would be stored every iteration.
template <int R>
inline void accumulate(const GemmS8Args& g, int m, const uint8_t* panel, int kp, int32x4_t (&out)[R][4]) {
  int32x4_t acc[R][4];
  const auto* kbias = static_cast<const int32_t*>(static_cast<const void*>(panel));
  for (int j = 0; j < 4; ++j) {
    const int32x4_t b = vld1q_s32(kbias + 4 * j);
    for (int r = 0; r < R; ++r) acc[r][j] = b;
  }
  const int segments = segment_count(g), segment_bytes = kp / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    // k-group k/4 of the segment starts at (k/4) * 64 bytes of its weights.
    const int8_t* w = reinterpret_cast<const int8_t*>(panel + 8 * kNR) + static_cast<size_t>(s) * segment_bytes * kNR;
    int k = 0;
    for (; k + 16 <= segment_bytes; k += 16) {
      int8x16_t av[R];
      for (int r = 0; r < R; ++r) av[r] = vld1q_s8(rows[r] + k);
      const int8_t* wk = w + static_cast<size_t>(k) * kNR;
      step<R, 0>(wk, av, acc);
      step<R, 1>(wk + 64, av, acc);
      step<R, 2>(wk + 128, av, acc);
      step<R, 3>(wk + 192, av, acc);
    }
    if (k + 8 <= segment_bytes) {
      int8x8_t av[R];
      for (int r = 0; r < R; ++r) av[r] = vld1_s8(rows[r] + k);
      const int8_t* wk = w + static_cast<size_t>(k) * kNR;
      step<R, 0>(wk, av, acc);
      step<R, 1>(wk + 64, av, acc);
      k += 8;
    }
    if (k < segment_bytes) {  // one k-group left
      int8x8_t av[R];
      for (int r = 0; r < R; ++r) {
        int32_t quad;
        std::memcpy(&quad, rows[r] + k, 4);
        av[r] = vreinterpret_s8_s32(vdup_n_s32(quad));
      }
      step<R, 0>(w + static_cast<size_t>(k) * kNR, av, acc);
    }
  }
  for (int r = 0; r < R; ++r) {
    for (int j = 0; j < 4; ++j) out[r][j] = acc[r][j];
  }
}

// Per-column float parameters of a panel, zero outside [lo, hi) so nothing past N is read.
void load_cols(const float* p, int n, int lo, int hi, float32x4_t (&out)[4]) {
  float tmp[kNR] = {};
  const float* src = p + n;
  if (lo != 0 || hi != kNR) {
    std::memcpy(tmp + lo, p + n + lo, sizeof(float) * static_cast<size_t>(hi - lo));
    src = tmp;
  }
  for (int j = 0; j < 4; ++j) out[j] = vld1q_f32(src + 4 * j);
}

struct EpiS8 {
  const GemmS8OutS8& o;
  float32x4_t scale[4]{}, bias[4]{};

  void begin_panel(int n, int lo, int hi) {
    load_cols(o.scale, n, lo, hi, scale);
    if (o.bias != nullptr) load_cols(o.bias, n, lo, hi, bias);
  }
  void row(int m, int n, int lo, int hi, const int32x4_t (&acc)[4]) const {
    const bool full = lo == 0 && hi == kNR;
    float32x4_t v[4];
    for (int j = 0; j < 4; ++j) {
      const float32x4_t s = o.a_row_scale != nullptr ? vmulq_f32(vdupq_n_f32(o.a_row_scale[m]), scale[j]) : scale[j];
      v[j] = vmulq_f32(vcvtq_f32_s32(acc[j]), s);
      if (o.bias != nullptr) v[j] = vaddq_f32(v[j], bias[j]);
    }
    if (o.residual != nullptr) {
      const int8_t* rp = o.residual + static_cast<size_t>(m) * o.ldr + n;
      int8_t tmp[kNR] = {};
      if (!full) {
        std::memcpy(tmp + lo, rp + lo, static_cast<size_t>(hi - lo));
        rp = tmp;
      }
      const int8x16_t rb = vld1q_s8(rp);
      const int16x8_t r16[2] = {vmovl_s8(vget_low_s8(rb)), vmovl_high_s8(rb)};
      const int32x4_t rzp = vdupq_n_s32(o.residual_zero_point);
      const float32x4_t rscale = vdupq_n_f32(o.residual_scale);
      for (int j = 0; j < 4; ++j) {
        const int16x8_t h = r16[j / 2];
        const int32x4_t r32 = vsubq_s32(j % 2 == 0 ? vmovl_s16(vget_low_s16(h)) : vmovl_high_s16(h), rzp);
        v[j] = vaddq_f32(v[j], vmulq_f32(vcvtq_f32_s32(r32), rscale));
      }
    }
    const float32x4_t zo = vdupq_n_f32(static_cast<float>(o.out_zero_point));
    const float32x4_t qmin = vdupq_n_f32(static_cast<float>(o.qmin));
    const float32x4_t qmax = vdupq_n_f32(static_cast<float>(o.qmax));
    int32x4_t q[4];
    for (int j = 0; j < 4; ++j) {
      float32x4_t x = vaddq_f32(v[j], zo);
      x = vmaxnmq_f32(x, qmin);  // v > qmin ? v : qmin (fmaxnm turns a NaN into qmin, like maxps)
      x = vminnmq_f32(x, qmax);
      q[j] = vcvtnq_s32_f32(x);  // round half to even
    }
    const int16x8_t q16a = vcombine_s16(vqmovn_s32(q[0]), vqmovn_s32(q[1]));
    const int16x8_t q16b = vcombine_s16(vqmovn_s32(q[2]), vqmovn_s32(q[3]));
    const int8x16_t q8 = vcombine_s8(vqmovn_s16(q16a), vqmovn_s16(q16b));  // exact: within [qmin, qmax]
    int8_t* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    if (full) {
      vst1q_s8(cp, q8);
    } else {
      int8_t tmp[kNR];
      vst1q_s8(tmp, q8);
      std::memcpy(cp + lo, tmp + lo, static_cast<size_t>(hi - lo));
    }
  }
};

struct EpiF32 {
  const GemmS8OutF32& o;
  float32x4_t w_scale[4]{}, bias[4]{};

  void begin_panel(int n, int lo, int hi) {
    load_cols(o.w_scale, n, lo, hi, w_scale);
    if (o.bias != nullptr) {
      load_cols(o.bias, n, lo, hi, bias);
    } else {
      for (auto& b : bias) b = vdupq_n_f32(0.0f);
    }
  }
  void row(int m, int n, int lo, int hi, const int32x4_t (&acc)[4]) const {
    const bool full = lo == 0 && hi == kNR;
    const float32x4_t a_scale = vdupq_n_f32(o.a_row_scale != nullptr ? o.a_row_scale[m] : o.a_scale);
    float res[kNR] = {};
    const float* rp = nullptr;
    if (o.residual != nullptr) {
      rp = o.residual + static_cast<size_t>(m) * o.ldr + n;
      if (!full) {
        std::memcpy(res + lo, rp + lo, sizeof(float) * static_cast<size_t>(hi - lo));
        rp = res;
      }
    }
    float out[kNR];
    float* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    float* dst = full ? cp : out;
    for (int j = 0; j < 4; ++j) {
      const float32x4_t s = vmulq_f32(a_scale, w_scale[j]);
      float32x4_t y = vmulq_f32(vcvtq_f32_s32(acc[j]), s);
      y = vaddq_f32(y, bias[j]);
      if (rp != nullptr) y = vaddq_f32(y, vld1q_f32(rp + 4 * j));
      if (o.relu) y = vmaxnmq_f32(y, vdupq_n_f32(0.0f));  // y > 0 ? y : 0 (NaN -> 0)
      vst1q_f32(dst + 4 * j, y);
    }
    if (!full) std::memcpy(cp + lo, out + lo, sizeof(float) * static_cast<size_t>(hi - lo));
  }
};

struct EpiS32 {
  const GemmS8OutS32& o;
  void begin_panel(int, int, int) {}
  void row(int m, int n, int lo, int hi, const int32x4_t (&acc)[4]) const {
    int32_t* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    if (lo == 0 && hi == kNR) {
      for (int j = 0; j < 4; ++j) vst1q_s32(cp + 4 * j, acc[j]);
    } else {
      int32_t tmp[kNR];
      for (int j = 0; j < 4; ++j) vst1q_s32(tmp + 4 * j, acc[j]);
      std::memcpy(cp + lo, tmp + lo, sizeof(int32_t) * static_cast<size_t>(hi - lo));
    }
  }
};

// acc -= (z_row - z_packed) * ksum (the driver's per-row zero points).
template <int R>
void subtract_row_zero_points(const GemmS8Args& g, const GemmS8PackedHeader& h, const uint8_t* panel, int m,
                              int32x4_t (&acc)[R][4]) {
  const auto* ksum = static_cast<const int32_t*>(static_cast<const void*>(panel + 4 * kNR));
  for (int r = 0; r < R; ++r) {
    const int32x4_t dz = vdupq_n_s32(g.a_row_zero_point[m + r] - h.a_zero_point);
    for (int j = 0; j < 4; ++j) acc[r][j] = vmlsq_s32(acc[r][j], dz, vld1q_s32(ksum + 4 * j));
  }
}

#include "kernels/gemm_s8/gemm_s8_tiles.inc"

}  // namespace

const GemmS8Kernels* gemm_s8_table_neondot() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_16x4_goi", "gemm_s8s8_s8out_4x16c4_neondot", "gemm_s8s8_f32out_4x16c4_neondot",
       "gemm_s8s8_s32out_4x16c4_neondot"},
      pack_w_s8_16x4_goi, pack_wt_s8_16x4_goi);
  return &kTable;
}

}  // namespace act::kernels

#else  // not AArch64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_neondot() { return nullptr; }
}  // namespace act::kernels

#endif
