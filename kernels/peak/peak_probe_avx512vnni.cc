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

// Other tile shapes' inner loops, the same way (weights wrapping within 16 KB, rows 1 KB apart), to
// tell which shape streams fastest on a core (kernels/config/kernel_tuning.h): a taller tile loads
// fewer weight vectors per row, a wider one fewer broadcasts per column. Accumulators in zmm0..,
// weights in zmm24.. (zmm28.. for 14x32), the broadcast in zmm31.
#define ACT_W(i, reg) "vmovdqu64 " #i "*64(%[w],%[wo]), %%zmm" #reg "\n\t"
#define ACT_B(row) "vpbroadcastd " #row "*1024(%[a],%[ao]), %%zmm31\n\t"
#define ACT_D(w, acc) "vpdpbusd %%zmm31, %%zmm" #w ", %%zmm" #acc "\n\t"
#define ACT_ROW3(row, a0, a1, a2) ACT_B(row) ACT_D(24, a0) ACT_D(25, a1) ACT_D(26, a2)
#define ACT_ROW2(row, w0, w1, a0, a1) ACT_B(row) ACT_D(w0, a0) ACT_D(w1, a1)
// A probe function: `body` (one k-group's instructions) in a loop whose weight offset steps by
// w_step bytes and whose row offset by 4, both wrapping; returns the MACs done.
#define ACT_LOOP_PROBE(fn, macs_per_iteration, w_step, body)                                                        \
  uint64_t fn(uint64_t iterations) {                                                                               \
    uint64_t n = iterations, w_off = 0, a_off = 0;                                                                 \
    __asm__ volatile("1:\n\t" body "add $" #w_step ", %[wo]\n\tand $16383, %[wo]\n\tadd $4, %[ao]\n\t"             \
                     "and $1023, %[ao]\n\tdec %[n]\n\tjnz 1b\n\tvzeroupper\n\t"                                     \
                     : [n] "+r"(n), [wo] "+r"(w_off), [ao] "+r"(a_off)                                             \
                     : [w] "r"(kProbeWeights), [a] "r"(kProbeRows)                                                 \
                     : "xmm0", "xmm1", "xmm2", "xmm3", "xmm4", "xmm5", "xmm6", "xmm7", "xmm8", "xmm9", "xmm10",      \
                       "xmm11", "xmm12", "xmm13", "xmm14", "xmm15", "xmm16", "xmm17", "xmm18", "xmm19", "xmm20",   \
                       "xmm21", "xmm22", "xmm23", "xmm24", "xmm25", "xmm26", "xmm27", "xmm28", "xmm29", "xmm30",   \
                       "xmm31", "memory", "cc");                                                                   \
    return iterations * (macs_per_iteration);                                                                      \
  }

namespace {
// 16 KB of weights and the widest step past its end (the offsets wrap at 16 KB, not at a step).
alignas(64) const uint8_t kProbeWeights[16 * 1024 + 256] = {};
alignas(64) const int8_t kProbeRows[14 * 1024] = {};
}  // namespace

// 8x48c4: 3 weight loads, 8 broadcasts, 24 vpdpbusd per k-group.
ACT_LOOP_PROBE(peak_vpdpbusd_zmm_8x48_loop, 24 * 64, 192,
               ACT_W(0, 24) ACT_W(1, 25) ACT_W(2, 26) ACT_ROW3(0, 0, 1, 2) ACT_ROW3(1, 3, 4, 5) ACT_ROW3(2, 6, 7, 8)
                   ACT_ROW3(3, 9, 10, 11) ACT_ROW3(4, 12, 13, 14) ACT_ROW3(5, 15, 16, 17) ACT_ROW3(6, 18, 19, 20)
                       ACT_ROW3(7, 21, 22, 23))

// 12x32c4: 2 weight loads, 12 broadcasts, 24 vpdpbusd per k-group.
ACT_LOOP_PROBE(peak_vpdpbusd_zmm_12x32_loop, 24 * 64, 128,
               ACT_W(0, 24) ACT_W(1, 25) ACT_ROW2(0, 24, 25, 0, 1) ACT_ROW2(1, 24, 25, 2, 3) ACT_ROW2(2, 24, 25, 4, 5)
                   ACT_ROW2(3, 24, 25, 6, 7) ACT_ROW2(4, 24, 25, 8, 9) ACT_ROW2(5, 24, 25, 10, 11)
                       ACT_ROW2(6, 24, 25, 12, 13) ACT_ROW2(7, 24, 25, 14, 15) ACT_ROW2(8, 24, 25, 16, 17)
                           ACT_ROW2(9, 24, 25, 18, 19) ACT_ROW2(10, 24, 25, 20, 21) ACT_ROW2(11, 24, 25, 22, 23))

// 14x32c4: 2 weight loads, 14 broadcasts, 28 vpdpbusd per k-group (every register in use).
ACT_LOOP_PROBE(peak_vpdpbusd_zmm_14x32_loop, 28 * 64, 128,
               ACT_W(0, 28) ACT_W(1, 29) ACT_ROW2(0, 28, 29, 0, 1) ACT_ROW2(1, 28, 29, 2, 3) ACT_ROW2(2, 28, 29, 4, 5)
                   ACT_ROW2(3, 28, 29, 6, 7) ACT_ROW2(4, 28, 29, 8, 9) ACT_ROW2(5, 28, 29, 10, 11)
                       ACT_ROW2(6, 28, 29, 12, 13) ACT_ROW2(7, 28, 29, 14, 15) ACT_ROW2(8, 28, 29, 16, 17)
                           ACT_ROW2(9, 28, 29, 18, 19) ACT_ROW2(10, 28, 29, 20, 21) ACT_ROW2(11, 28, 29, 22, 23)
                               ACT_ROW2(12, 28, 29, 24, 25) ACT_ROW2(13, 28, 29, 26, 27))
#undef ACT_W
#undef ACT_B
#undef ACT_D
#undef ACT_ROW3
#undef ACT_ROW2
#undef ACT_LOOP_PROBE
#else
uint64_t peak_vpdpbusd_zmm(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_6x64_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_8x48_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_12x32_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_14x32_loop(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
