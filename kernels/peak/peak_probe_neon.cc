// Float fmla throughput probe (baseline AArch64 NEON), the bound of the FP32 kernels there. Inline
// assembly so that the loop is exactly the instructions measured.
#include "kernels/peak/peak_probe.h"

namespace act::kernels {

#if defined(__aarch64__)
uint64_t peak_fmla_f32(uint64_t iterations) {
  uint64_t n = iterations;
  __asm__ volatile(
      "movi v30.4s, #0\n\t"
      "movi v31.4s, #0\n\t"
      "1:\n\t"
      "fmla v0.4s, v30.4s, v31.4s\n\t"
      "fmla v1.4s, v30.4s, v31.4s\n\t"
      "fmla v2.4s, v30.4s, v31.4s\n\t"
      "fmla v3.4s, v30.4s, v31.4s\n\t"
      "fmla v4.4s, v30.4s, v31.4s\n\t"
      "fmla v5.4s, v30.4s, v31.4s\n\t"
      "fmla v6.4s, v30.4s, v31.4s\n\t"
      "fmla v7.4s, v30.4s, v31.4s\n\t"
      "fmla v8.4s, v30.4s, v31.4s\n\t"
      "fmla v9.4s, v30.4s, v31.4s\n\t"
      "fmla v10.4s, v30.4s, v31.4s\n\t"
      "fmla v11.4s, v30.4s, v31.4s\n\t"
      "fmla v12.4s, v30.4s, v31.4s\n\t"
      "fmla v13.4s, v30.4s, v31.4s\n\t"
      "fmla v14.4s, v30.4s, v31.4s\n\t"
      "fmla v15.4s, v30.4s, v31.4s\n\t"
      "subs %0, %0, #1\n\t"
      "b.ne 1b\n\t"
      : "+r"(n)
      :
      : "v0", "v1", "v2", "v3", "v4", "v5", "v6", "v7", "v8", "v9", "v10", "v11", "v12", "v13", "v14", "v15", "v30", "v31", "cc");
  return iterations * 16 * 4;
}
#else
uint64_t peak_fmla_f32(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
