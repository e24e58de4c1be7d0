#include "kernels/common/im2col.h"

#include <algorithm>
#include <cstring>

namespace act::kernels {

namespace {

// memcpy for the short runs of im2col (21 bytes for the 7x7 stem's kernel row, 64-576 for the
// others), inline: 16-byte moves, the last one ending exactly at `bytes` (overlapping the one before)
// so nothing outside either run is touched. The library call costs more than the copy at these sizes.
inline void copy_run(int8_t* dst, const int8_t* src, size_t bytes) {
  if (bytes < 16) {
    std::memcpy(dst, src, bytes);
    return;
  }
  size_t i = 0;
  for (; i + 16 < bytes; i += 16) std::memcpy(dst + i, src + i, 16);
  std::memcpy(dst + bytes - 16, src + bytes - 16, 16);
}

// Kernel rows at least this long (a cache line) are copied pixel by pixel (see im2col_nhwc_s8).
constexpr size_t kWholeLineRun = 64;

// Rounding divisions for a positive divisor and any sign of numerator.
inline int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
inline int ceil_div(int a, int b) { return -floor_div(-a, b); }

}  // namespace

void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches) {
  const size_t patch = static_cast<size_t>(s.patch_size());
  const size_t run = static_cast<size_t>(s.in_c);
  for (int i = 0; i < count; ++i) {
    const int pixel = pixel_begin + i;
    const int oy = pixel / s.out_w;
    const int ox = pixel % s.out_w;
    float* dst = patches + static_cast<size_t>(i) * patch;
    const int ix0 = ox * s.stride - s.pad;
    for (int ky = 0; ky < s.kernel_h; ++ky) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      if (s.dilation == 1) {
        // Undilated taps of one kernel row are adjacent input pixels: one copy for those inside the
        // image (the stem's 7 taps of 3 channels in one go), zeros either side.
        const bool row_inside = iy >= 0 && iy < s.in_h;
        copy_kernel_row_padded(s, row_inside ? input + static_cast<size_t>(iy) * s.in_w * run : nullptr, ix0, 0.0f, dst);
        dst += static_cast<size_t>(s.kernel_w) * run;
        continue;
      }
      for (int kx = 0; kx < s.kernel_w; ++kx, dst += run) {
        const int ix = ix0 + kx * s.dilation;
        if (iy < 0 || iy >= s.in_h || ix < 0 || ix >= s.in_w) {
          std::memset(dst, 0, run * sizeof(float));
        } else {
          std::memcpy(dst, input + (static_cast<size_t>(iy) * s.in_w + ix) * run, run * sizeof(float));
        }
      }
    }
  }
}

void im2col_nhwc_s8(const Conv2dShape& s, const int8_t* input, int8_t pad_value, int pixel_begin, int count,
                    int8_t* patches, size_t ld) {
  const size_t run = static_cast<size_t>(s.in_c);
  const size_t kernel_row_bytes = run * static_cast<size_t>(s.kernel_w);
  const size_t input_row_bytes = static_cast<size_t>(s.in_w) * run;
  // One output row at a time. Without dilation a kernel row inside the image is kernel_w consecutive
  // NHWC pixels, so the pixels whose kernel rows are all inside horizontally take one copy per kernel
  // row (the 7x7 stem with 3 channels would otherwise copy 3 bytes at a time); only the pixels at the
  // image's left and right edges go tap by tap. The order of those copies was measured (one thread,
  // act_kernel_bench): short kernel rows (the stem's 21 bytes) go kernel row by kernel row, a tight
  // loop stepping the source by stride * C (conv1 67 % of the vpdpbusd peak, 61 % pixel by pixel);
  // kernel rows of whole cache lines (layer1's 192 bytes) go pixel by pixel, each patch row written
  // front to back (layer1's 3x3 about 82 %, 80 % the other way).
  int8_t* tile_row = patches;
  for (int pixel = pixel_begin; pixel < pixel_begin + count;) {
    const int oy = pixel / s.out_w;
    const int ox_begin = pixel % s.out_w;
    const int n = std::min(s.out_w - ox_begin, pixel_begin + count - pixel);
    int inside_begin = n, inside_end = n;
    if (s.dilation == 1) {
      const int first = ceil_div(s.pad - ox_begin * s.stride, s.stride);  // ix0 >= 0
      const int last = floor_div(s.in_w - s.kernel_w + s.pad - ox_begin * s.stride, s.stride);  // ix0 + kw <= in_w
      inside_begin = std::clamp(first, 0, n);
      inside_end = std::clamp(last + 1, inside_begin, n);
    }
    // Kernel row ky of the pixels [j_begin, j_end) inside horizontally.
    const auto kernel_rows = [&](int ky, int j_begin, int j_end) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      int8_t* d = tile_row + static_cast<size_t>(j_begin) * ld + static_cast<size_t>(ky) * kernel_row_bytes;
      if (iy < 0 || iy >= s.in_h) {
        for (int j = j_begin; j < j_end; ++j, d += ld) std::memset(d, pad_value, kernel_row_bytes);
        return;
      }
      const size_t src_step = static_cast<size_t>(s.stride) * run;
      const int8_t* src = input + static_cast<size_t>(iy) * input_row_bytes +
                          static_cast<size_t>((ox_begin + j_begin) * s.stride - s.pad) * run;
      for (int j = j_begin; j < j_end; ++j, src += src_step, d += ld) copy_run(d, src, kernel_row_bytes);
    };
    if (kernel_row_bytes < kWholeLineRun) {
      for (int ky = 0; ky < s.kernel_h && inside_begin < inside_end; ++ky) kernel_rows(ky, inside_begin, inside_end);
    } else {
      for (int j = inside_begin; j < inside_end; ++j) {
        for (int ky = 0; ky < s.kernel_h; ++ky) kernel_rows(ky, j, j + 1);
      }
    }
    for (int ky = 0; ky < s.kernel_h; ++ky) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      const bool row_inside = iy >= 0 && iy < s.in_h;
      const int8_t* input_row = row_inside ? input + static_cast<size_t>(iy) * input_row_bytes : nullptr;
      const auto taps = [&](int j_begin, int j_end) {
        for (int j = j_begin; j < j_end; ++j) {
          int8_t* d = tile_row + static_cast<size_t>(j) * ld + static_cast<size_t>(ky) * kernel_row_bytes;
          const int ix0 = (ox_begin + j) * s.stride - s.pad;
          if (s.dilation == 1) {  // in one run, not tap by tap (the stem's edge pixels: 3 bytes a call)
            copy_kernel_row_padded(s, input_row, ix0, pad_value, d);
            continue;
          }
          for (int kx = 0; kx < s.kernel_w; ++kx, d += run) {
            const int ix = ix0 + kx * s.dilation;
            if (!row_inside || ix < 0 || ix >= s.in_w) {
              std::memset(d, pad_value, run);
            } else {
              copy_run(d, input_row + static_cast<size_t>(ix) * run, run);
            }
          }
        }
      };
      taps(0, inside_begin);
      taps(inside_end, n);
    }
    pixel += n;
    tile_row += static_cast<size_t>(n) * ld;
  }
}

}  // namespace act::kernels
