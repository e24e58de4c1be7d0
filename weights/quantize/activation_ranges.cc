#include "weights/quantize/activation_ranges.h"

#include <algorithm>
#include <cmath>

#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"  // calibration uses the reference (every variant gives its bits)

namespace act {

namespace {

ActivationQuant to_activation(const kernels::QuantS8& q) { return {q.scale, q.zero_point}; }

}  // namespace

void RangeObserver::observe(std::span<const float> values) {
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
  const bool constant_so_far = seen_ && !(hi_ > lo_);  // then every value so far was lo_
  const float constant = lo_;
  lo_ = seen_ ? std::min(lo_, lo) : lo;
  hi_ = seen_ ? std::max(hi_, hi) : hi;
  seen_ = true;
  if (!(hi_ > lo_)) {
    uncounted_ += static_cast<double>(std::count_if(values.begin(), values.end(), [](float v) { return std::isfinite(v); }));
    return;
  }
  cover(lo_, hi_);
  const float base = static_cast<float>(edge(0)), inv = static_cast<float>(1.0 / width_);
  const int last = static_cast<int>(hist_.size()) - 1;
  const auto bin = [&](float v) { return static_cast<size_t>(std::clamp(static_cast<int>((v - base) * inv), 0, last)); };
  if (constant_so_far) {
    hist_[bin(constant)] += uncounted_;
    total_ += uncounted_;
    uncounted_ = 0.0;
  }
  double counted = 0.0;
  for (float v : values) {
    if (!std::isfinite(v)) continue;
    hist_[bin(v)] += 1.0;
    counted += 1.0;
  }
  total_ += counted;
}

void RangeObserver::cover(float lo, float hi) {
  if (width_ == 0.0) {  // the first range: the grid starts at it, kMaxGridBins bins to its top
    origin_ = lo;
    width_ = (static_cast<double>(hi) - static_cast<double>(lo)) / (kMaxGridBins - 1);
  }
  const auto grid_index = [&](float v) { return static_cast<int64_t>(std::floor((static_cast<double>(v) - origin_) / width_)); };
  // Grid indices of the first and last bins to hold: the bins there now and [lo, hi]. Pairs of bins
  // merge (g -> floor(g / 2), on the same origin) until they fit in kMaxGridBins.
  int64_t want_first = grid_index(lo), want_last = grid_index(hi);
  if (!hist_.empty()) {
    want_first = std::min(want_first, first_);
    want_last = std::max(want_last, first_ + static_cast<int64_t>(hist_.size()) - 1);
  }
  while (want_last - want_first + 1 > kMaxGridBins) {
    if (!hist_.empty()) {
      const int64_t merged_first = first_ >> 1;  // arithmetic shift: floor(g / 2) for negative g too
      std::vector<double> merged(static_cast<size_t>(((first_ + static_cast<int64_t>(hist_.size()) - 1) >> 1) - merged_first + 1), 0.0);
      for (size_t b = 0; b < hist_.size(); ++b) merged[static_cast<size_t>(((first_ + static_cast<int64_t>(b)) >> 1) - merged_first)] += hist_[b];
      hist_ = std::move(merged);
      first_ = merged_first;
    }
    width_ *= 2.0;
    want_first >>= 1;
    want_last >>= 1;
  }
  if (hist_.empty()) {
    hist_.assign(static_cast<size_t>(want_last - want_first + 1), 0.0);
  } else if (want_first < first_ || want_last >= first_ + static_cast<int64_t>(hist_.size())) {
    std::vector<double> grown(static_cast<size_t>(want_last - want_first + 1), 0.0);
    std::copy(hist_.begin(), hist_.end(), grown.begin() + (first_ - want_first));
    hist_ = std::move(grown);
  }
  first_ = want_first;
}

RangeObserver::Histogram RangeObserver::histogram() const {
  if (hist_.empty()) return {lo_, 0.0, {}};
  return {edge(0), width_, hist_};
}

std::vector<double> RangeObserver::method_bins() const {
  std::vector<double> out(kBins, 0.0);
  const double lo = lo_, hi = hi_, step = (hi - lo) / kBins;
  for (size_t b = 0; b < hist_.size(); ++b) {
    const double c = hist_[b];
    if (c == 0.0) continue;
    // The grid bin's part within [min, max] (its values are there), spread over the method bins it
    // overlaps in proportion.
    const double from = std::max(lo, edge(static_cast<int64_t>(b))), to = std::min(hi, edge(static_cast<int64_t>(b) + 1));
    const int first = std::clamp(static_cast<int>((from - lo) / step), 0, kBins - 1);
    const int last = std::clamp(static_cast<int>((to - lo) / step), 0, kBins - 1);
    if (!(to > from) || first == last) {
      out[static_cast<size_t>(first)] += c;
      continue;
    }
    for (int i = first; i <= last; ++i) {
      const double overlap = std::min(to, lo + (i + 1) * step) - std::max(from, lo + i * step);
      if (overlap > 0.0) out[static_cast<size_t>(i)] += c * overlap / (to - from);
    }
  }
  return out;
}

double RangeObserver::squared_error(const std::vector<double>& bins, const ActivationQuant& q) const {
  // Each bin's values taken at its center: with 2048 bins over the range, 8 or more per int8
  // step, this samples both the rounding and the clipping error.
  double err = 0.0;
  const float inv = 1.0f / q.scale;
  for (int b = 0; b < kBins; ++b) {
    const double c = bins[static_cast<size_t>(b)];
    if (c == 0.0) continue;
    const float x = lo_ + (hi_ - lo_) * (static_cast<float>(b) + 0.5f) / static_cast<float>(kBins);
    int8_t code;
    kernels::quant_s8_table_ref()->quantize(1, &x, inv, q.zero_point, &code);
    const double d = static_cast<double>(x) - static_cast<double>(q.scale) * (static_cast<int>(code) - q.zero_point);
    err += c * d * d;
  }
  return total_ > 0 ? err / total_ : 0.0;
}

double RangeObserver::expected_squared_error(const ActivationQuant& q) const {
  return has_histogram() && hi_ > lo_ ? squared_error(method_bins(), q) : 0.0;
}

ActivationQuant RangeObserver::choose_minmax() const {
  if (!seen_) return {};
  return to_activation(kernels::choose_quant_s8(lo_, hi_));
}

ActivationQuant RangeObserver::choose_percentile(double percentile) const {
  if (!seen_ || !has_histogram() || !(hi_ > lo_)) return choose_minmax();
  const std::vector<double> bins = method_bins();
  const double tail = total_ * (100.0 - percentile) / 100.0;
  double acc = 0.0;
  int top = kBins - 1;
  for (; top > 0; --top) {
    acc += bins[static_cast<size_t>(top)];
    if (acc > tail) break;
  }
  acc = 0.0;
  int bottom = 0;
  for (; bottom < kBins - 1; ++bottom) {
    acc += bins[static_cast<size_t>(bottom)];
    if (acc > tail) break;
  }
  const float step = (hi_ - lo_) / kBins;
  const float hi = lo_ + step * static_cast<float>(top + 1);
  const float lo = lo_ + step * static_cast<float>(bottom);
  return to_activation(kernels::choose_quant_s8(lo_ < 0.0f ? lo : lo_, hi));
}

ActivationQuant RangeObserver::choose_mse() const {
  if (!seen_ || !has_histogram() || !(hi_ > lo_)) return choose_minmax();
  const std::vector<double> bins = method_bins();
  // Shrink the range from both ends in 1/256 steps, keep the best.
  ActivationQuant best = to_activation(kernels::choose_quant_s8(lo_, hi_));
  double best_err = squared_error(bins, best);
  for (int i = 255; i >= 16; --i) {
    const float f = static_cast<float>(i) / 256.0f;
    const ActivationQuant q = to_activation(kernels::choose_quant_s8(lo_ * f, hi_ * f));
    const double e = squared_error(bins, q);
    if (e < best_err) {
      best_err = e;
      best = q;
    }
  }
  return best;
}

}  // namespace act
