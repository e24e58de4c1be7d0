// The one place that maps CPU features (and ACT_ISA) to a float element-wise variant, and the
// public functions of fp32_kernels.h that run the variant chosen once per process.
#include "kernels/common/variant_tables.h"
#include "kernels/fp32/elementwise_f32.h"
#include "kernels/fp32/fp32_kernels.h"

namespace act::kernels {

namespace {

const VariantTables<ElementwiseF32Kernels>& tables() {
  static const VariantTables<ElementwiseF32Kernels> t({elementwise_f32_table_ref(), elementwise_f32_table_avx2(),
                                                       elementwise_f32_table_avx512vnni(),
                                                       elementwise_f32_table_neondot()});
  return t;
}

}  // namespace

IsaMask elementwise_f32_built_isas() { return tables().built_isas(); }
const ElementwiseF32Kernels* elementwise_f32_kernels(Isa isa) { return tables().available(isa); }
std::vector<Isa> elementwise_f32_available_isas() { return tables().available_isas(); }
const ElementwiseF32Kernels& elementwise_f32_active() {
  static const ElementwiseF32Kernels& active = tables().choose();
  return active;
}

void layernorm_rows_f32(int rows, int cols, const float* x, size_t ldx, const float* gamma, const float* beta,
                        float eps, float* y, size_t ldy) {
  elementwise_f32_active().layernorm_rows(rows, cols, x, ldx, gamma, beta, eps, y, ldy);
}

void softmax_rows_f32(int rows, int cols, float* x, size_t ldx) {
  elementwise_f32_active().softmax_rows(rows, cols, x, ldx);
}

void relu_f32(size_t n, float* x) { elementwise_f32_active().relu(n, x); }
void gelu_f32(size_t n, float* x) { elementwise_f32_active().gelu(n, x); }
void add_f32(size_t n, const float* a, const float* b, float* y) { elementwise_f32_active().add(n, a, b, y); }

}  // namespace act::kernels
