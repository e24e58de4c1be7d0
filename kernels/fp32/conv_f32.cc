#include "kernels/fp32/conv_f32.h"

#include <algorithm>

#include "kernels/common/im2col.h"

namespace act::kernels {

namespace {
constexpr int kTileQuantum = 24;  // lcm of the gemm_f32 MRs (1, 6, 8)
constexpr size_t kTargetScratchBytes = 256 * 1024;
}  // namespace

int conv_f32_tile_pixels(const Conv2dShape& s) {
  const size_t per_pixel = static_cast<size_t>(s.patch_size()) * sizeof(float);
  const int fit = static_cast<int>(kTargetScratchBytes / per_pixel) / kTileQuantum * kTileQuantum;
  return std::clamp(fit, kTileQuantum, 8 * kTileQuantum);  // at most 192 pixels, as the int8 conv's tiles
}

size_t conv_f32_scratch_floats(const Conv2dShape& s, int tile_pixels) {
  return s.reads_input_in_place() ? 0 : static_cast<size_t>(tile_pixels) * static_cast<size_t>(s.patch_size());
}

void conv_f32(const ConvF32& conv, const float* input, float* y, const GemmF32Epilogue& epilogue, int pixel_begin,
              int count, float* scratch) {
  const Conv2dShape& s = conv.shape;
  GemmF32PackedArgs args;
  args.m = count;
  args.n = s.out_c;
  args.k = s.patch_size();
  if (s.reads_input_in_place()) {
    args.a = input + static_cast<size_t>(pixel_begin) * s.in_c;
  } else {
    im2col_nhwc_f32(s, input, pixel_begin, count, scratch);
    args.a = scratch;
  }
  args.lda = static_cast<size_t>(args.k);
  args.packed_b = conv.packed_w;
  args.c = y + static_cast<size_t>(pixel_begin) * static_cast<size_t>(s.out_c);
  args.ldc = static_cast<size_t>(s.out_c);
  args.epilogue = epilogue;
  if (epilogue.residual != nullptr) args.epilogue.residual += static_cast<size_t>(pixel_begin) * epilogue.residual_ld;
  conv.kernels->packed(args);
}

}  // namespace act::kernels
