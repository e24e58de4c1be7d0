#include "weights/blob/blob_tensors.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "actengine/status.h"
#include "weights/blob/quant_config.h"

namespace act {

namespace {

// What is wrong with tensor `t` of a blob of `precision`, or "".
std::string tensor_problem(const ActbTensor& t, Precision precision) {
  if (t.dtype == DType::kF32) return t.quant.empty() ? "" : "is float32 but has quantization parameters";
  if (t.dtype != DType::kI8) return std::string("has dtype ") + dtype_name(t.dtype) + " (this engine reads F32 and I8 tensors)";
  if (precision != Precision::kInt8) return "is int8 in a blob whose precision is not int8";
  if (t.shape.empty() || t.quant.scales.size() != static_cast<size_t>(t.shape[0]) || t.quant.axis != 0) {
    return "is int8 without one scale per output channel (axis 0)";
  }
  for (int32_t zero_point : t.quant.zero_points) {
    if (zero_point != 0) {
      return "is int8 with zero point " + std::to_string(zero_point) + ": the int8 kernels need symmetric weights (zero points 0)";
    }
  }
  return "";
}

void check_quantization(const ActbFile& blob, const ModelConfig& config) {
  const auto section = blob.config().find("quantization");
  const bool int8 = config.precision == Precision::kInt8;
  if (section == blob.config().end()) {
    if (int8) fail(StatusCode::kDataLoss, "int8 blob without a quantization section");
    return;
  }
  if (!int8) fail(StatusCode::kDataLoss, "a quantization section in a blob whose precision is not int8");
  const QuantConfig quant = QuantConfig::from_json(*section);
  if (!quant.static_activations() && !quant.activations.empty()) {
    fail(StatusCode::kDataLoss, "dynamic quantization with activation parameters (\"" + quant.activations.begin()->first +
         "\", ...): only static and mixed blobs have them");
  }
  for (const std::string& name : quant.float_layers) {
    const ActbTensor* t = blob.find(name);
    if (t == nullptr || t->dtype != DType::kF32) {
      fail(StatusCode::kDataLoss, "quantization float_layers names \"" + name + "\", " +
           (t == nullptr ? "which is no tensor of the blob" : "which the blob stores as int8"));
    }
  }
}

// "1e+30", "-nan": a stored number as an error names it.
std::string number_text(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", x);
  return text;
}

[[noreturn]] void bad_value(const ActbTensor& t, const std::string& problem) {
  fail(StatusCode::kDataLoss, "tensor \"" + t.name + "\" " + problem + "; is the blob damaged?");
}

// Whether every value of x[0..n) lies within +/- limit (NaN does not): a branch-free reduction the
// compiler vectorizes, as the whole network passes through it at every open.
bool all_within(const float* x, size_t n, float limit) {
  int ok = 1;
  for (size_t i = 0; i < n; ++i) ok &= static_cast<int>(std::fabs(x[i]) <= limit);
  return ok != 0;
}

// Input normalisation's statistics may be anything finite (a state in microseconds), except a zero
// divisor; the network's values are bounded.
void check_f32_values(const ActbTensor& t) {
  const bool statistic = t.name.starts_with("norm.") || t.name.starts_with("unnorm.");
  const bool divisor = t.name.starts_with("norm.") && t.name.ends_with(".div");
  const float limit = statistic ? FLT_MAX : kMaxStoredValue;
  const float* values = t.f32();
  const uint64_t n = t.elements();
  constexpr uint64_t kBlock = 4096;
  for (uint64_t b = 0; b < n; b += kBlock) {
    const uint64_t end = std::min(n, b + kBlock);
    if (all_within(values + b, static_cast<size_t>(end - b), limit)) continue;
    for (uint64_t i = b; i < end; ++i) {
      const float x = values[i];
      if (std::fabs(x) <= limit) continue;
      bad_value(t, "holds " + number_text(x) + " at index " + std::to_string(i) +
                       (std::isfinite(x) ? ": no network value is that large (the limit is " + number_text(kMaxStoredValue) + ")"
                                         : ": every stored number must be finite"));
    }
  }
  for (uint64_t i = 0; divisor && i < n; ++i) {
    if (values[i] == 0.0f) {
      bad_value(t, "holds 0 at index " + std::to_string(i) + ": a normalisation divisor of 0 makes that input infinite");
    }
  }
}

// Symmetric int8 weights: values in [-127, 127] (the kernels' packers require it), one plausible
// scale per output channel.
void check_i8_values(const ActbTensor& t) {
  for (size_t c = 0; c < t.quant.scales.size(); ++c) {
    const float s = t.quant.scales[c];
    if (!(s >= FLT_MIN && s <= kMaxWeightScale)) {
      bad_value(t, "has int8 scale " + number_text(s) + " for channel " + std::to_string(c) + ": outside [" + number_text(FLT_MIN) +
                       ", " + number_text(kMaxWeightScale) + "] (a weight scale is its channel's largest weight / 127)");
    }
  }
  const auto* values = reinterpret_cast<const int8_t*>(t.data);
  const void* found = t.nbytes == 0 ? nullptr : std::memchr(values, 0x80, t.nbytes);
  if (found != nullptr) {
    bad_value(t, "holds -128 at index " + std::to_string(static_cast<const int8_t*>(found) - values) +
                     ": int8 weights are symmetric, in [-127, 127]");
  }
}

}  // namespace

void check_tensor_values(const ActbFile& blob) {
  for (const ActbTensor& t : blob.tensors()) {
    if (t.dtype == DType::kF32) check_f32_values(t);
    if (t.dtype == DType::kI8) check_i8_values(t);
  }
}

ModelConfig blob_model_config(const ActbFile& blob) {
  try {
    // First, so that a fuzzed config that does not parse still leaves the numbers checked.
    check_tensor_values(blob);
    ModelConfig config = ModelConfig::from_json(blob.config());
    for (const ActbTensor& t : blob.tensors()) {
      if (const std::string problem = tensor_problem(t, config.precision); !problem.empty()) {
        fail(StatusCode::kDataLoss, "tensor \"" + t.name + "\" " + problem);
      }
    }
    check_quantization(blob, config);
    return config;
  } catch (const Error& e) {
    // A config breaking one of ModelConfig's invariants is a bad argument to an importer, but in a
    // blob it is damage.
    fail(e.code() == StatusCode::kInvalidArgument ? StatusCode::kDataLoss : e.code(), "'" + blob.path() + "': " + e.what());
  }
}

const ActbTensor* BlobTensors::find(const std::string& name) {
  const ActbTensor* t = blob_.find(name);
  if (t != nullptr) read_[static_cast<size_t>(t - blob_.tensors().data())] = true;
  return t;
}

void BlobTensors::release(const std::string& name) {
  const ActbTensor* t = find(name);
  if (t == nullptr || t->dtype != DType::kF32) {
    fail(StatusCode::kInternal, "'" + blob_.path() + "': no float tensor \"" + name + "\" to release");
  }
  released_[static_cast<size_t>(t - blob_.tensors().data())] = true;
  blob_.release_pages(*t);
}

const ActbTensor& BlobTensors::get(const std::string& name, const std::vector<int64_t>& shape) {
  const ActbTensor* t = find(name);
  if (t == nullptr) fail(StatusCode::kDataLoss, "'" + blob_.path() + "': missing tensor \"" + name + "\"");
  if (released_[static_cast<size_t>(t - blob_.tensors().data())]) {
    fail(StatusCode::kInternal, "'" + blob_.path() + "': tensor \"" + name + "\" read after its pages were released");
  }
  if (t->shape != shape) {
    fail(StatusCode::kDataLoss, "'" + blob_.path() + "': tensor \"" + name + "\" has shape " + shape_string(t->shape) +
         ", the model config implies " + shape_string(shape));
  }
  return *t;
}

const float* BlobTensors::f32(const std::string& name, const std::vector<int64_t>& shape) {
  const ActbTensor& t = get(name, shape);
  if (t.dtype != DType::kF32) {
    fail(StatusCode::kDataLoss, "'" + blob_.path() + "': tensor \"" + name + "\" has dtype " + dtype_name(t.dtype) +
         ", the model reads it as F32");
  }
  return t.f32();
}

void BlobTensors::skip(const std::string& prefix) {
  for (size_t i = 0; i < read_.size(); ++i) {
    if (blob_.tensors()[i].name.starts_with(prefix)) read_[i] = true;
  }
}

void BlobTensors::check_all_read() const {
  std::vector<std::string> unread;
  for (size_t i = 0; i < read_.size(); ++i) {
    if (!read_[i]) unread.push_back(blob_.tensors()[i].name);
  }
  if (unread.empty()) return;
  std::string list;
  for (size_t i = 0; i < unread.size() && i < 8; ++i) list += (i ? ", " : "") + ("\"" + unread[i] + "\"");
  if (unread.size() > 8) list += ", ... (" + std::to_string(unread.size()) + " in all)";
  fail(StatusCode::kDataLoss, "'" + blob_.path() + "': tensors the model config does not use: " + list +
       " (does the config belong to these tensors?)");
}

}  // namespace act
