// The quant family's variants: quantize / dequantize / min-max per ISA, behind the public functions
// of quant_s8.h (which dispatch to quant_s8_active()). Names follow <op>_<dtypes>_<isa>; tests and
// benchmarks use the tables directly.
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
#include <vector>

#include "kernels/common/isa.h"

namespace act::kernels {

struct QuantS8Kernels {
  Isa isa;
  const char* quantize_name;    ///< quantize_f32_s8_<isa>
  const char* dequantize_name;  ///< dequantize_s8_f32_<isa>
  const char* minmax_name;      ///< minmax_f32_<isa>
  void (*quantize)(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y);
  void (*dequantize)(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y);
  void (*minmax)(size_t n, const float* x, float* lo, float* hi);  ///< n >= 1
};

/// The table compiled for each ISA (nullptr when that file compiled to nothing on this target).
const QuantS8Kernels* quant_s8_table_ref();
const QuantS8Kernels* quant_s8_table_avx2();
const QuantS8Kernels* quant_s8_table_avx512vnni();  ///< AVX-512 F/BW (the kAvx512Vnni variant)
const QuantS8Kernels* quant_s8_table_neondot();     ///< plain NEON (the kNeonDot variant)

IsaMask quant_s8_built_isas();
/// The table of `isa` when built and supported by this CPU, else nullptr.
const QuantS8Kernels* quant_s8_kernels(Isa isa);
std::vector<Isa> quant_s8_available_isas();
/// The variant the public functions use: chosen once per process (ACT_ISA, else the best).
const QuantS8Kernels& quant_s8_active();

/// quantize_rows_dynamic_f32_s8 with the given variant's min-max and quantize.
void quantize_rows_dynamic_f32_s8_with(const QuantS8Kernels& k, int rows, int cols, const float* x, size_t ldx,
                                       int8_t* y, size_t ldy, float* row_scale, int32_t* row_zero_point);

}  // namespace act::kernels
