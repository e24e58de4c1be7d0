// sdot throughput probe (AArch64 dot product, the by-element form the 4x16c4 kernel uses). Inline
// assembly so that the loop is exactly the instructions measured.
#include "kernels/peak/peak_probe.h"

namespace act::kernels {

#if defined(__aarch64__)
uint64_t peak_sdot(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "movi v30.16b, #1\n\t"
      "movi v31.16b, #2\n\t"
      "1:\n\t"
      "sdot v0.4s, v30.16b, v31.4b[0]\n\t"
      "sdot v1.4s, v30.16b, v31.4b[1]\n\t"
      "sdot v2.4s, v30.16b, v31.4b[2]\n\t"
      "sdot v3.4s, v30.16b, v31.4b[3]\n\t"
      "sdot v4.4s, v30.16b, v31.4b[0]\n\t"
      "sdot v5.4s, v30.16b, v31.4b[1]\n\t"
      "sdot v6.4s, v30.16b, v31.4b[2]\n\t"
      "sdot v7.4s, v30.16b, v31.4b[3]\n\t"
      "sdot v16.4s, v30.16b, v31.4b[0]\n\t"
      "sdot v17.4s, v30.16b, v31.4b[1]\n\t"
      "sdot v18.4s, v30.16b, v31.4b[2]\n\t"
      "sdot v19.4s, v30.16b, v31.4b[3]\n\t"
      "sdot v20.4s, v30.16b, v31.4b[0]\n\t"
      "sdot v21.4s, v30.16b, v31.4b[1]\n\t"
      "sdot v22.4s, v30.16b, v31.4b[2]\n\t"
      "sdot v23.4s, v30.16b, v31.4b[3]\n\t"
      "subs %0, %0, #1\n\t"
      "b.ne 1b\n\t"
      : "+r"(n)
      :
      : "v0", "v1", "v2", "v3", "v4", "v5", "v6", "v7", "v16", "v17", "v18", "v19", "v20", "v21", "v22", "v23",
        "v30", "v31", "cc");
  return iterations * 16 * 16;
}
#else
uint64_t peak_sdot(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
