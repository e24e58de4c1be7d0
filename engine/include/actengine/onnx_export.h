// actengine public API: export an .actb blob as an ONNX model (libactengine_onnx, built where Debian's
// libonnx-dev is found; act_convert --export-onnx uses it).
//
//   auto summary = act::export_onnx("model.actb", "model.onnx", {.part = act::OnnxPart::kFull});
//
// The ONNX graph is the Engine's own graph translated op by op (BatchNorm, the position embeddings and
// the constant first decoder block already folded), opset 17, batch 1, static shapes:
//  - inputs, named by the LeRobot feature keys: every camera "observation.images.<name>" float32
//    [1, 3, H, W] RGB in [0, 1] (normalised by the model's statistics with OnnxNormalization::kOutside),
//    "observation.state" [1, state_dim], "observation.environment_state" [1, env_state_dim];
//  - kFull's output "action" [1, chunk_size, action_dim] (raw units; normalised with kOutside);
//  - kBackbone's outputs "<camera key>.features" float32 [1, dim_model, h, w], one per camera: the
//    ResNet and the 1x1 input projection, what an accelerator runs; the split engine
//    (EngineOptions::external_backbone) takes exactly this layout (ImageView::backbone_features).
// An INT8 blob exports as QDQ: weights int8 per output channel with the blob's scales, and with static
// calibration every calibrated activation quantized with the blob's scale and zero point; what our
// engine quantizes at run time (dynamic activations, the transformer's per-token inputs) stays float.
// The model passes onnx::checker and ONNX's shape inference (strict) before it is written; the file is
// written atomically (nothing at the path on failure). No call throws.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "actengine/status.h"

namespace act {

enum class OnnxPart {
  kFull,      ///< the whole policy: observation in, action chunk out
  kBackbone,  ///< each camera's ResNet + input projection: image in, features out
};
/// "full", "backbone".
StatusOr<OnnxPart> parse_onnx_part(std::string_view name);

enum class OnnxNormalization {
  kInside,   ///< raw observations in, raw actions out (the statistics are in the graph)
  kOutside,  ///< normalised observations in, normalised actions out (the caller normalises)
};
/// "in", "out".
StatusOr<OnnxNormalization> parse_onnx_normalization(std::string_view name);

struct OnnxExportOptions {
  OnnxPart part = OnnxPart::kFull;
  OnnxNormalization normalization = OnnxNormalization::kInside;
};

struct OnnxTensorInfo {
  std::string name;
  std::vector<int64_t> shape;
};

struct OnnxExportSummary {
  std::string precision;  ///< "fp32", or "int8 static" etc. (QDQ)
  std::vector<OnnxTensorInfo> inputs, outputs;
  size_t nodes = 0;
  uint64_t bytes = 0;  ///< of the written file
};

/// Exports the blob at `blob_path` to `onnx_path`. kNotFound / kDataLoss for a missing or bad blob (as
/// Engine::open), kIoError for an unwritable output, kInternal when ONNX's checker refuses the model.
StatusOr<OnnxExportSummary> export_onnx(const std::string& blob_path, const std::string& onnx_path,
                                        const OnnxExportOptions& options = {});

}  // namespace act
