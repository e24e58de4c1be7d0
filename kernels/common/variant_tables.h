// The dispatch pattern every kernel family shares: one table of function pointers per ISA variant
// (nullptr when that ISA file compiled to nothing for this target), "available" = built and
// supported by this CPU, and a process-wide choice made once (ACT_ISA when set, else the best).
// Only the families' dispatch files (baseline flags) instantiate this template.
#pragma once

#include <array>
#include <vector>

#include "kernels/common/isa.h"

namespace act::kernels {

template <class Table>
class VariantTables {
 public:
  /// built[i]: the table of Isa(i) compiled into this binary, or nullptr. built[kRef] is required.
  explicit VariantTables(const std::array<const Table*, kIsaCount>& built) : built_(built) {}

  IsaMask built_isas() const {
    IsaMask mask = 0;
    for (int i = 0; i < kIsaCount; ++i) {
      if (built_[i] != nullptr) mask |= isa_bit(static_cast<Isa>(i));
    }
    return mask;
  }
  /// The table of `isa` when it is built and the CPU supports it, else nullptr.
  const Table* available(Isa isa) const {
    return cpu_supports(isa) ? built_[static_cast<int>(isa)] : nullptr;
  }
  std::vector<Isa> available_isas() const {
    std::vector<Isa> out;
    for (int i = 0; i < kIsaCount; ++i) {
      if (available(static_cast<Isa>(i)) != nullptr) out.push_back(static_cast<Isa>(i));
    }
    return out;
  }
  /// ACT_ISA's variant, else the best available one; the reference when ACT_ISA cannot be honoured
  /// (callers validate ACT_ISA up front with gemm_s8_select(), as Engine does).
  const Table& choose() const {
    const IsaChoice c = choose_isa_from_env(built_isas());
    const Table* t = c.ok() ? available(c.isa) : nullptr;
    return t != nullptr ? *t : *built_[static_cast<int>(Isa::kRef)];
  }

 private:
  std::array<const Table*, kIsaCount> built_;
};

}  // namespace act::kernels
