// vpmaddwd throughput probes (AVX2). Inline assembly so that the loop is exactly the instructions
// measured.
#include "kernels/peak/peak_probe.h"

namespace act::kernels {

#if defined(__x86_64__)
uint64_t peak_vpmaddwd_ymm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vpxor %%ymm14, %%ymm14, %%ymm14\n\t"
      "1:\n\t"
      "vpmaddwd %%ymm14, %%ymm0, %%ymm0\n\t"
      "vpmaddwd %%ymm14, %%ymm1, %%ymm1\n\t"
      "vpmaddwd %%ymm14, %%ymm2, %%ymm2\n\t"
      "vpmaddwd %%ymm14, %%ymm3, %%ymm3\n\t"
      "vpmaddwd %%ymm14, %%ymm4, %%ymm4\n\t"
      "vpmaddwd %%ymm14, %%ymm5, %%ymm5\n\t"
      "vpmaddwd %%ymm14, %%ymm6, %%ymm6\n\t"
      "vpmaddwd %%ymm14, %%ymm7, %%ymm7\n\t"
      "vpmaddwd %%ymm14, %%ymm8, %%ymm8\n\t"
      "vpmaddwd %%ymm14, %%ymm9, %%ymm9\n\t"
      "vpmaddwd %%ymm14, %%ymm10, %%ymm10\n\t"
      "vpmaddwd %%ymm14, %%ymm11, %%ymm11\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm14",
        "cc");
  return iterations * 12 * 16;
}

uint64_t peak_vpmaddwd_vpaddd_ymm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vpxor %%ymm14, %%ymm14, %%ymm14\n\t"
      "vpxor %%ymm15, %%ymm15, %%ymm15\n\t"
      "1:\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm8\n\t"
      "vpaddd %%ymm8, %%ymm0, %%ymm0\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm9\n\t"
      "vpaddd %%ymm9, %%ymm1, %%ymm1\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm10\n\t"
      "vpaddd %%ymm10, %%ymm2, %%ymm2\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm11\n\t"
      "vpaddd %%ymm11, %%ymm3, %%ymm3\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm12\n\t"
      "vpaddd %%ymm12, %%ymm4, %%ymm4\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm13\n\t"
      "vpaddd %%ymm13, %%ymm5, %%ymm5\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm8\n\t"
      "vpaddd %%ymm8, %%ymm6, %%ymm6\n\t"
      "vpmaddwd %%ymm14, %%ymm15, %%ymm9\n\t"
      "vpaddd %%ymm9, %%ymm7, %%ymm7\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12",
        "xmm13", "xmm14", "xmm15", "cc");
  return iterations * 8 * 16;
}
uint64_t peak_vfmadd_f32_ymm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vxorps %%ymm14, %%ymm14, %%ymm14\n\tvxorps %%ymm15, %%ymm15, %%ymm15\n\t"
      "1:\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm0\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm1\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm2\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm3\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm4\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm5\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm6\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm7\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm8\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm9\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm10\n\t"
      "vfmadd231ps %%ymm14, %%ymm15, %%ymm11\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm14", "xmm15", "cc");
  return iterations * 12 * 8;
}
#else
uint64_t peak_vfmadd_f32_ymm(uint64_t) { return 0; }
uint64_t peak_vpmaddwd_ymm(uint64_t) { return 0; }
uint64_t peak_vpmaddwd_vpaddd_ymm(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
