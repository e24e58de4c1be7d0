// Tiled im2col for the convolutions, float and int8: the patches of a tile of output pixels,
// gathered into a small per-thread buffer that the GEMM reads as A (never a whole-image buffer).
// Patch order is (ky, kx, c), the OHWI weight order. Or, without copying, pointers at each pixel's
// kernel rows where they lie in the input (the GEMMs' segmented A).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "kernels/common/conv2d_shape.h"

namespace act::kernels {

/// Gathers the patches of output pixels [pixel_begin, pixel_begin + count) (row-major pixel index)
/// of an NHWC float input into `patches` [count x patch_size]; taps in the padding are 0.
void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches);

/// The same for an int8 input, row i at patches + i * ld (ld >= patch_size). Taps in the padding get
/// `pad_value` — the input's zero point, the int8 code of 0.0, so padding contributes exactly nothing.
void im2col_nhwc_s8(const Conv2dShape& s, const int8_t* input, int8_t pad_value, int pixel_begin, int count,
                    int8_t* patches, size_t ld);

/// Elements of one kernel row (a segment of the patch): kernel_w * in_c, contiguous in NHWC when
/// the dilation is 1.
inline size_t kernel_row_elements(const Conv2dShape& s) {
  return static_cast<size_t>(s.kernel_w) * static_cast<size_t>(s.in_c);
}

/// Scratch elements point_at_kernel_rows needs for `pixels` pixels: the padding row and at most one
/// padded copy per kernel row.
inline size_t kernel_row_copies_elements(const Conv2dShape& s, int pixels) {
  return kernel_row_elements(s) * (1 + static_cast<size_t>(pixels) * static_cast<size_t>(s.kernel_h));
}

/// Where the pointer array starts in a scratch of T that holds the copies first (64-byte aligned
/// after them), in elements of T.
template <class T>
size_t kernel_row_pointers_offset(const Conv2dShape& s, int pixels) {
  return (kernel_row_copies_elements(s, pixels) * sizeof(T) + 63) / 64 * 64 / sizeof(T);
}

/// Elements of T the in-place path needs for `pixels` pixels: the copies, then a pointer per
/// kernel row.
template <class T>
size_t kernel_row_scratch_elements(const Conv2dShape& s, int pixels) {
  const size_t pointers = static_cast<size_t>(pixels) * static_cast<size_t>(s.kernel_h);
  return kernel_row_pointers_offset<T>(s, pixels) + (pointers * sizeof(const T*) + sizeof(T) - 1) / sizeof(T);
}

/// Kernel row [ix0, ix0 + kernel_w) of one input row (undilated) into dst, kernel_row_elements
/// long: the taps inside the image in one copy, the rest `pad`; all `pad` when input_row is null (a
/// row above or below the image). The edge pixels' path of im2col and of point_at_kernel_rows.
template <class T>
void copy_kernel_row_padded(const Conv2dShape& s, const T* input_row, int ix0, T pad, T* dst) {
  const size_t c = static_cast<size_t>(s.in_c);
  const int kx0 = input_row != nullptr ? std::clamp(-ix0, 0, s.kernel_w) : s.kernel_w;
  const int kx1 = input_row != nullptr ? std::clamp(s.in_w - ix0, kx0, s.kernel_w) : s.kernel_w;
  std::fill(dst, dst + static_cast<size_t>(kx0) * c, pad);
  if (kx1 > kx0) {
    std::copy(input_row + static_cast<size_t>(ix0 + kx0) * c, input_row + static_cast<size_t>(ix0 + kx1) * c,
              dst + static_cast<size_t>(kx0) * c);
  }
  std::fill(dst + static_cast<size_t>(kx1) * c, dst + kernel_row_elements(s), pad);
}

/// point_at_kernel_rows for one pixel whose window crosses the image's edge (its top-left input
/// pixel at iy0, ix0): its kernel rows rows[0..kernel_h) point at `pad_row` (a row of `pad`), into
/// the input, or at a padded copy made at `copies` (which then moves past it).
template <class T>
void point_at_edge_window(const Conv2dShape& s, const T* input, T pad, const T* pad_row, int iy0, int ix0,
                          bool inside_x, T*& copies, const T** rows) {
  const size_t seg = kernel_row_elements(s), c = static_cast<size_t>(s.in_c);
  const size_t row_stride = static_cast<size_t>(s.in_w) * c;
  for (int ky = 0; ky < s.kernel_h; ++ky) {
    const int iy = iy0 + ky;
    if (iy < 0 || iy >= s.in_h) {
      rows[ky] = pad_row;
      continue;
    }
    const T* row = input + static_cast<size_t>(iy) * row_stride;
    if (inside_x) {
      rows[ky] = row + static_cast<size_t>(ix0) * c;
    } else {
      copy_kernel_row_padded(s, row, ix0, pad, copies);
      rows[ky] = copies;
      copies += seg;
    }
  }
}

/// Points rows[i * kernel_h + ky] at kernel row ky of output pixel pixel_begin + i (dilation 1):
/// in the input where the row lies inside it, else at a row of `pad` (above or below the image) or
/// at a copy with its padding (across the left or right edge), both in `scratch`
/// (kernel_row_copies_elements). The order of the patch: (ky, kx, c).
template <class T>
void point_at_kernel_rows(const Conv2dShape& s, const T* input, T pad, int pixel_begin, int count, T* scratch,
                          const T** rows) {
  const size_t seg = kernel_row_elements(s), c = static_cast<size_t>(s.in_c);
  const size_t row_stride = static_cast<size_t>(s.in_w) * c;
  const T* pad_row = scratch;
  std::fill(scratch, scratch + seg, pad);
  T* copies = scratch + seg;
  // The pixel's coordinates step along the tile (a division per pixel cost as much as the rest).
  int oy = pixel_begin / s.out_w, ox = pixel_begin % s.out_w;
  const size_t pixel_step = static_cast<size_t>(s.stride) * c;
  // The end of the output columns whose windows are inside the image horizontally (used only from
  // such a column, so the numerator is not negative).
  const int ox_inside_end = std::min(s.out_w, (s.in_w - s.kernel_w + s.pad) / s.stride + 1);
  for (int i = 0; i < count;) {
    const int ix0 = ox * s.stride - s.pad, iy0 = oy * s.stride - s.pad;
    const bool inside_x = ix0 >= 0 && ix0 + s.kernel_w <= s.in_w;
    int done = 1;  // pixels handled this step
    if (inside_x && iy0 >= 0 && iy0 + s.kernel_h <= s.in_h) {
      // The whole window inside the image (nearly every pixel): kernel rows a row stride apart, and
      // the next pixels of this output row, up to its right edge, one stride further each.
      done = std::min(count - i, ox_inside_end - ox);
      const T* first = input + static_cast<size_t>(iy0) * row_stride + static_cast<size_t>(ix0) * c;
      for (int j = 0; j < done; ++j, first += pixel_step, rows += s.kernel_h) {
        const T* row = first;
        for (int ky = 0; ky < s.kernel_h; ++ky, row += row_stride) rows[ky] = row;
      }
    } else {
      point_at_edge_window(s, input, pad, pad_row, iy0, ix0, inside_x, copies, rows);
      rows += s.kernel_h;
    }
    i += done;
    ox += done;
    if (ox == s.out_w) {
      ox = 0;
      ++oy;
    }
  }
}

}  // namespace act::kernels
