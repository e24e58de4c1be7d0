// The INT8 GEMM family: C[M x N] = epilogue(A[M x K] x W[N x K]^T), the workhorse of the INT8
// path (convolutions as im2col/indirect GEMMs, transformer linears). kernels/gemm_s8/README.md has
// the math, the packed layout diagrams, the rounding rule and the over-read contract.
//
//   A  int8 activations, row-major, row stride lda; zero point z_a per tensor (folded into the
//      packed weights) or per row (GemmS8Args::a_row_zero_point, dynamic per-token quantization).
//   W  int8 weights [N x K] (PyTorch Linear / OHWI conv layout), symmetric per output channel,
//      values in [-127, 127], packed once at load by the packer paired with the kernel.
//   acc[m][n] = sum_k (A[m][k] - z_a) * W[n][k] + bias_i32[n]      (int32, wraps modulo 2^32)
//
// Three epilogues, all fused into the micro-kernel (see kernels/common/requant_ref.h):
//   s8 out   requantize with a per-channel float scale (times an optional per-row one, plus an
//            optional float bias), optional int8 residual, clamp, z_out;
//   f32 out  dequantize with s_a (per tensor or per row) * s_w[n], + f32 bias, optional f32
//            residual, optional ReLU;
//   s32 out  the raw accumulators (tests, and ops that need them).
//
// Threading: kernels never allocate or start threads. Each call computes one sub-rectangle
// [m0, m1) x [n0, n1) of C, so a caller splits the output by rows or columns across a pool.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/common/covered_paths.h"
#include "kernels/common/isa.h"

namespace act::kernels {

/// Bytes that a kernel may read past the end of each A row it reads (A[m][K-1]); the caller must
/// keep them addressable (XNNPACK's XNN_EXTRA_BYTES). Their values never change the result.
inline constexpr size_t kGemmS8ReadSlack = 16;
/// segment_k of a segmented A is a multiple of this (every variant's k-group divides it).
inline constexpr int kGemmS8SegmentAlign = 8;
/// Largest K the kernels accept: keeps every int32 sum exact (255 * 127 * K < 2^31).
inline constexpr int kGemmS8MaxK = 1 << 16;
/// Alignment of packed buffers and of every panel inside them.
inline constexpr size_t kGemmS8PackedAlign = 64;

/// The packed-weight layouts, one per packer (recorded in the buffer's header so that a kernel can
/// check it got its own packer's output).
enum class GemmS8Layout : uint32_t {
  kRef1x1 = 1,    ///< nr=1, kr=1: one column per panel, K bytes in order
  kAvx2_8x8 = 2,  ///< nr=8, kr=8: columns paired (j, j+4) for the vpmaddwd reduction
  kVnni64x4 = 3,  ///< nr=64, kr=4: 64 columns x 4 bytes per k-group, weights stored + 128 (u8)
  kNeon16x4 = 4,  ///< nr=16, kr=4: 16 columns x 4 bytes per k-group
  kVnni64x4U8A = 5,  ///< as kVnni64x4 with the weights as they are (s8), for unsigned activations
  kVnni16x4 = 6,  ///< nr=16, kr=4: kNeon16x4's order with the weights stored + 128 (u8), AVX-VNNI
  kAmx64x4 = 7,      ///< nr=64, kr=4, weights as they are, K padded to 64 (one AMX tile row per k-group)
  kAmx64x4U8A = 8,   ///< the same bytes, for unsigned activations (tdpbusd instead of tdpbssd)
};

inline constexpr uint32_t kGemmS8PackedMagic = 0x38534741u;  // "AGS8"

/// The first 64 bytes of every packed buffer. Panel p (columns [p*nr, p*nr + nr)) starts at
/// byte 64 + p * panel_bytes and holds int32 kbias[nr], int32 ksum[nr], then kp*nr weight bytes:
///   ksum[n]  = sum_k W[n][k]
///   kbias[n] = bias_i32[n] - a_zero_point * ksum[n]
/// Columns past N are zero everywhere, and so are the weight bytes of k in [K, kp). (kVnni64x4 and
/// kVnni16x4 store W XOR 0x80 = W + 128 as u8 for the real weights; their kernels subtract 128 * row
/// sums of A.)
struct GemmS8PackedHeader {
  uint32_t magic;
  GemmS8Layout layout;
  int32_t n, k;
  int32_t nr, kr, kp;    ///< panel width, k-group, K rounded up to kr
  int32_t a_zero_point;  ///< the per-tensor activation zero point folded into kbias
  int32_t reserved0[2];  ///< zero
  uint64_t panel_bytes;  ///< panel size, a multiple of 64
  uint8_t reserved[16];
};
static_assert(sizeof(GemmS8PackedHeader) == 64);

/// Operands shared by every epilogue. Pointers address whole matrices (row 0, column 0); a call
/// computes only the sub-rectangle it is given.
struct GemmS8Args {
  int m = 0, n = 0, k = 0;           ///< C is [m x n]; 1 <= k <= kGemmS8MaxK
  const int8_t* a = nullptr;         ///< A [m x k]
  size_t lda = 0;                    ///< elements between A rows, >= k
  /// Instead of a and lda, A's rows in segments of segment_k bytes (a convolution's kernel rows,
  /// read where they lie in the input): row i's segment s at a_segments[i * (k / segment_k) + s].
  /// segment_k is a multiple of kGemmS8SegmentAlign and divides k; no byte past a segment is read.
  const int8_t* const* a_segments = nullptr;
  int segment_k = 0;
  const void* packed_w = nullptr;    ///< W packed for [n x k] by this variant's packer
  /// Optional [m]: per-row activation zero points, used instead of the packed a_zero_point.
  const int32_t* a_row_zero_point = nullptr;
  /// Optional: the kernel records (its Isa, KernelPath bits) here.
  CoveredPaths* covered = nullptr;
};

/// s8 output: C[m][n] = requantize(acc, scale[n], ...), the rule of requant_ref.h.
/// ReLU is the clamp: use qmin = max(qmin, out_zero_point).
struct GemmS8OutS8 {
  int8_t* c = nullptr;
  size_t ldc = 0;                    ///< >= n
  const float* scale = nullptr;      ///< [n] s_a * s_w[n] / s_out (s_w[n] / s_out with a_row_scale); finite, > 0
  /// Optional [m]: per-row activation scales s_a (dynamic per-token input), multiplied into scale[n].
  const float* a_row_scale = nullptr;
  /// Optional [n]: a float bias in output units (bias / s_out), added after the scaling (the int32
  /// bias packed into the weights assumes one s_a for every row).
  const float* bias = nullptr;
  int32_t out_zero_point = 0;        ///< in [-128, 127]
  int32_t qmin = -128, qmax = 127;   ///< -128 <= qmin <= qmax <= 127
  const int8_t* residual = nullptr;  ///< optional [m x n] int8, row stride ldr (0: one row for all)
  size_t ldr = 0;
  int32_t residual_zero_point = 0;
  float residual_scale = 0.0f;       ///< s_residual / s_out; finite
};

/// f32 output: C[m][n] = float(acc) * (s_a * w_scale[n]) + bias[n] (+ residual) (ReLU).
struct GemmS8OutF32 {
  float* c = nullptr;
  size_t ldc = 0;                      ///< >= n
  const float* w_scale = nullptr;      ///< [n] per-channel weight scales
  float a_scale = 1.0f;                ///< per-tensor activation scale, used when a_row_scale is null
  const float* a_row_scale = nullptr;  ///< optional [m] per-row activation scales
  const float* bias = nullptr;         ///< optional [n]
  const float* residual = nullptr;     ///< optional [m x n], row stride ldr (0: one row for all)
  size_t ldr = 0;
  bool relu = false;
};

/// s32 output: the accumulators themselves.
struct GemmS8OutS32 {
  int32_t* c = nullptr;
  size_t ldc = 0;  ///< >= n
};

/// Bytes the packer writes for an [n x k] weight.
using GemmS8PackedSizeFn = size_t (*)(int n, int k);
/// Packs W [n x k] (row stride ldw) with an optional int32 bias [n] (scale s_a * s_w[n], zero point
/// 0) and the per-tensor activation zero point into `packed` (kGemmS8PackedAlign-aligned, the size
/// from the paired GemmS8PackedSizeFn). Pass a_zero_point = 0 when rows carry their own.
using GemmS8PackFn = void (*)(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                              void* packed);
using GemmS8S8OutFn = void (*)(const GemmS8Args& args, const GemmS8OutS8& out, int m0, int m1, int n0, int n1);
using GemmS8F32OutFn = void (*)(const GemmS8Args& args, const GemmS8OutF32& out, int m0, int m1, int n0, int n1);
using GemmS8S32OutFn = void (*)(const GemmS8Args& args, const GemmS8OutS32& out, int m0, int m1, int n0, int n1);

/// One variant: its kernels, the packer that matches them, and their tile. Sub-rectangles whose
/// n0 is a multiple of nr (and m0 of mr) split the work without recomputing shared tiles.
struct GemmS8Kernels {
  Isa isa;
  GemmS8Layout layout;
  int mr, nr, kr;
  const char* pack_name;  ///< names follow <family>_<dtypes>_<tile>_<isa>
  const char* s8out_name;
  const char* f32out_name;
  const char* s32out_name;
  GemmS8PackedSizeFn packed_size;
  GemmS8PackFn pack;
  GemmS8PackFn pack_transposed;  ///< the same bytes as `pack`, from W^T [k x n] (w row stride ldw >= n)
  GemmS8S8OutFn s8out;
  GemmS8F32OutFn f32out;
  GemmS8S32OutFn s32out;
  /// Packs W (into packed_size(n, k) bytes, as pack) for activations stored unsigned: A's bytes are
  /// read as uint8 with a per-tensor zero point in [0, 255] (no per-row zero points), and the same
  /// kernels take them. Null where the ISA has no unsigned x signed product (AVX2 and NEON SDOT:
  /// their kernels' A is signed).
  const char* pack_u8a_name = nullptr;
  GemmS8PackFn pack_u8a = nullptr;
};

}  // namespace act::kernels
