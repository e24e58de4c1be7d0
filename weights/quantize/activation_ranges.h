// Calibration of activation ranges, pure math over the values seen (no graph, no model): each
// observed value gets its min/max (pass 1) and a histogram over that range (pass 2), from which a
// calibration method (minmax, percentile or mse) picks the int8 scale and zero point.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "weights/blob/quant_config.h"

namespace act {

class RangeObserver {
 public:
  static constexpr int kBins = 2048;

  /// Pass 1: widens [min, max] to include the values (NaN/Inf are ignored).
  void observe_range(std::span<const float> values);
  /// Pass 2 (after every observe_range call): counts the values into kBins bins over [min, max].
  void observe_histogram(std::span<const float> values);

  float min() const { return lo_; }
  float max() const { return hi_; }
  bool has_histogram() const { return total_ > 0; }

  /// The parameters of the three methods. minmax covers [min, max] and needs pass 1 only;
  /// percentile clips the tails at `percentile` (e.g. 99.99) and mse minimizes the expected squared
  /// quantization error (rounding and clipping) over the histogram. Without a histogram (or for a
  /// constant value) the last two fall back to minmax.
  ActivationQuant choose_minmax() const;
  ActivationQuant choose_percentile(double percentile) const;
  ActivationQuant choose_mse() const;

  /// Expected squared error per value of quantizing this histogram with q.
  double expected_squared_error(const ActivationQuant& q) const;

 private:
  float bin_center(int b) const;
  float lo_ = 0.0f, hi_ = 0.0f;
  bool seen_ = false;
  std::vector<double> hist_;
  double total_ = 0.0;
};

}  // namespace act
