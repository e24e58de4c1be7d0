// INT8 NHWC convolution as gemm_s8 over tiles of output pixels: each call computes one tile, its A
// the input itself (1x1 stride 1), pointers at its kernel rows in the input (kGemmS8SegmentAlign-
// multiple rows), or its patches gathered into caller-provided scratch (the rest: the stem). The
// gemm_s8 epilogue does the rest: bias, per-channel requantization (or dequantization), residual,
// ReLU.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/common/conv2d_shape.h"
#include "kernels/gemm_s8/gemm_s8.h"

namespace act::kernels {

struct ConvS8 {
  Conv2dShape shape;
  const GemmS8Kernels* kernels = nullptr;
  /// OHWI weights [out_c x patch_size] packed by kernels->pack with the input zero point folded in.
  const void* packed_w = nullptr;
  /// Also the padding value. With weights packed by pack_u8a (input stored unsigned), the byte of
  /// the uint8 zero point.
  int8_t input_zero_point = 0;
  /// True when the conv reads its input in place (1x1, stride 1, no padding).
  bool direct() const { return shape.reads_input_in_place(); }
};

/// The lcm of every gemm_s8 variant's MR (1, 2, 4, 6): the largest tile (conv_s8_tile_pixels) is a
/// multiple of it, so it holds whole row tiles of any variant. The graph's unpooled convs start their
/// tiles on the variant's own MR instead (finer, so the threads' shares come out even); the fused
/// max-pool's bands still start on multiples of this.
inline constexpr int kConvS8TileQuantum = 12;
/// Output pixels per tile for this conv at most: a multiple of kConvS8TileQuantum that keeps the
/// patch buffer near 256 KB (L2-resident while the weights stream past it).
int conv_s8_tile_pixels(const Conv2dShape& s);
/// Bytes of scratch conv_s8_* needs for tiles of `tile_pixels` pixels (0 when direct), including
/// the kernels' read slack.
size_t conv_s8_scratch_bytes(const Conv2dShape& s, int tile_pixels);

/// A range of output channels [begin, end) (end < 0: to the last). Splitting channels lets several
/// threads share a conv with few output pixels (layer4: 300 at 480x640) without each streaming all
/// its weights; `begin` should be a multiple of the variant's NR (64 suits every variant).
struct ConvChannels {
  int begin = 0;
  int end = -1;
};

/// Output pixels [pixel_begin, pixel_begin + count), channels `channels`, s8 out. `out.c` and `out.residual` address
/// the whole output / residual ([out_h * out_w x out_c]) from pixel out_pixel0 on (a band of it held
/// elsewhere; 0: all of it). The input must be followed by kGemmS8ReadSlack addressable bytes.
void conv_s8_s8out(const ConvS8& conv, const int8_t* input, const GemmS8OutS8& out, int pixel_begin, int count,
                   int8_t* scratch, ConvChannels channels = {}, int out_pixel0 = 0);
/// The same with f32 out (dequantized, + bias, residual, ReLU; out.a_scale is the input's scale).
void conv_s8_f32out(const ConvS8& conv, const int8_t* input, const GemmS8OutF32& out, int pixel_begin, int count,
                    int8_t* scratch, ConvChannels channels = {});

}  // namespace act::kernels
