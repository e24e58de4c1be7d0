// GemmS8Tester: a builder that runs one gemm_s8 problem through a variant (packer + kernel) and
// checks it against the scalar reference variant and against a naive definition computed from the
// unpacked operands:
//   - int32 accumulators and s8 outputs: exact equality;
//   - f32 outputs: the reference must equal the naive definition exactly (same float operations),
//     the variant must be within 2 ulp of the reference (tight; today they are bit-identical);
//   - computing C by sub-rectangles (unaligned to the tile) gives the same bits as one call;
//   - nothing outside C's rectangle is written (sentinels in the row gaps and after the end);
//   - the variant asked for is the one that ran (CoveredPaths), and nothing else ran.
// A is allocated with exactly kGemmS8ReadSlack bytes after its last row, so ASan catches a kernel
// that reads further.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/gemm_s8/gemm_s8.h"

namespace act::kernels::test {

enum class GemmOut { kS8, kF32, kS32 };
/// How operands are filled: random, or constant extremes (to prove no 16-bit saturation).
enum class GemmFill { kRandom, kMax, kMin };

class GemmS8Tester {
 public:
  GemmS8Tester& m(int v) { m_ = v; return *this; }
  GemmS8Tester& n(int v) { n_ = v; return *this; }
  GemmS8Tester& k(int v) { k_ = v; return *this; }
  /// Extra elements between rows (strided A / C / residual).
  GemmS8Tester& a_stride_pad(size_t v) { lda_pad_ = v; return *this; }
  GemmS8Tester& c_stride_pad(size_t v) { ldc_pad_ = v; return *this; }
  GemmS8Tester& a_zero_point(int v) { za_ = v; return *this; }
  /// Per-row activation zero points (and, for f32 out, per-row scales): dynamic quantization.
  GemmS8Tester& per_row(bool v) { per_row_ = v; return *this; }
  GemmS8Tester& out(GemmOut v) { out_ = v; return *this; }
  GemmS8Tester& out_zero_point(int v) { zo_ = v; return *this; }
  GemmS8Tester& qmin(int v) { qmin_ = v; return *this; }
  GemmS8Tester& qmax(int v) { qmax_ = v; return *this; }
  GemmS8Tester& residual(bool v) { residual_ = v; return *this; }
  /// One residual row for every row of C (ldr 0: the decoder's first layer adds a constant row).
  GemmS8Tester& residual_row(bool v) { residual_row_ = v; return *this; }
  GemmS8Tester& relu(bool v) { relu_ = v; return *this; }
  GemmS8Tester& bias(bool v) { bias_ = v; return *this; }
  /// Per-channel scales drawn log-uniformly from [lo, hi]; lo == hi gives that exact value.
  GemmS8Tester& scales(float lo, float hi) { scale_lo_ = lo; scale_hi_ = hi; return *this; }
  GemmS8Tester& a_fill(GemmFill v) { a_fill_ = v; return *this; }
  GemmS8Tester& w_fill(GemmFill v) { w_fill_ = v; return *this; }
  /// Sub-rectangle size for the tiling check (0: a default set of unaligned sizes).
  GemmS8Tester& tile(int tm, int tn) { tile_m_ = tm; tile_n_ = tn; return *this; }
  GemmS8Tester& seed(uint32_t v) { seed_ = v; return *this; }
  /// A read in segments of this many bytes (GemmS8Args::a_segments; a multiple of kGemmS8SegmentAlign
  /// that divides k): each its own allocation of exactly that size (ASan catches a read past one),
  /// shared between rows the way a convolution's kernel rows are. 0: a plain A.
  GemmS8Tester& segments(int segment_k) { segment_k_ = segment_k; return *this; }
  /// Where C and the residual are the same buffer (s8 out only).
  GemmS8Tester& residual_in_place(bool v) { in_place_ = v; return *this; }
  /// The variant reads A stored unsigned (every byte XOR 0x80, zero point + 128) through weights
  /// packed by its pack_u8a; the reference and the definition read the signed codes.
  GemmS8Tester& unsigned_a(bool v) { unsigned_a_ = v; return *this; }

  /// Runs the checks for `variant` (which must be available on this CPU); reports with gtest.
  void test(const GemmS8Kernels& variant) const;

 private:
  int m_ = 1, n_ = 1, k_ = 1;
  size_t lda_pad_ = 0, ldc_pad_ = 0;
  int za_ = 0;
  bool per_row_ = false;
  GemmOut out_ = GemmOut::kS32;
  int zo_ = 0, qmin_ = -128, qmax_ = 127;
  bool residual_ = false, residual_row_ = false, relu_ = false, bias_ = true, in_place_ = false;
  float scale_lo_ = 1e-4f, scale_hi_ = 1e-2f;
  GemmFill a_fill_ = GemmFill::kRandom, w_fill_ = GemmFill::kRandom;
  int tile_m_ = 0, tile_n_ = 0;
  int segment_k_ = 0;
  bool unsigned_a_ = false;
  uint32_t seed_ = 1;
};

}  // namespace act::kernels::test
