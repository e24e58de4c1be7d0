// How far one array of numbers is from a reference, for the apps' --compare checks. A non-finite
// value on either side is counted, and fails every check: std::max(m, NaN) keeps m, so a plain
// maximum would certify an output full of NaN.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace act {

struct DiffStats {
  size_t count = 0;       ///< pairs added
  size_t non_finite = 0;  ///< pairs where either side is NaN or infinite
  double sum_sq = 0, max_abs = 0, max_rel = 0;
  double max_ratio = 0;   ///< max |ours - ref| / (1 + |ref|)

  void add(double ours, double ref) {
    ++count;
    if (!std::isfinite(ours) || !std::isfinite(ref)) {
      ++non_finite;
      return;
    }
    const double diff = std::fabs(ours - ref);
    sum_sq += diff * diff;
    max_abs = std::max(max_abs, diff);
    max_rel = std::max(max_rel, diff / std::max(1e-12, std::fabs(ref)));
    max_ratio = std::max(max_ratio, diff / (1.0 + std::fabs(ref)));
  }
  /// Mean squared difference over the finite pairs; NaN when any pair was not finite (or none was added).
  double mse() const {
    const size_t finite = count - non_finite;
    return non_finite == 0 && finite > 0 ? sum_sq / static_cast<double>(finite) : std::nan("");
  }
  /// Every pair finite and |ours - ref| <= tol * (1 + |ref|).
  bool within(double tol) const { return count > 0 && non_finite == 0 && max_ratio <= tol; }
};

}  // namespace act
