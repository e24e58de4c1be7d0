// CoveredPaths: which kernel variants and code paths actually ran (ruy's "covered paths" idea), so a
// test can fail when the variant it asked for silently did not run. Recording is opt-in per call:
// a kernel records only when its caller passes a CoveredPaths, so there is no global state.
#pragma once

#include <atomic>
#include <cstdint>

#include "kernels/common/isa.h"

namespace act::kernels {

/// Code paths inside one variant (bits, combined per call).
enum KernelPath : uint32_t {
  kPathFullTile = 1u << 0,     ///< a full MR x NR micro-tile
  kPathRowTail = 1u << 1,      ///< a micro-tile with fewer than MR rows (e.g. the 1x16c4 kernel)
  kPathPartialCols = 1u << 2,  ///< a micro-tile storing fewer than NR columns
  kPathRowZeroPoint = 1u << 3, ///< per-row activation zero points
  kPathSegmentedA = 1u << 4,   ///< A rows read in segments (GemmS8Args::a_segments)
  kPathStreamedWeights = 1u << 5,  ///< weights prefetched ahead (more panels than L1 keeps; AVX-512 VNNI)
  kPathUnsignedA = 1u << 6,    ///< activations stored unsigned (GemmS8Kernels::pack_u8a)
};

/// A record of (Isa, KernelPath) pairs that ran. Thread-safe: kernels running on several threads
/// may share one record.
class CoveredPaths {
 public:
  CoveredPaths() = default;
  CoveredPaths(const CoveredPaths&) = delete;
  CoveredPaths& operator=(const CoveredPaths&) = delete;

  /// Adds `paths` (KernelPath bits) to the record of `isa`. Out of line: ISA files call it.
  void record(Isa isa, uint32_t paths);
  /// The KernelPath bits recorded for `isa` (0 when it never ran).
  uint32_t paths(Isa isa) const;
  /// True when anything of `isa` ran.
  bool ran(Isa isa) const { return paths(isa) != 0; }
  /// The ISAs that ran.
  IsaMask ran_mask() const;
  void clear();

 private:
  std::atomic<uint32_t> paths_[kIsaCount] = {};
};

}  // namespace act::kernels
