// Calibration of activation ranges: each observed backbone value gets its min/max (pass 1) and a
// histogram over that range (pass 2), from which a calibration method picks the int8 scale and
// zero point.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "weights/blob/quant_config.h"

namespace act {

enum class CalibrationMethod { kMinMax, kPercentile, kMse };
const char* calibration_method_name(CalibrationMethod m);
/// "minmax", "percentile" or "mse"; throws kInvalidArgument otherwise.
CalibrationMethod parse_calibration_method(const std::string& name);

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

  /// The parameters the method chooses. minmax needs pass 1 only; percentile clips the tails at
  /// `percentile` (e.g. 99.99) and mse minimizes the expected squared quantization error (rounding
  /// and clipping) over the histogram; both need pass 2.
  ActivationQuant choose(CalibrationMethod method, double percentile = 99.99) const;

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
