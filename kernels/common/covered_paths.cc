#include "kernels/common/covered_paths.h"

namespace act::kernels {

void CoveredPaths::record(Isa isa, uint32_t paths) {
  paths_[static_cast<unsigned>(isa)].fetch_or(paths, std::memory_order_relaxed);
}

uint32_t CoveredPaths::paths(Isa isa) const {
  return paths_[static_cast<unsigned>(isa)].load(std::memory_order_relaxed);
}

IsaMask CoveredPaths::ran_mask() const {
  IsaMask mask = 0;
  for (int i = 0; i < kIsaCount; ++i) {
    if (paths(static_cast<Isa>(i)) != 0) mask |= isa_bit(static_cast<Isa>(i));
  }
  return mask;
}

void CoveredPaths::clear() {
  for (auto& p : paths_) p.store(0, std::memory_order_relaxed);
}

}  // namespace act::kernels
