#include "weights/quantize/activation_ranges.h"

#include <algorithm>
#include <cmath>

#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"  // calibration uses the reference (every variant gives its bits)

namespace act {

namespace {

ActivationQuant to_activation(const kernels::QuantS8& q) { return {q.scale, q.zero_point}; }

}  // namespace

void RangeObserver::observe_range(std::span<const float> values) {
  float lo, hi;
  kernels::quant_s8_table_ref()->minmax(values.size(), values.data(), &lo, &hi);
  if (!std::isfinite(lo) || !std::isfinite(hi)) {
    // Drop infinities too: recompute over the finite values only.
    lo = INFINITY;
    hi = -INFINITY;
    for (float v : values) {
      if (std::isfinite(v)) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    }
    if (!std::isfinite(lo)) return;
  }
  lo_ = seen_ ? std::min(lo_, lo) : lo;
  hi_ = seen_ ? std::max(hi_, hi) : hi;
  seen_ = true;
}

void RangeObserver::observe_histogram(std::span<const float> values) {
  if (hist_.empty()) hist_.assign(kBins, 0.0);
  const float width = hi_ - lo_;
  if (!(width > 0.0f)) {
    total_ += static_cast<double>(values.size());
    hist_[0] += static_cast<double>(values.size());
    return;
  }
  const float inv = static_cast<float>(kBins) / width;
  for (float v : values) {
    if (!std::isfinite(v)) continue;
    const int b = std::clamp(static_cast<int>((v - lo_) * inv), 0, kBins - 1);
    hist_[static_cast<size_t>(b)] += 1.0;
  }
  total_ += static_cast<double>(values.size());
}

float RangeObserver::bin_center(int b) const {
  return lo_ + (hi_ - lo_) * (static_cast<float>(b) + 0.5f) / static_cast<float>(kBins);
}

double RangeObserver::expected_squared_error(const ActivationQuant& q) const {
  // Each bin's values taken at its center: with 2048 bins over the range, 8 or more per int8
  // step, this samples both the rounding and the clipping error.
  double err = 0.0;
  const float inv = 1.0f / q.scale;
  for (int b = 0; b < kBins; ++b) {
    const double c = hist_[static_cast<size_t>(b)];
    if (c == 0.0) continue;
    const float x = bin_center(b);
    int8_t code;
    kernels::quant_s8_table_ref()->quantize(1, &x, inv, q.zero_point, &code);
    const double d = static_cast<double>(x) - static_cast<double>(q.scale) * (static_cast<int>(code) - q.zero_point);
    err += c * d * d;
  }
  return total_ > 0 ? err / total_ : 0.0;
}

ActivationQuant RangeObserver::choose_minmax() const {
  if (!seen_) return {};
  return to_activation(kernels::choose_quant_s8(lo_, hi_));
}

ActivationQuant RangeObserver::choose_percentile(double percentile) const {
  if (!seen_ || !has_histogram() || !(hi_ > lo_)) return choose_minmax();
  const double tail = total_ * (100.0 - percentile) / 100.0;
  double acc = 0.0;
  int top = kBins - 1;
  for (; top > 0; --top) {
    acc += hist_[static_cast<size_t>(top)];
    if (acc > tail) break;
  }
  acc = 0.0;
  int bottom = 0;
  for (; bottom < kBins - 1; ++bottom) {
    acc += hist_[static_cast<size_t>(bottom)];
    if (acc > tail) break;
  }
  const float step = (hi_ - lo_) / kBins;
  const float hi = lo_ + step * static_cast<float>(top + 1);
  const float lo = lo_ + step * static_cast<float>(bottom);
  return to_activation(kernels::choose_quant_s8(lo_ < 0.0f ? lo : lo_, hi));
}

ActivationQuant RangeObserver::choose_mse() const {
  if (!seen_ || !has_histogram() || !(hi_ > lo_)) return choose_minmax();
  // Shrink the range from both ends in 1/256 steps, keep the best.
  ActivationQuant best = to_activation(kernels::choose_quant_s8(lo_, hi_));
  double best_err = expected_squared_error(best);
  for (int i = 255; i >= 16; --i) {
    const float f = static_cast<float>(i) / 256.0f;
    const ActivationQuant q = to_activation(kernels::choose_quant_s8(lo_ * f, hi_ * f));
    const double e = expected_squared_error(q);
    if (e < best_err) {
      best_err = e;
      best = q;
    }
  }
  return best;
}

}  // namespace act
