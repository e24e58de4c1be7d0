// gemm_s8 on AMX-INT8 (Sapphire Rapids and later Xeons): a 32 x 64 block of C per panel, computed
// by tile dot products, then the AVX-512 epilogues. Compiled with the avx512vnni flags plus
// -mamx-tile -mamx-int8 on x86-64 targets only; elsewhere this file is just the null table.
//
// One tdpbssd multiplies a 16 x 64 int8 tile of A by a 16 x 64 tile of W holding 16 k-groups of 4
// bytes for 16 columns, adding 16 x 16 int32 sums into a C tile: 16,384 MACs per instruction, signed
// by signed, so W is stored as it is (no +128 and no row sums as on AVX-512 VNNI). A stored
// unsigned (pack_u8a) takes tdpbusd instead.
//
// Tiles: C 0-3 (rows 0-15 / 16-31 x columns 0-15 / 16-31 of a half panel), A 4-5, W 6-7: a 2 x 2
// block per k-step of 64 bytes, 4 tile loads per 4 dot products. A 64-column panel is two halves;
// each half's C tiles go to a 32 x 64 int32 buffer, from which the epilogue reads a whole panel row.
//
// A: tiles load rows of 64 bytes at a stride. Rows of a plain A whose K is a multiple of 64 are read
// in place (only whole 16-row tiles: a tile never reads a row past m1); otherwise (segments, a
// ragged K, a row tail) the row block's A is first copied into a stack buffer, K padded to 64 with
// zeros, reused by every panel. K beyond kAChunk bytes is copied chunk by chunk for each half panel
// (slower, and never ACT's shapes: its largest K is 3 x 3 x 512 = 4608).
//
// The tile state is configured at the start of each row block and released at its end, so that
// nothing of AMX outlives a kernel call in the calling thread.
//
// Rules for ISA files (see README.md): only intrinsics and internal-linkage code here.
#include "kernels/gemm_s8/gemm_s8_variants.h"

#if defined(__x86_64__)

// See gemm_s8_avx512vnni.cc: GCC 12's _mm512_undefined_*() warnings, for the header only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cstring>
#include <type_traits>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {

constexpr int kMR = 32;
constexpr int kNR = 64;
constexpr int kKR = 4;
constexpr Isa kIsa = Isa::kAmx;
constexpr GemmS8Layout kLayout = GemmS8Layout::kAmx64x4;
constexpr GemmS8Layout kLayoutU8A = GemmS8Layout::kAmx64x4U8A;
constexpr bool own_layout(GemmS8Layout l) { return l == kLayout || l == kLayoutU8A; }
constexpr int kVecs = kNR / 16;
constexpr size_t kPanelBlockBytes = size_t{1} << 20;  // weight panels kept in L2 per sweep
constexpr int kKStep = 64;                            // bytes of K per tile dot product
constexpr int kAChunk = 4608;                         // bytes of K per row of the A buffer (144 KiB of stack)
constexpr size_t kGroupBytes = kNR * kKR;             // one k-group of a panel: 256 bytes

#include "kernels/gemm_s8/gemm_s8_driver.inc"

#include "kernels/gemm_s8/gemm_s8_epilogue_avx512.inc"

#include "kernels/gemm_s8/gemm_s8_pack_avx512.inc"

// Palette 1, every tile 16 rows x 64 bytes (the layout ldtilecfg reads).
struct alignas(64) TileConfig {
  uint8_t palette_id = 1;
  uint8_t start_row = 0;
  uint8_t reserved[14] = {};
  uint16_t colsb[16] = {64, 64, 64, 64, 64, 64, 64, 64};
  uint8_t rows[16] = {16, 16, 16, 16, 16, 16, 16, 16};
};
static_assert(sizeof(TileConfig) == 64);

// Configures the tiles for one row block and releases them when it ends. The configuration is
// static: GCC 12 does not see ldtilecfg read its operand, so it would drop the stores that fill a
// local one (and ldtilecfg then faults on the garbage).
constexpr TileConfig kTileConfig{};
class TileScope {
 public:
  TileScope() { _tile_loadconfig(&kTileConfig); }
  ~TileScope() { _tile_release(); }
  TileScope(const TileScope&) = delete;
  TileScope& operator=(const TileScope&) = delete;
};

// len bytes from src to dst, 64 at a time (masked at the end: nothing past src + len is read).
inline void copy_bytes(int8_t* dst, const int8_t* src, int len) {
  int i = 0;
  for (; i + 64 <= len; i += 64) _mm512_storeu_si512(dst + i, _mm512_loadu_si512(src + i));
  if (i < len) {
    const __mmask64 mask = (__mmask64{1} << (len - i)) - 1;
    _mm512_mask_storeu_epi8(dst + i, mask, _mm512_maskz_loadu_epi8(mask, src + i));
  }
}

// Bytes [k0, k0 + kc) of rows [m, m + rows) of A into buf (row stride kc), zero past K, and rows
// [rows, row_tiles * 16) zero: the block a tile loads at stride kc. Vector moves, not memcpy: a
// 3 x 3 conv's row is three segments of 3 * Cin bytes, and 96 memcpy calls per row block cost
// more than the block's tile dot products.
void copy_a(const GemmS8Args& g, int m, int rows, int row_tiles, int k0, int kc, int8_t* buf) {
  const int segments = segment_count(g), segment_k = g.k / segments;
  const int k1 = std::min(g.k, k0 + kc);
  for (int r = 0; r < rows; ++r) {
    int8_t* dst = buf + static_cast<size_t>(r) * static_cast<size_t>(kc);
    for (int k = k0; k < k1;) {
      const int s = k / segment_k, in_segment = k - s * segment_k;
      const int len = std::min(k1 - k, segment_k - in_segment);
      const int8_t* src = g.a_segments != nullptr
                              ? g.a_segments[static_cast<size_t>(m + r) * static_cast<size_t>(segments) + s] + in_segment
                              : g.a + static_cast<size_t>(m + r) * g.lda + static_cast<size_t>(k);
      copy_bytes(dst + (k - k0), src, len);
      k += len;
    }
    if (k1 - k0 < kc) std::memset(dst + (k1 - k0), 0, static_cast<size_t>(kc - (k1 - k0)));
  }
  for (int r = rows; r < 16 * row_tiles; ++r) std::memset(buf + static_cast<size_t>(r) * static_cast<size_t>(kc), 0, static_cast<size_t>(kc));
}

// C tiles of one half panel (16 x TWO_ROWS rows x 32 columns) += A [steps * 64 bytes] x W, W at `w`
// (the half's first k-group), A at `a` with row stride lda. Starts from zero, or from `acc` (int32,
// row stride 64) when `resume`; stores back to `acc`.
template <bool kTwoRowTiles, bool kUnsignedA>
void dot_half(const int8_t* a, size_t lda, const uint8_t* w, int steps, bool resume, int32_t* acc) {
  constexpr size_t kAccStride = kNR * sizeof(int32_t);
  if (resume) {
    _tile_loadd(0, acc, kAccStride);
    _tile_loadd(1, acc + 16, kAccStride);
    if constexpr (kTwoRowTiles) {
      _tile_loadd(2, acc + 16 * kNR, kAccStride);
      _tile_loadd(3, acc + 16 * kNR + 16, kAccStride);
    }
  } else {
    _tile_zero(0);
    _tile_zero(1);
    if constexpr (kTwoRowTiles) {
      _tile_zero(2);
      _tile_zero(3);
    }
  }
  const int8_t* a1 = a + 16 * lda;
  for (int s = 0; s < steps; ++s) {
    const uint8_t* ws = w + static_cast<size_t>(s) * 16 * kGroupBytes;
    _tile_loadd(4, a + static_cast<size_t>(s) * kKStep, lda);
    _tile_loadd(6, ws, kGroupBytes);
    _tile_loadd(7, ws + 64, kGroupBytes);
    if constexpr (kUnsignedA) {
      _tile_dpbusd(0, 4, 6);
      _tile_dpbusd(1, 4, 7);
    } else {
      _tile_dpbssd(0, 4, 6);
      _tile_dpbssd(1, 4, 7);
    }
    if constexpr (kTwoRowTiles) {
      _tile_loadd(5, a1 + static_cast<size_t>(s) * kKStep, lda);
      if constexpr (kUnsignedA) {
        _tile_dpbusd(2, 5, 6);
        _tile_dpbusd(3, 5, 7);
      } else {
        _tile_dpbssd(2, 5, 6);
        _tile_dpbssd(3, 5, 7);
      }
    }
  }
  _tile_stored(0, acc, kAccStride);
  _tile_stored(1, acc + 16, kAccStride);
  if constexpr (kTwoRowTiles) {
    _tile_stored(2, acc + 16 * kNR, kAccStride);
    _tile_stored(3, acc + 16 * kNR + 16, kAccStride);
  }
}

// Where a row block's A comes from: read in place, or copied (whole, or chunk by chunk).
struct ABlock {
  const int8_t* a;  // the first row's first byte, in place or in the buffer
  size_t lda;       // row stride of `a`
  bool chunked;     // K is copied chunk by chunk for each half panel
};

// The accumulators of rows [m, m + rows) against one panel: both halves (the second only when
// columns past 32 are wanted), into acc (int32 [32 x 64]).
template <bool kTwoRowTiles, bool kUnsignedA>
void panel_dots(const GemmS8Args& g, const GemmS8PackedHeader& h, const ABlock& ab, int8_t* buf, int m, int rows,
                const uint8_t* panel, int hi, int32_t* acc) {
  const uint8_t* w = panel + 8 * kNR;
  for (int half = 0; half < 2 && 32 * half < hi; ++half) {
    const uint8_t* wh = w + 128 * half;
    int32_t* acc_half = acc + 32 * half;
    if (!ab.chunked) {
      dot_half<kTwoRowTiles, kUnsignedA>(ab.a, ab.lda, wh, h.kp / kKStep, false, acc_half);
      continue;
    }
    for (int k0 = 0; k0 < h.kp; k0 += kAChunk) {
      const int kc = std::min(kAChunk, h.kp - k0);
      copy_a(g, m, rows, kTwoRowTiles ? 2 : 1, k0, kc, buf);
      dot_half<kTwoRowTiles, kUnsignedA>(buf, static_cast<size_t>(kc), wh + static_cast<size_t>(k0 / kKR) * kGroupBytes,
                                         kc / kKStep, k0 > 0, acc_half);
    }
  }
}

// One finished panel's rows through the epilogue: acc (int32 [32 x 64], from the tiles) + kbias,
// minus (z_row - z_packed) * ksum where rows carry their own zero points (the packed kbias
// assumed z_packed).
template <class Epi>
void finish_panel(const GemmS8Args& g, const GemmS8PackedHeader& h, const uint8_t* panel, const int32_t* acc, int m,
                  int rows, int n, int lo, int hi, Epi& epi) {
  __m512i kbias[kVecs], ksum[kVecs];
  for (int j = 0; j < kVecs; ++j) {
    kbias[j] = _mm512_loadu_si512(panel + 64 * j);
    ksum[j] = _mm512_loadu_si512(panel + 4 * kNR + 64 * j);
  }
  epi.begin_panel(n, lo, hi);
  for (int r = 0; r < rows; ++r) {
    __m512i v[kVecs];
    for (int j = 0; j < kVecs; ++j) v[j] = _mm512_add_epi32(_mm512_load_si512(acc + r * kNR + 16 * j), kbias[j]);
    if (g.a_row_zero_point != nullptr) {
      const __m512i dz = _mm512_set1_epi32(g.a_row_zero_point[m + r] - h.a_zero_point);
      for (int j = 0; j < kVecs; ++j) v[j] = _mm512_sub_epi32(v[j], _mm512_mullo_epi32(dz, ksum[j]));
    }
    epi.row(m + r, n, v);
  }
}

// Rows [m, m + rows) of C against panels [pb, pe): A placed once, then per panel the tile dot
// products into one of two accumulator buffers while the previous panel goes through the epilogue
// from the other: vector loads of what tilestored has just written wait for the stores to drain
// (finishing each panel at once took 4x the dot products' time on K = 576), and the tile unit
// works while the vector units finish.
template <bool kTwoRowTiles, bool kUnsignedA, class Epi>
void row_block_of(const GemmS8Args& g, const GemmS8PackedHeader& h, const uint8_t* panels, int m, int rows, int pb,
                  int pe, int n0, int n1, Epi& epi, uint32_t& paths) {
  alignas(64) int8_t buf[kMR * kAChunk];
  alignas(64) int32_t acc[2][kMR * kNR];
  const int row_tiles = kTwoRowTiles ? 2 : 1;
  ABlock ab{};
  if (g.a_segments == nullptr && g.k % kKStep == 0 && rows == 16 * row_tiles) {
    ab = {g.a + static_cast<size_t>(m) * g.lda, g.lda, false};
  } else if (h.kp <= kAChunk) {
    copy_a(g, m, rows, row_tiles, 0, h.kp, buf);
    ab = {buf, static_cast<size_t>(h.kp), false};
  } else {
    ab = {buf, 0, true};
  }
  if (h.panel_bytes * static_cast<uint64_t>(pe - pb) > 48 * 1024) paths |= kPathStreamedWeights;
  struct Pending {
    const uint8_t* panel = nullptr;
    int n = 0, lo = 0, hi = 0;
  } pending;
  int slot = 0;
  TileScope tiles;
  for_each_panel(pb, pe, n0, n1, paths, [&](int p, int n, int lo, int hi) {
    const uint8_t* panel = panels + static_cast<size_t>(p) * h.panel_bytes;
    epi.prefetch_rows(m, rows, n);
    panel_dots<kTwoRowTiles, kUnsignedA>(g, h, ab, buf, m, rows, panel, hi, acc[slot]);
    if (pending.panel != nullptr) finish_panel(g, h, pending.panel, acc[slot ^ 1], m, rows, pending.n, pending.lo, pending.hi, epi);
    pending = {panel, n, lo, hi};
    slot ^= 1;
  });
  if (pending.panel != nullptr) finish_panel(g, h, pending.panel, acc[slot ^ 1], m, rows, pending.n, pending.lo, pending.hi, epi);
}

template <class Epi>
void row_block(const GemmS8Args& g, const GemmS8PackedHeader& h, const uint8_t* panels, int m, int rows, int pb,
               int pe, int n0, int n1, Epi& epi, uint32_t& paths) {
  const bool unsigned_a = h.layout == kLayoutU8A;
  ACT_DCHECK(!unsigned_a || g.a_row_zero_point == nullptr, "unsigned activations have one zero point, in the packed weights");
  if (unsigned_a) paths |= kPathUnsignedA;
  if (rows > 16) {
    if (unsigned_a) {
      row_block_of<true, true>(g, h, panels, m, rows, pb, pe, n0, n1, epi, paths);
    } else {
      row_block_of<true, false>(g, h, panels, m, rows, pb, pe, n0, n1, epi, paths);
    }
  } else if (unsigned_a) {
    row_block_of<false, true>(g, h, panels, m, rows, pb, pe, n0, n1, epi, paths);
  } else {
    row_block_of<false, false>(g, h, panels, m, rows, pb, pe, n0, n1, epi, paths);
  }
}

}  // namespace

const GemmS8Kernels* gemm_s8_table_amx() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_64x4_goi_k64", "gemm_s8s8_s8out_32x64c4_amx", "gemm_s8s8_f32out_32x64c4_amx",
       "gemm_s8s8_s32out_32x64c4_amx"},
      pack_w_64x4<kLayout, false>, pack_wt_64x4<kLayout, false>, "pack_w_s8_64x4_goi_k64_u8a",
      pack_w_64x4<kLayoutU8A, false>);
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_amx() { return nullptr; }
}  // namespace act::kernels

#endif
