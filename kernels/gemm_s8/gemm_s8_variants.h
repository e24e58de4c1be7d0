// Every gemm_s8 packer and reference kernel by name, and the per-ISA tables (nullptr when that ISA's
// file compiled to nothing on this target), which hold each SIMD variant's kernels and their names
// (<family>_<dtypes>_<tile>_<isa>). An Engine runs the table its KernelConfig chose
// (kernels/config/kernel_config.h); tests and benchmarks use the tables directly.
//
// Common preconditions of every kernel below (checked with ACT_DCHECK):
//   - args.packed_w was written by the packer of the same table for [args.n x args.k];
//   - 1 <= args.k <= kGemmS8MaxK, args.lda >= args.k, ldc (and ldr) >= args.n;
//   - 0 <= m0 <= m1 <= args.m, 0 <= n0 <= n1 <= args.n (an empty rectangle does nothing);
//   - the kGemmS8ReadSlack bytes after the last element of every A row in [m0, m1) are readable;
//   - the output rectangle does not overlap A, the packed weights or the epilogue's inputs
//     (the residual may alias C only when it is the same element: ldr == ldc, same base);
//   - the default floating-point environment (round to nearest, no flush-to-zero).
// Only C[m0:m1, n0:n1] is written; per-column inputs are read only for columns in [n0, n1).
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/gemm_s8/gemm_s8.h"

namespace act::kernels {

// ---- packers (pack.cc, portable: packing runs once at load) ----------------------------------

/// Bytes of a packed buffer of `layout` for an [n x k] weight: a 64-byte header, then
/// ceil(n / nr) panels of round_up(8 * nr + round_up(k, kr) * nr, 64) bytes.
size_t gemm_s8_packed_size(GemmS8Layout layout, int n, int k);

/// The header every packer of `layout` writes first (a SIMD packer of the same bytes uses it too).
GemmS8PackedHeader gemm_s8_packed_header(GemmS8Layout layout, int n, int k, int32_t a_zero_point);

/// The packers, one per layout. Preconditions: 1 <= n, 1 <= k <= kGemmS8MaxK, ldw >= k, every
/// W value in [-127, 127], `packed` 64-byte aligned and gemm_s8_packed_size() bytes long. `bias`
/// (int32 [n], scale s_a * s_w[n]) may be null.
void pack_w_s8_1x1_goi(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                       void* packed);
/// nr=8, kr=8; within a k-group the 8 columns are stored in the order 0,4,1,5,2,6,3,7 so that the
/// AVX2 kernel's horizontal adds end in natural column order.
void pack_w_s8_8x8_goi_pair4(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed);
/// nr=64, kr=4; weights stored as W XOR 0x80 (W + 128, the unsigned side of vpdpbusd), padding 0.
void pack_w_s8_64x4_goi_x80(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed);
/// nr=16, kr=4 (NEON SDOT; AVX-VNNI for unsigned activations).
void pack_w_s8_16x4_goi(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                        void* packed);
/// VNNI for unsigned activations (GemmS8Kernels::pack_u8a): 64 columns x 4 bytes, W as it is.
void pack_w_s8_64x4_goi_u8a(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed);
/// nr=16, kr=4 in pack_w_s8_16x4_goi's order, weights stored as W XOR 0x80 (AVX-VNNI), padding 0.
void pack_w_s8_16x4_goi_x80(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed);
/// AMX: nr=64, kr=4, W as it is, K padded with zeros to a multiple of 64 (kp): each k-group's
/// 16-column quarter is one 64-byte row of an AMX weight tile. The _u8a twin writes the same bytes
/// under the unsigned-activation layout.
void pack_w_s8_64x4_goi_k64(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed);
void pack_w_s8_64x4_goi_k64_u8a(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                                void* packed);
/// The same six packers reading W^T: `wt` is [k x n] (row stride ldw >= n), W[j][i] = wt[i * ldw + j];
/// each writes the bytes its pack_w_ twin writes for W. Attention packs its values this way, straight
/// from their token-major int8 copy.
void pack_wt_s8_1x1_goi(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                        void* packed);
void pack_wt_s8_8x8_goi_pair4(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                              void* packed);
void pack_wt_s8_64x4_goi_x80(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed);
void pack_wt_s8_16x4_goi(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                         void* packed);
void pack_wt_s8_16x4_goi_x80(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed);
void pack_wt_s8_64x4_goi_k64(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed);

// ---- ref (gemm_s8_ref.cc): the normative scalar definition ----------------------------------

/// Scalar reference, s8 output (requant_ref.h). Packed by pack_w_s8_1x1_goi.
void gemm_s8s8_s8out_1x1c1_ref(const GemmS8Args& args, const GemmS8OutS8& out, int m0, int m1, int n0, int n1);
/// Scalar reference, f32 output. Packed by pack_w_s8_1x1_goi.
void gemm_s8s8_f32out_1x1c1_ref(const GemmS8Args& args, const GemmS8OutF32& out, int m0, int m1, int n0, int n1);
/// Scalar reference, int32 accumulators. Packed by pack_w_s8_1x1_goi.
void gemm_s8s8_s32out_1x1c1_ref(const GemmS8Args& args, const GemmS8OutS32& out, int m0, int m1, int n0, int n1);
const GemmS8Kernels* gemm_s8_table_ref();

// ---- AVX2 (gemm_s8_avx2.cc, x86-64 only; -mavx2 -mfma) --------------------------------------
// 2x8c8: A and W sign-extended to int16 and multiplied with vpmaddwd (exact; no vpmaddubsw
// saturation). Packed by pack_w_s8_8x8_goi_pair4. Needs cpu_supports(Isa::kAvx2).

/// The AVX2 table, or nullptr when not built.
const GemmS8Kernels* gemm_s8_table_avx2();

// ---- AVX-VNNI (gemm_s8_avxvnni.cc, x86-64 only; -mavx2 -mfma -mavxvnni) ----------------------
// 6x16c4 on ymm: the AVX-512 VNNI scheme with VEX vpdpbusd (W + 128 as u8 x A as s8, row sums).
// Packed by pack_w_s8_16x4_goi_x80; or by pack_w_s8_16x4_goi for A stored unsigned. Needs
// cpu_supports(Isa::kAvxVnni).

const GemmS8Kernels* gemm_s8_table_avxvnni();

// ---- AVX-512 VNNI (gemm_s8_avx512vnni.cc, x86-64 only; -mavx512f/bw/vl/vnni) ----------------
// 6x64c4: vpdpbusd on (W + 128) as u8 x A as s8; each row tile subtracts 128 * rowsum(A).
// Packed by pack_w_s8_64x4_goi_x80; or by pack_w_s8_64x4_goi_u8a for A stored unsigned, which the
// same kernels multiply as u8 x W as s8, without row sums. Needs cpu_supports(Isa::kAvx512Vnni).

const GemmS8Kernels* gemm_s8_table_avx512vnni();

// ---- AMX-INT8 (gemm_s8_amx.cc, x86-64 only; the avx512vnni flags + -mamx-tile -mamx-int8) ----
// 32x64c4: 2 x 2 tiles of tdpbssd (tdpbusd for A stored unsigned) per half panel, A read in place
// or copied into a K-padded stack buffer, the AVX-512 VNNI variant's epilogues. Packed by
// pack_w_s8_64x4_goi_k64 (or its _u8a twin). Needs cpu_supports(Isa::kAmx), which includes the
// OS's permission for the tile state.

const GemmS8Kernels* gemm_s8_table_amx();

// ---- NEON dot product (gemm_s8_neondot.cc, AArch64 only; -march=armv8.2-a+dotprod) -----------
// 4x16c4 SDOT micro-kernel (activations read in place, 4 k-groups per 16-byte load via
// vdotq_laneq_s32) plus a 1x16c4 kernel for the last M % 4 rows. Packed by pack_w_s8_16x4_goi.
// Needs cpu_supports(Isa::kNeonDot).

const GemmS8Kernels* gemm_s8_table_neondot();

}  // namespace act::kernels
