// Float FMA throughput probes on zmm registers (AVX-512 F), the bound of the avx512 FP32 GEMM, and
// its tile shapes' inner loops. Inline assembly so that the loop is exactly the instructions
// measured.
#include "kernels/peak/peak_probe.h"

namespace act::kernels {

#if defined(__x86_64__)
uint64_t peak_vfmadd_f32_zmm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vpxord %%zmm14, %%zmm14, %%zmm14\n\tvpxord %%zmm15, %%zmm15, %%zmm15\n\t"
      "1:\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm0\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm1\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm2\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm3\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm4\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm5\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm6\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm7\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm8\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm9\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm10\n\t"
      "vfmadd231ps %%zmm14, %%zmm15, %%zmm11\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm14", "xmm15", "cc");
  return iterations * 12 * 16;
}

#include "kernels/peak/loop_probe.inc"
#define ACT_B(row) "vbroadcastss " #row "*1024(%[a],%[ao]), %%zmm31\n\t"
#define ACT_MAC(w, acc) "vfmadd231ps %%zmm31, %%zmm" #w ", %%zmm" #acc "\n\t"

// The float GEMM's 6x64 tile (gemm_f32_avx512.cc) and the int8 probes' other shapes in float.
ACT_TILE_SHAPE_PROBES(peak_vfmadd_f32_zmm, 16)
#else
uint64_t peak_vfmadd_f32_zmm(uint64_t) { return 0; }
uint64_t peak_vfmadd_f32_zmm_6x64_loop(uint64_t) { return 0; }
uint64_t peak_vfmadd_f32_zmm_8x48_loop(uint64_t) { return 0; }
uint64_t peak_vfmadd_f32_zmm_12x32_loop(uint64_t) { return 0; }
uint64_t peak_vfmadd_f32_zmm_14x32_loop(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
