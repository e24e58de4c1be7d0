// Calibration of activation ranges, pure math over the values seen (no graph, no model): each
// observed value gets its min/max and a histogram, in one pass over the calibration frames, from
// which a calibration method (minmax, percentile or mse) picks the int8 scale and zero point.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "weights/blob/quant_config.h"

namespace act {

class RangeObserver {
 public:
  /// The methods choose over kBins equal bins over [min, max]. Those are only known once every
  /// value is seen, so the values are counted on a finer grid fixed by the first values with a
  /// range: bin g covers [origin + g w, origin + (g + 1) w). When later values fall outside, bins
  /// are added at the ends, and when that would make more than kMaxGridBins, w doubles by merging
  /// pairs of bins, which moves no count across a bin edge. The grid ends with kMaxGridBins / 2 to
  /// kMaxGridBins bins over [min, max], 4 to 8 in each of the methods' bins, which take their
  /// counts in proportion: one pass over the calibration frames instead of a second one, which
  /// cost as much as the float inference it observes.
  static constexpr int kBins = 2048;
  static constexpr int kMaxGridBins = 16384;

  /// Widens [min, max] to include the values and counts them into the histogram (NaN/Inf are
  /// ignored).
  void observe(std::span<const float> values);

  float min() const { return lo_; }
  float max() const { return hi_; }
  bool has_histogram() const { return total_ > 0; }

  /// The grid as it stands: counts[b] values in [first_edge + b width, first_edge + (b + 1) width).
  struct Histogram {
    double first_edge = 0.0, width = 0.0;
    std::span<const double> counts;
  };
  Histogram histogram() const;

  /// The parameters of the three methods. minmax covers [min, max] (the histogram unused);
  /// percentile clips the tails at `percentile` (e.g. 99.99) and mse minimizes the expected squared
  /// quantization error (rounding and clipping) over the histogram. Without a histogram (or for a
  /// constant value) the last two fall back to minmax.
  ActivationQuant choose_minmax() const;
  ActivationQuant choose_percentile(double percentile) const;
  ActivationQuant choose_mse() const;

  /// Expected squared error per value of quantizing this histogram with q.
  double expected_squared_error(const ActivationQuant& q) const;

 private:
  /// Grows the grid (or starts it) so that its bins cover [lo, hi].
  void cover(float lo, float hi);
  /// The grid's counts in kBins equal bins over [min, max].
  std::vector<double> method_bins() const;
  double squared_error(const std::vector<double>& bins, const ActivationQuant& q) const;
  double edge(int64_t b) const { return origin_ + static_cast<double>(first_ + b) * width_; }
  float lo_ = 0.0f, hi_ = 0.0f;
  bool seen_ = false;
  double origin_ = 0.0, width_ = 0.0;  // the grid; width_ 0 until values with a range are seen
  int64_t first_ = 0;                  // grid index of hist_[0]
  std::vector<double> hist_;
  double total_ = 0.0;
  double uncounted_ = 0.0;  // values seen while every value so far was the same (lo_): no grid yet
};

}  // namespace act
