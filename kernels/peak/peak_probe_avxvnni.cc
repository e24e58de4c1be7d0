// vpdpbusd throughput probes on ymm, VEX-encoded (AVX-VNNI: the cores without AVX-512). Inline
// assembly so that the loop is exactly the instructions measured; {vex} makes the assembler emit
// the AVX-VNNI encoding (without it an AVX-512 VNNI assembler may pick EVEX).
#include "kernels/peak/peak_probe.h"

#include <cstdint>

namespace act::kernels {

#if defined(__x86_64__)
// 14 independent chains (vpdpbusd's latency is 4-5 cycles at up to 2 per cycle) on 16 registers.
uint64_t peak_vpdpbusd_ymm(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "vpxor %%ymm14, %%ymm14, %%ymm14\n\t"
      "vpcmpeqd %%ymm15, %%ymm15, %%ymm15\n\t"
      "1:\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm0\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm1\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm2\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm3\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm4\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm5\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm6\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm7\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm8\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm9\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm10\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm11\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm12\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm15, %%ymm13\n\t"
      "dec %0\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : "+r"(n)
      :
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12",
        "xmm13", "xmm14", "xmm15", "cc");
  return iterations * 14 * 32;
}
// The 6x16c4 micro-kernel's inner loop as it runs, its operands in L1: per k-group 2 weight loads,
// 6 A broadcasts (rows 1 KB apart) and 12 vpdpbusd, the offsets wrapping within 16 KB of weights
// and 1 KB of each row (see peak_vpdpbusd_zmm_6x64_loop).
uint64_t peak_vpdpbusd_ymm_6x16_loop(uint64_t iterations) {
  alignas(64) static const uint8_t weights[16 * 1024] = {};
  alignas(64) static const int8_t rows[6 * 1024] = {};
  uint64_t n = iterations, w_off = 0, a_off = 0;
  __asm__ volatile(
      "1:\n\t"
      "vmovdqu 0(%[w],%[wo]), %%ymm12\n\t"
      "vmovdqu 32(%[w],%[wo]), %%ymm13\n\t"
      "vpbroadcastd 0(%[a],%[ao]), %%ymm14\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm12, %%ymm0\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm13, %%ymm1\n\t"
      "vpbroadcastd 1024(%[a],%[ao]), %%ymm15\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm12, %%ymm2\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm13, %%ymm3\n\t"
      "vpbroadcastd 2048(%[a],%[ao]), %%ymm14\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm12, %%ymm4\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm13, %%ymm5\n\t"
      "vpbroadcastd 3072(%[a],%[ao]), %%ymm15\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm12, %%ymm6\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm13, %%ymm7\n\t"
      "vpbroadcastd 4096(%[a],%[ao]), %%ymm14\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm12, %%ymm8\n\t"
      "%{vex%} vpdpbusd %%ymm14, %%ymm13, %%ymm9\n\t"
      "vpbroadcastd 5120(%[a],%[ao]), %%ymm15\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm12, %%ymm10\n\t"
      "%{vex%} vpdpbusd %%ymm15, %%ymm13, %%ymm11\n\t"
      "add $64, %[wo]\n\t"
      "and $16383, %[wo]\n\t"
      "add $4, %[ao]\n\t"
      "and $1023, %[ao]\n\t"
      "dec %[n]\n\t"
      "jnz 1b\n\t"
      "vzeroupper\n\t"
      : [n] "+r"(n), [wo] "+r"(w_off), [ao] "+r"(a_off)
      : [w] "r"(weights), [a] "r"(rows)
      : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10", "xmm11", "xmm12",
        "xmm13", "xmm14", "xmm15", "memory", "cc");
  return iterations * 12 * 32;
}
#else
uint64_t peak_vpdpbusd_ymm(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_ymm_6x16_loop(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
