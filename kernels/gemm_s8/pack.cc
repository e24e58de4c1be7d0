// The portable weight packers of every gemm_s8 layout, the definition of each layout's bytes. One
// generic routine; each named packer fixes the layout (panel width nr, k-group kr, column order,
// weight shift). Plain C++ on every architecture: it runs once at load for the weights. The AVX-512
// VNNI and AVX-VNNI variants pack with SIMD packers of the same bytes (gemm_s8_avx512vnni.cc,
// gemm_s8_avxvnni.cc), since attention packs its keys and values at every run.
#include <algorithm>
#include <cstring>

#include "kernels/common/check.h"
#include "kernels/gemm_s8/gemm_s8_variants.h"

namespace act::kernels {

namespace {

struct LayoutDesc {
  GemmS8Layout layout;
  int nr, kr;
  bool pair4;      // AVX2: store columns 0,4,1,5,2,6,3,7 inside each k-group
  bool w_plus128;  // VNNI: store W XOR 0x80 (W + 128 as u8) for the unsigned side of vpdpbusd
  int k_align;     // K padded with zero weights to a multiple of this (kr, or a tile's 64 bytes)
};

constexpr LayoutDesc kLayouts[] = {
    {GemmS8Layout::kRef1x1, 1, 1, false, false, 1},
    {GemmS8Layout::kAvx2_8x8, 8, 8, true, false, 8},
    {GemmS8Layout::kVnni64x4, 64, 4, false, true, 4},
    {GemmS8Layout::kNeon16x4, 16, 4, false, false, 4},
    {GemmS8Layout::kVnni64x4U8A, 64, 4, false, false, 4},
    {GemmS8Layout::kVnni16x4, 16, 4, false, true, 4},
    {GemmS8Layout::kAmx64x4, 64, 4, false, false, 64},
    {GemmS8Layout::kAmx64x4U8A, 64, 4, false, false, 64},
};

const LayoutDesc& desc_of(GemmS8Layout layout) {
  for (const LayoutDesc& d : kLayouts) {
    if (d.layout == layout) return d;
  }
  ACT_CHECK(false, "unknown gemm_s8 layout");
  return kLayouts[0];
}

constexpr int kMaxNr = 64;

size_t round_up(size_t x, size_t to) { return (x + to - 1) / to * to; }

size_t panel_bytes(const LayoutDesc& d, int k) {
  const size_t kp = round_up(static_cast<size_t>(k), static_cast<size_t>(d.k_align));
  return round_up(8 * static_cast<size_t>(d.nr) + kp * static_cast<size_t>(d.nr), kGemmS8PackedAlign);
}

// One column's k-groups: column `slot` of group g sits at group_base[g * nr * kr]. KR is a constant
// so that each whole group is a fixed-length copy the compiler turns into word moves (attention
// packs its keys and values at every run); returns the column's sum of weights.
template <int KR>
int64_t pack_column(const LayoutDesc& d, int k, const int8_t* wrow, int8_t* group_base) {
  const auto flip = static_cast<int8_t>(d.w_plus128 ? 0x80 : 0);
  const size_t group_stride = static_cast<size_t>(d.nr) * KR;
  int64_t sum = 0;
  int8_t* group = group_base;
  int k0 = 0;
  for (; k0 + KR <= k; k0 += KR, group += group_stride) {
    int32_t group_sum = 0;
    for (int r = 0; r < KR; ++r) {
      const int8_t wv = wrow[k0 + r];
      ACT_DCHECK(wv != -128, "gemm_s8 weights must lie in [-127, 127]");
      group_sum += wv;
      group[r] = static_cast<int8_t>(wv ^ flip);  // VNNI: W + 128 as u8
    }
    sum += group_sum;
  }
  // The ragged last group; its padding (k >= K, like columns past N) stays 0 in every layout, so
  // over-read A bytes meet 0.
  for (int r = 0; k0 + r < k; ++r) {
    const int8_t wv = wrow[k0 + r];
    ACT_DCHECK(wv != -128, "gemm_s8 weights must lie in [-127, 127]");
    sum += wv;
    group[r] = static_cast<int8_t>(wv ^ flip);
  }
  return sum;
}

// The same for W^T [k x n] (row stride ldw): the `cols` columns of one panel, k-group by k-group,
// the group's KR rows of W^T read in order (contiguous, where a column of W^T would be a strided
// walk) and interleaved into the group; column sums accumulate in `sums`. Interleave and sums are
// separate plain loops over columns, which GCC vectorizes.
template <int KR, bool PAIR4>
void pack_panel_transposed(const LayoutDesc& d, int k, int cols, const int8_t* wt, size_t ldw, int8_t* data,
                           int32_t* sums) {
  const auto flip = static_cast<int8_t>(d.w_plus128 ? 0x80 : 0);
  const size_t group_stride = static_cast<size_t>(d.nr) * KR;
  const auto slot = [](int c) { return PAIR4 ? 2 * (c % 4) + c / 4 : c; };
  int k0 = 0;
  for (; k0 + KR <= k; k0 += KR) {
    int8_t* group = data + static_cast<size_t>(k0 / KR) * group_stride;
    const int8_t* src = wt + static_cast<size_t>(k0) * ldw;
    // PAIR4: interleaved in column order first (the loop GCC vectorizes), then each column's KR
    // bytes moved to its slot as one word.
    int8_t staged[kMaxNr * KR];
    int8_t* interleaved = PAIR4 ? staged : group;
    for (int c = 0; c < cols; ++c) {
      for (int r = 0; r < KR; ++r) {
        const int8_t wv = src[static_cast<size_t>(r) * ldw + static_cast<size_t>(c)];
        ACT_DCHECK(wv != -128, "gemm_s8 weights must lie in [-127, 127]");
        interleaved[c * KR + r] = static_cast<int8_t>(wv ^ flip);
      }
    }
    if constexpr (PAIR4) {
      for (int c = 0; c < cols; ++c) std::memcpy(group + slot(c) * KR, staged + c * KR, KR);
    }
    for (int r = 0; r < KR; ++r) {
      const int8_t* row = src + static_cast<size_t>(r) * ldw;
      for (int c = 0; c < cols; ++c) sums[c] += row[c];
    }
  }
  // The ragged last group; its padding stays 0.
  int8_t* group = data + static_cast<size_t>(k0 / KR) * group_stride;
  for (int r = 0; k0 + r < k; ++r) {
    const int8_t* row = wt + static_cast<size_t>(k0 + r) * ldw;
    for (int c = 0; c < cols; ++c) {
      ACT_DCHECK(row[c] != -128, "gemm_s8 weights must lie in [-127, 127]");
      sums[c] += row[c];
      group[slot(c) * KR + r] = static_cast<int8_t>(row[c] ^ flip);
    }
  }
}

template <int KR, bool TRANSPOSED = false>
void pack_generic(const LayoutDesc& d, int n, int k, const int8_t* w, size_t ldw, const int32_t* bias,
                  int32_t a_zero_point, void* packed) {
  ACT_DCHECK(n >= 1 && k >= 1 && k <= kGemmS8MaxK && ldw >= static_cast<size_t>(TRANSPOSED ? n : k),
             "bad weight shape");
  ACT_DCHECK(reinterpret_cast<uintptr_t>(packed) % kGemmS8PackedAlign == 0, "packed buffer must be 64-byte aligned");
  ACT_DCHECK(d.kr == KR, "layout and packer disagree on the k-group");
  ACT_DCHECK(d.nr <= kMaxNr, "panel wider than the column sums kept per panel");
  const GemmS8PackedHeader h = gemm_s8_packed_header(d.layout, n, k, a_zero_point);
  const size_t pbytes = h.panel_bytes;
  const int panels = (n + d.nr - 1) / d.nr;

  auto* base = static_cast<uint8_t*>(packed);
  std::memset(base, 0, sizeof(GemmS8PackedHeader) + static_cast<size_t>(panels) * pbytes);
  std::memcpy(base, &h, sizeof h);

  for (int p = 0; p < panels; ++p) {
    uint8_t* panel = base + sizeof(GemmS8PackedHeader) + static_cast<size_t>(p) * pbytes;
    auto* data = reinterpret_cast<int8_t*>(panel + 8 * static_cast<size_t>(d.nr));
    const int cols = std::min(d.nr, n - p * d.nr);  // columns past N stay zero
    // Column sums fit int32: |sum| <= 127 * kGemmS8MaxK.
    int32_t sums[kMaxNr] = {};
    if constexpr (TRANSPOSED) {
      const int8_t* wt = w + static_cast<size_t>(p) * static_cast<size_t>(d.nr);
      if (d.pair4) {
        pack_panel_transposed<KR, true>(d, k, cols, wt, ldw, data, sums);
      } else {
        pack_panel_transposed<KR, false>(d, k, cols, wt, ldw, data, sums);
      }
    } else {
      for (int c = 0; c < cols; ++c) {
        const int slot = d.pair4 ? 2 * (c % 4) + c / 4 : c;
        const int8_t* wrow = w + static_cast<size_t>(p * d.nr + c) * ldw;
        sums[c] = static_cast<int32_t>(pack_column<KR>(d, k, wrow, data + static_cast<size_t>(slot) * KR));
      }
    }
    for (int c = 0; c < cols; ++c) {
      const int col = p * d.nr + c;
      // kbias wraps modulo 2^32 like the kernels' int32 arithmetic (C++20 conversion is modular).
      const int64_t kbias = (bias != nullptr ? bias[col] : 0) - int64_t{a_zero_point} * sums[c];
      const auto kbias32 = static_cast<int32_t>(kbias);
      std::memcpy(panel + 4 * static_cast<size_t>(c), &kbias32, 4);
      std::memcpy(panel + 4 * static_cast<size_t>(d.nr + c), &sums[c], 4);
    }
  }
}

}  // namespace

GemmS8PackedHeader gemm_s8_packed_header(GemmS8Layout layout, int n, int k, int32_t a_zero_point) {
  const LayoutDesc& d = desc_of(layout);
  GemmS8PackedHeader h{};
  h.magic = kGemmS8PackedMagic;
  h.layout = d.layout;
  h.n = n;
  h.k = k;
  h.nr = d.nr;
  h.kr = d.kr;
  h.kp = static_cast<int32_t>(round_up(static_cast<size_t>(k), static_cast<size_t>(d.k_align)));
  h.a_zero_point = a_zero_point;
  h.panel_bytes = panel_bytes(d, k);
  return h;
}

size_t gemm_s8_packed_size(GemmS8Layout layout, int n, int k) {
  const LayoutDesc& d = desc_of(layout);
  const size_t panels = (static_cast<size_t>(n) + static_cast<size_t>(d.nr) - 1) / static_cast<size_t>(d.nr);
  return sizeof(GemmS8PackedHeader) + panels * panel_bytes(d, k);
}

void pack_w_s8_1x1_goi(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                       void* packed) {
  pack_generic<1>(desc_of(GemmS8Layout::kRef1x1), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_8x8_goi_pair4(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed) {
  pack_generic<8>(desc_of(GemmS8Layout::kAvx2_8x8), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_64x4_goi_x80(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kVnni64x4), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_64x4_goi_u8a(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kVnni64x4U8A), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_64x4_goi_k64(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kAmx64x4), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_64x4_goi_k64_u8a(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                                void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kAmx64x4U8A), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_16x4_goi(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                        void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kNeon16x4), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_w_s8_16x4_goi_x80(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                            void* packed) {
  pack_generic<4>(desc_of(GemmS8Layout::kVnni16x4), n, k, w, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_1x1_goi(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                        void* packed) {
  pack_generic<1, true>(desc_of(GemmS8Layout::kRef1x1), n, k, wt, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_8x8_goi_pair4(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                              void* packed) {
  pack_generic<8, true>(desc_of(GemmS8Layout::kAvx2_8x8), n, k, wt, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_64x4_goi_x80(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed) {
  pack_generic<4, true>(desc_of(GemmS8Layout::kVnni64x4), n, k, wt, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_64x4_goi_k64(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed) {
  pack_generic<4, true>(desc_of(GemmS8Layout::kAmx64x4), n, k, wt, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_16x4_goi(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                         void* packed) {
  pack_generic<4, true>(desc_of(GemmS8Layout::kNeon16x4), n, k, wt, ldw, bias, a_zero_point, packed);
}

void pack_wt_s8_16x4_goi_x80(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                             void* packed) {
  pack_generic<4, true>(desc_of(GemmS8Layout::kVnni16x4), n, k, wt, ldw, bias, a_zero_point, packed);
}

}  // namespace act::kernels
