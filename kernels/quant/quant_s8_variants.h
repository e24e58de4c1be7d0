// The quant family's variants: quantize / dequantize / min-max per ISA, one table each. An Engine
// runs the table its KernelConfig chose (kernels/config/kernel_config.h); tests and benchmarks use
// the tables directly. Names follow <op>_<dtypes>_<isa>.
//
// Every variant gives the reference's bits: quantize and dequantize are the same IEEE single
// operations in the same order (kernels build with -ffp-contract=off), clamps map NaN to -128
// (x86 maxps(v, lo) / NEON fmaxnm), rounding is half to even (cvtps2dq / fcvtns). minmax ignores
// NaNs (minps(x, acc) keeps acc / fminnm); its result equals the reference's as a float (only
// the sign of a zero extreme may differ, which no caller can observe: choose_quant_s8 clamps
// the range to include 0).
// Preconditions: no overlap between inputs and outputs; the default floating-point environment.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/quant/quant_s8.h"

namespace act::kernels {


/// The table compiled for each ISA (nullptr when that file compiled to nothing on this target).
const QuantS8Kernels* quant_s8_table_ref();
const QuantS8Kernels* quant_s8_table_avx2();
const QuantS8Kernels* quant_s8_table_avx512();  ///< AVX-512 F/BW
const QuantS8Kernels* quant_s8_table_neon();

}  // namespace act::kernels
