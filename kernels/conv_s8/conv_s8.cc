#include "kernels/conv_s8/conv_s8.h"

#include <algorithm>

#include "kernels/common/im2col.h"

namespace act::kernels {

namespace {

constexpr int kTileQuantum = kConvS8TileQuantum;
constexpr size_t kTargetScratchBytes = 256 * 1024;

// Kernel rows read in place (the GEMM's a_segments) instead of im2col when each is a whole number
// of every variant's k-groups: copying patches cost layer1's 3x3 convs (64 channels, K 576) about
// an eighth of their time, all of it in the stores. The stem's rows (7 taps x 3 channels) are
// gathered.
bool reads_kernel_rows_in_place(const Conv2dShape& s) {
  return !s.reads_input_in_place() && s.dilation == 1 &&
         kernel_row_elements(s) % static_cast<size_t>(kGemmS8SegmentAlign) == 0;
}

// The A operand of a tile: kernel rows in place, patches in scratch, or the input itself.
GemmS8Args tile_args(const ConvS8& conv, const int8_t* input, int pixel_begin, int count, int8_t* scratch) {
  const Conv2dShape& s = conv.shape;
  GemmS8Args args;
  args.m = count;
  args.n = s.out_c;
  args.k = s.patch_size();
  args.packed_w = conv.packed_w;
  if (conv.direct()) {
    args.a = input + static_cast<size_t>(pixel_begin) * s.in_c;
    args.lda = static_cast<size_t>(s.in_c);
  } else if (reads_kernel_rows_in_place(s)) {
    auto** rows = reinterpret_cast<const int8_t**>(scratch + kernel_row_pointers_offset<int8_t>(s, count));
    point_at_kernel_rows(s, input, conv.input_zero_point, pixel_begin, count, scratch, rows);
    args.a_segments = rows;
    args.segment_k = static_cast<int>(kernel_row_elements(s));
  } else {
    args.lda = static_cast<size_t>(args.k);
    im2col_nhwc_s8(s, input, conv.input_zero_point, pixel_begin, count, scratch, args.lda);
    args.a = scratch;
  }
  return args;
}

}  // namespace

int conv_s8_tile_pixels(const Conv2dShape& s) {
  const size_t per_pixel = static_cast<size_t>(s.patch_size());
  const int fit = static_cast<int>(kTargetScratchBytes / per_pixel) / kTileQuantum * kTileQuantum;
  return std::clamp(fit, kTileQuantum, 16 * kTileQuantum);
}

size_t conv_s8_scratch_bytes(const Conv2dShape& s, int tile_pixels) {
  const ConvS8 probe{s, nullptr, nullptr, 0};
  if (probe.direct()) return 0;
  if (reads_kernel_rows_in_place(s)) return kernel_row_scratch_elements<int8_t>(s, tile_pixels);
  return static_cast<size_t>(tile_pixels) * static_cast<size_t>(s.patch_size()) + kGemmS8ReadSlack;
}

void conv_s8_s8out(const ConvS8& conv, const int8_t* input, const GemmS8OutS8& out, int pixel_begin, int count,
                   int8_t* scratch, ConvChannels channels, int out_pixel0) {
  const GemmS8Args args = tile_args(conv, input, pixel_begin, count, scratch);
  GemmS8OutS8 tile = out;
  const size_t out_pixel = static_cast<size_t>(pixel_begin - out_pixel0);
  tile.c = out.c + out_pixel * out.ldc;
  if (out.residual) tile.residual = out.residual + out_pixel * out.ldr;
  conv.kernels->s8out(args, tile, 0, count, channels.begin, channels.end < 0 ? args.n : channels.end);
}

void conv_s8_f32out(const ConvS8& conv, const int8_t* input, const GemmS8OutF32& out, int pixel_begin, int count,
                    int8_t* scratch, ConvChannels channels) {
  const GemmS8Args args = tile_args(conv, input, pixel_begin, count, scratch);
  GemmS8OutF32 tile = out;
  tile.c = out.c + static_cast<size_t>(pixel_begin) * out.ldc;
  if (out.residual) tile.residual = out.residual + static_cast<size_t>(pixel_begin) * out.ldr;
  if (out.a_row_scale) tile.a_row_scale = out.a_row_scale + pixel_begin;
  conv.kernels->f32out(args, tile, 0, count, channels.begin, channels.end < 0 ? args.n : channels.end);
}

}  // namespace act::kernels
