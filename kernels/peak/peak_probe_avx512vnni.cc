// vpdpbusd throughput probes (AVX-512 VNNI). Inline assembly so that the loop is exactly the
// instructions measured (compilers spill or fold intrinsic arrays in such loops).
#include "kernels/peak/peak_probe.h"

#include <cstdint>

namespace act::kernels {

#if defined(__x86_64__)
uint64_t peak_vpdpbusd_zmm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vpxord %%zmm30, %%zmm30, %%zmm30\n\t"
      "vpternlogd $0xff, %%zmm31, %%zmm31, %%zmm31\n\t"
      "1:\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm0\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm1\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm2\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm3\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm4\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm5\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm6\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm7\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm8\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm9\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm10\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm11\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm12\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm13\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm14\n\t"
      "vpdpbusd %%zmm30, %%zmm31, %%zmm15\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12",
        "xmm13", "xmm14", "xmm15", "xmm30", "xmm31", "cc");
  return iterations * 16 * 64;
}
// The 6x64c4 micro-kernel's inner loop as it runs, its operands in L1: per k-group 4 weight loads,
// 6 A broadcasts (rows 1 KB apart) and 24 vpdpbusd, the offsets wrapping within 16 KB of weights
// and 1 KB of each row. What the kernel could reach if every byte it reads were in L1: the gap from
// peak_vpdpbusd_zmm is the loop's own cost, the gap from it to a GEMM the data's arrival and the
// per-tile work (row sums, epilogue).
uint64_t peak_vpdpbusd_zmm_6x64_loop(uint64_t iterations) {
  alignas(64) static const uint8_t weights[16 * 1024] = {};
  alignas(64) static const int8_t rows[6 * 1024] = {};
  uint64_t n = iterations, w_off = 0, a_off = 0;
  __asm__ volatile(
      "1:\n\t"
      "vmovdqu64 0(%[w],%[wo]), %%zmm24\n\t"
      "vmovdqu64 64(%[w],%[wo]), %%zmm25\n\t"
      "vmovdqu64 128(%[w],%[wo]), %%zmm26\n\t"
      "vmovdqu64 192(%[w],%[wo]), %%zmm27\n\t"
      "vpbroadcastd 0(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm0\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm1\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm2\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm3\n\t"
      "vpbroadcastd 1024(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm4\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm5\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm6\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm7\n\t"
      "vpbroadcastd 2048(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm8\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm9\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm10\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm11\n\t"
      "vpbroadcastd 3072(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm12\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm13\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm14\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm15\n\t"
      "vpbroadcastd 4096(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm16\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm17\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm18\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm19\n\t"
      "vpbroadcastd 5120(%[a],%[ao]), %%zmm28\n\t"
      "vpdpbusd %%zmm28, %%zmm24, %%zmm20\n\t"
      "vpdpbusd %%zmm28, %%zmm25, %%zmm21\n\t"
      "vpdpbusd %%zmm28, %%zmm26, %%zmm22\n\t"
      "vpdpbusd %%zmm28, %%zmm27, %%zmm23\n\t"
      "add $256, %[wo]\n\t"
      "and $16383, %[wo]\n\t"
      "add $4, %[ao]\n\t"
      "and $1023, %[ao]\n\t"
      "dec %[n]\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : [n] "+r"(n), [wo] "+r"(w_off), [ao] "+r"(a_off)
      : [w] "r"(weights), [a] "r"(rows)
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12", "xmm13", "xmm14", "xmm15", "xmm16", "xmm17", "xmm18", "xmm19", "xmm20", "xmm21", "xmm22", "xmm23", "xmm24", "xmm25", "xmm26", "xmm27", "xmm28", "memory", "cc");
  return iterations * 24 * 64;
}
#else
uint64_t peak_vpdpbusd_zmm(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_6x64_loop(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
