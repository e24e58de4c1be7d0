#include "kernels/fp32/conv_f32.h"

#include <algorithm>

#include "kernels/common/im2col.h"

namespace act::kernels {

namespace {
constexpr int kTileQuantum = kConvF32TileQuantum;
constexpr size_t kTargetScratchBytes = 256 * 1024;

// Kernel rows read in place (the GEMM's a_segments) instead of im2col: at 64 output channels (the
// stem, layer1) copying patches cost a quarter of the convolution, and every ResNet conv measured
// faster without it. A kernel row of kernel_w * in_c floats is contiguous in NHWC when the dilation
// is 1; rows shorter than 8 floats are gathered.
bool reads_kernel_rows_in_place(const Conv2dShape& s) {
  return !s.reads_input_in_place() && s.dilation == 1 && s.kernel_w * s.in_c >= 8;
}

}  // namespace

int conv_f32_tile_pixels(const Conv2dShape& s) {
  constexpr int kMaxTile = 8 * kTileQuantum;  // 192 pixels, as the int8 conv's tiles
  // No patch buffer to keep in L2: the largest tiles, so that the weights stream past as few as
  // possible (layer4's 9.4 MB went past 13 tiles of 24 pixels, from L3 for every 4 row tiles).
  if (reads_kernel_rows_in_place(s) || s.reads_input_in_place()) return kMaxTile;
  const size_t per_pixel = static_cast<size_t>(s.patch_size()) * sizeof(float);
  const int fit = static_cast<int>(kTargetScratchBytes / per_pixel) / kTileQuantum * kTileQuantum;
  return std::clamp(fit, kTileQuantum, kMaxTile);
}

size_t conv_f32_scratch_floats(const Conv2dShape& s, int tile_pixels) {
  if (reads_kernel_rows_in_place(s)) return kernel_row_scratch_elements<float>(s, tile_pixels);
  return s.reads_input_in_place() ? 0 : static_cast<size_t>(tile_pixels) * static_cast<size_t>(s.patch_size());
}

void conv_f32(const ConvF32& conv, const float* input, float* y, const GemmF32Epilogue& epilogue, int pixel_begin,
              int count, float* scratch, int out_pixel0) {
  const Conv2dShape& s = conv.shape;
  GemmF32PackedArgs args;
  args.m = count;
  args.n = s.out_c;
  args.k = s.patch_size();
  args.lda = static_cast<size_t>(args.k);
  if (reads_kernel_rows_in_place(s)) {
    // The pointers after the row copies, in the same (suitably aligned) scratch.
    auto** rows = reinterpret_cast<const float**>(scratch + kernel_row_pointers_offset<float>(s, count));
    point_at_kernel_rows(s, input, 0.0f, pixel_begin, count, scratch, rows);
    args.a_segments = rows;
    args.segment_k = static_cast<int>(kernel_row_elements(s));
  } else if (s.reads_input_in_place()) {
    args.a = input + static_cast<size_t>(pixel_begin) * s.in_c;
  } else {
    im2col_nhwc_f32(s, input, pixel_begin, count, scratch);
    args.a = scratch;
  }
  args.packed_b = conv.packed_w;
  const size_t band_pixel = static_cast<size_t>(pixel_begin - out_pixel0);
  args.c = y + band_pixel * static_cast<size_t>(s.out_c);
  args.ldc = static_cast<size_t>(s.out_c);
  args.epilogue = epilogue;
  if (epilogue.residual != nullptr) args.epilogue.residual += band_pixel * epilogue.residual_ld;
  conv.kernels->packed(args);
}

}  // namespace act::kernels
