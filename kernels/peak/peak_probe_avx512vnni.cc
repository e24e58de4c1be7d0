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

#include "kernels/peak/loop_probe.inc"
#define ACT_B(row) "vpbroadcastd " #row "*1024(%[a],%[ao]), %%zmm31\n\t"
#define ACT_MAC(w, acc) "vpdpbusd %%zmm31, %%zmm" #w ", %%zmm" #acc "\n\t"

// The 6x64c4 micro-kernel's inner loop as it runs (per k-group 4 weight loads, 6 A broadcasts, 24
// vpdpbusd), and the other shapes, to tell which streams fastest on a core
// (kernels/config/kernel_tuning.h). What the kernel could reach if every byte it reads were in L1:
// the gap from peak_vpdpbusd_zmm is the loop's own cost, the gap from it to a GEMM the data's
// arrival and the per-tile work (row sums, epilogue).
ACT_TILE_SHAPE_PROBES(peak_vpdpbusd_zmm, 64)
#else
uint64_t peak_vpdpbusd_zmm(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_6x64_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_8x48_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_12x32_loop(uint64_t) { return 0; }
uint64_t peak_vpdpbusd_zmm_14x32_loop(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
