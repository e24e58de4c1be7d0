// tdpbssd throughput probe (AMX-INT8): the tile dot product with its operands already in tiles, no
// loads, four independent accumulator tiles. Intrinsics suffice here: each names its tiles, so the
// loop is exactly these instructions.
#include "kernels/peak/peak_probe.h"

#include <cstdint>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace act::kernels {

#if defined(__x86_64__)
namespace {
// Palette 1, tiles 0-7 of 16 rows x 64 bytes. Static: GCC 12 does not see ldtilecfg read its
// operand, and drops the stores that would fill a local configuration (then ldtilecfg faults).
struct alignas(64) TileConfig {
  uint8_t palette_id = 1, start_row = 0, reserved[14] = {};
  uint16_t colsb[16] = {64, 64, 64, 64, 64, 64, 64, 64};
  uint8_t rows[16] = {16, 16, 16, 16, 16, 16, 16, 16};
};
constexpr TileConfig kTileConfig{};
}  // namespace

uint64_t peak_tdpbssd(uint64_t iterations) {
  _tile_loadconfig(&kTileConfig);
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
  _tile_zero(4);
  _tile_zero(5);
  _tile_zero(6);
  _tile_zero(7);
  for (uint64_t i = 0; i < iterations; ++i) {
    _tile_dpbssd(0, 4, 6);
    _tile_dpbssd(1, 4, 7);
    _tile_dpbssd(2, 5, 6);
    _tile_dpbssd(3, 5, 7);
  }
  _tile_release();
  return iterations * 4 * 16 * 16 * 64;
}
#else
uint64_t peak_tdpbssd(uint64_t) { return 0; }
#endif

}  // namespace act::kernels
