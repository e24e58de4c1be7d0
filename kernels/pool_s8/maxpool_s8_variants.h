// The max-pool family's channel-max primitives, one table per ISA (nullptr when that file compiled
// to nothing on this target). Results are exact (integer max) in every variant.
#pragma once

#include "kernels/pool_s8/maxpool_s8.h"

namespace act::kernels {

const MaxPoolS8Kernels* maxpool_s8_table_ref();
const MaxPoolS8Kernels* maxpool_s8_table_avx2();
const MaxPoolS8Kernels* maxpool_s8_table_avx512();  ///< AVX-512 BW
const MaxPoolS8Kernels* maxpool_s8_table_neon();

}  // namespace act::kernels
