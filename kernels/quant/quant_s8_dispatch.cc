// The one place that maps CPU features (and ACT_ISA) to a quant variant, and the public functions of
// quant_s8.h, which run the variant chosen once per process.
#include "kernels/common/variant_tables.h"
#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"

namespace act::kernels {

namespace {

const VariantTables<QuantS8Kernels>& tables() {
  static const VariantTables<QuantS8Kernels> t(
      {quant_s8_table_ref(), quant_s8_table_avx2(), quant_s8_table_avx512vnni(), quant_s8_table_neondot()});
  return t;
}

}  // namespace

IsaMask quant_s8_built_isas() { return tables().built_isas(); }
const QuantS8Kernels* quant_s8_kernels(Isa isa) { return tables().available(isa); }
std::vector<Isa> quant_s8_available_isas() { return tables().available_isas(); }

const QuantS8Kernels& quant_s8_active() {
  static const QuantS8Kernels& active = tables().choose();
  return active;
}

void quantize_f32_s8(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  quant_s8_active().quantize(n, x, inv_scale, zero_point, y);
}

void dequantize_s8_f32(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  quant_s8_active().dequantize(n, q, scale, zero_point, y);
}

void minmax_f32(size_t n, const float* x, float* lo, float* hi) { quant_s8_active().minmax(n, x, lo, hi); }

void quantize_rows_dynamic_f32_s8(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                  float* row_scale, int32_t* row_zero_point) {
  quantize_rows_dynamic_f32_s8_with(quant_s8_active(), rows, cols, x, ldx, y, ldy, row_scale, row_zero_point);
}

}  // namespace act::kernels
