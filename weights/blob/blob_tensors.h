// A blob's tensors as the model its config describes reads them, and the checks that config and
// tensors agree. A blob whose semantic fields contradict its tensors (asymmetric int8 weights, a
// quantization section on a float model, a tensor no layer reads) is refused at Engine::open rather
// than half-used. Errors start with "'<blob path>': " and are kDataLoss.
#pragma once

#include <string>
#include <vector>

#include "weights/blob/actb.h"
#include "weights/blob/model_config.h"

namespace act {

/// The largest magnitude of a stored network value (weights, biases, folded tables): 100 times the
/// importer's limit on a checkpoint's weights (1e6), room for BatchNorm folding.
inline constexpr float kMaxStoredValue = 1e8f;
/// The largest per-channel scale of int8 weights: kMaxStoredValue / 127 (symmetric quantization).
inline constexpr float kMaxWeightScale = kMaxStoredValue / 127.0f;

/// The numbers the kernels read, before any of them runs: every float tensor finite, the network's
/// within +/- kMaxStoredValue, no zero in an input normalisation's divisor, int8 weights in
/// [-127, 127] and their scales in [FLT_MIN, kMaxWeightScale]. Throws kDataLoss naming the tensor,
/// the value and its index (without the blob's path; blob_model_config adds it).
void check_tensor_values(const ActbFile& blob);

/// The model config of `blob`, parsed (ModelConfig::from_json) and checked against the tensors:
/// every tensor is F32, or I8 in an int8 blob with one positive scale per output channel (axis 0) and
/// every zero point 0 (the int8 kernels are symmetric); F32 tensors carry no quantization
/// parameters; the "quantization" section is there exactly when the precision is int8, a dynamic one
/// has no activation parameters, and its float_layers name F32 tensors of the blob; and, first, the
/// stored numbers (check_tensor_values). Throws act::Error.
ModelConfig blob_model_config(const ActbFile& blob);

/// Reads tensors for a network built from the blob's config and records each one asked for, so that
/// a tensor nothing asked for (an encoder layer beyond n_encoder_layers, statistics of a feature the
/// model does not normalise) is found by check_all_read.
class BlobTensors {
 public:
  explicit BlobTensors(ActbFile& blob)
      : blob_(blob), read_(blob.tensors().size(), false), released_(blob.tensors().size(), false) {}

  const ActbFile& blob() const { return blob_; }
  /// The tensor called `name`, or null; recorded as read.
  const ActbTensor* find(const std::string& name);
  /// The float tensor called `name`; throws kDataLoss when it is missing, not F32, or not of `shape`.
  const float* f32(const std::string& name, const std::vector<int64_t>& shape);
  /// The tensor called `name` (any dtype); throws kDataLoss when it is missing or not of `shape`.
  const ActbTensor& get(const std::string& name, const std::vector<int64_t>& shape);
  /// Records every tensor whose name starts with `prefix` as read: a part of the network that runs
  /// elsewhere (the split engine's backbone) leaves its weights in the blob, unused.
  void skip(const std::string& prefix);
  /// Gives the float tensor `name`'s memory back (ActbFile::release_pages), for a reader that keeps
  /// it in another form (a layer's packed weights); get and f32 of it throw kInternal after (find
  /// still tells its dtype and shape).
  void release(const std::string& name);
  /// Throws kDataLoss listing the tensors never asked for.
  void check_all_read() const;

 private:
  ActbFile& blob_;
  std::vector<bool> read_;     // by index in blob_.tensors()
  std::vector<bool> released_;  // by index in blob_.tensors()
};

}  // namespace act
