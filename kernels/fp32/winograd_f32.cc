#include "kernels/fp32/winograd_f32.h"

#include <algorithm>
#include <vector>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {
constexpr int kChannelQuantum = 16;

size_t point_floats(const Conv2dShape& s) {
  return static_cast<size_t>(kWinogradBlockTiles) * static_cast<size_t>(std::max(s.in_c, s.out_c));
}
}  // namespace

bool winograd_f32_applies(const Conv2dShape& s, GemmF32Activation activation) {
  return s.kernel_h == 3 && s.kernel_w == 3 && s.stride == 1 && s.pad == 1 && s.dilation == 1 &&
         s.in_c % kChannelQuantum == 0 && s.out_c % kChannelQuantum == 0 && activation != GemmF32Activation::kGelu;
}

int winograd_f32_tiles(const Conv2dShape& s) { return ((s.out_h + 1) / 2) * ((s.out_w + 1) / 2); }

size_t winograd_f32_packed_floats(int nr, const Conv2dShape& s) {
  return kWinogradPoints * gemm_f32_packed_floats(nr, s.out_c, s.in_c);
}

void winograd_f32_pack(int nr, const Conv2dShape& s, const float* w, float* packed) {
  // U = G g G^T per (out, in) channel pair, G = [1 0 0; 1/2 1/2 1/2; 1/2 -1/2 1/2; 0 0 1].
  static constexpr double kG[4][3] = {{1, 0, 0}, {0.5, 0.5, 0.5}, {0.5, -0.5, 0.5}, {0, 0, 1}};
  const size_t n = static_cast<size_t>(s.out_c), k = static_cast<size_t>(s.in_c);
  std::vector<float> u(kWinogradPoints * n * k);  // [point][out][in]
  for (size_t o = 0; o < n; ++o) {
    for (size_t i = 0; i < k; ++i) {
      double g[3][3];
      for (int ky = 0; ky < 3; ++ky) {
        for (int kx = 0; kx < 3; ++kx) g[ky][kx] = w[((o * 3 + static_cast<size_t>(ky)) * 3 + static_cast<size_t>(kx)) * k + i];
      }
      for (int a = 0; a < 4; ++a) {
        for (int b = 0; b < 4; ++b) {
          double sum = 0.0;
          for (int ky = 0; ky < 3; ++ky) {
            for (int kx = 0; kx < 3; ++kx) sum += kG[a][ky] * g[ky][kx] * kG[b][kx];
          }
          u[(static_cast<size_t>(4 * a + b) * n + o) * k + i] = static_cast<float>(sum);
        }
      }
    }
  }
  const size_t per_point = gemm_f32_packed_floats(nr, s.out_c, s.in_c);
  for (int p = 0; p < kWinogradPoints; ++p) {
    gemm_f32_pack(nr, s.out_c, s.in_c, u.data() + static_cast<size_t>(p) * n * k, k, packed + static_cast<size_t>(p) * per_point);
  }
}

size_t winograd_f32_scratch_floats(const Conv2dShape& s) { return 2 * kWinogradPoints * point_floats(s); }

void winograd_f32(const GemmF32Kernels& kernels, const Conv2dShape& s, const float* packed_weights, const float* x,
                  float* y, const GemmF32Epilogue& epilogue, int tile_begin, int count, float* scratch) {
  ACT_CHECK(winograd_f32_applies(s, epilogue.activation), "winograd_f32: not a 3x3/1 conv of 16-channel multiples");
  const size_t ld_point = point_floats(s);
  float* v = scratch;
  float* m = scratch + kWinogradPoints * ld_point;
  const size_t per_point = gemm_f32_packed_floats(kernels.nr, s.out_c, s.in_c);
  for (int t0 = tile_begin; t0 < tile_begin + count; t0 += kWinogradBlockTiles) {
    const int tiles = std::min(kWinogradBlockTiles, tile_begin + count - t0);
    kernels.winograd_input({.shape = &s, .x = x, .tile_begin = t0, .count = tiles, .v = v, .ld_point = ld_point});
    for (int p = 0; p < kWinogradPoints; ++p) {
      kernels.packed({.m = tiles, .n = s.out_c, .k = s.in_c, .a = v + static_cast<size_t>(p) * ld_point,
                      .lda = static_cast<size_t>(s.in_c), .packed_b = packed_weights + static_cast<size_t>(p) * per_point,
                      .c = m + static_cast<size_t>(p) * ld_point, .ldc = static_cast<size_t>(s.out_c), .epilogue = {}});
    }
    kernels.winograd_output({.shape = &s, .m = m, .ld_point = ld_point, .tile_begin = t0, .count = tiles, .y = y,
                             .epilogue = epilogue});
  }
}

}  // namespace act::kernels
