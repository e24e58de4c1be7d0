// Names of the tensors in an .actb blob: the one place both the importer (writer) and the graph
// builder (reader) take them from.
#pragma once

#include <string>

namespace act::blob_names {

// Backbone convs, BatchNorm folded: weight [out, kh, kw, in] (OHWI), bias [out]. `conv` is the
// torchvision path, e.g. "conv1", "layer2.0.conv1", "layer2.0.downsample.0".
inline std::string conv_weight(const std::string& conv) { return "backbone." + conv + ".weight"; }
inline std::string conv_bias(const std::string& conv) { return "backbone." + conv + ".bias"; }

// Input normalisation per feature key: y = (x - sub) / div * mul + add (mul/add from the mode).
inline std::string norm_sub(const std::string& key) { return "norm." + key + ".sub"; }
inline std::string norm_div(const std::string& key) { return "norm." + key + ".div"; }
// Action un-normalisation: x = (y + shift) * scale + offset.
inline const char* kUnnormShift = "unnorm.action.shift";
inline const char* kUnnormScale = "unnorm.action.scale";
inline const char* kUnnormOffset = "unnorm.action.offset";

// Input projections and the constant latent token [D].
inline const char* kImgProjWeight = "proj.image.weight";  // [D, C_fm]
inline const char* kImgProjBias = "proj.image.bias";
inline const char* kStateProjWeight = "proj.state.weight";  // [D, S]
inline const char* kStateProjBias = "proj.state.bias";
inline const char* kEnvProjWeight = "proj.env.weight";  // [D, E]
inline const char* kEnvProjBias = "proj.env.bias";
inline const char* kLatentToken = "encoder.latent_token";  // [D]
inline const char* kEncoderPos = "encoder.pos";            // [N_tok, D] (for inspection; folded below)

inline std::string enc(int layer, const std::string& leaf) {
  return "encoder.layers." + std::to_string(layer) + "." + leaf;
}
inline std::string dec(int layer, const std::string& leaf) {
  return "decoder.layers." + std::to_string(layer) + "." + leaf;
}
// Per layer leaves:
//   encoder: in_proj.weight [3D, D], in_proj.bias [N_tok, 3D] (positions folded into q, k),
//            out_proj.{weight,bias}, linear1.*, linear2.*, norm1.*, norm2.*
//   decoder layer 0: const_y [D] (its observation-independent self-attention block),
//            cross_q [T, D] (its constant cross-attention queries, projected)
//   decoder layer >= 1: in_proj.weight [3D, D], in_proj.bias [T, 3D], out_proj.* (self-attention,
//            named as in the encoder), cross_q_proj.weight [D, D], cross_q_proj.bias [T, D]
//   every decoder layer: cross_kv_proj.weight [2D, D], cross_kv_proj.bias [N_tok, 2D],
//            cross_out_proj.*, linear1.*, linear2.*, norm1..3.*
// The plain bias vector behind a per-token bias table that folds in the encoder positions (encoder
// in_proj, every decoder cross_kv_proj). INT8 blobs store it instead of the table, which the graph
// rebuilds at load from encoder.pos and the (quantized) weights: a table is N_tok x width floats.
inline std::string bias_vector(const std::string& table) { return table + "_vector"; }

inline const char* kEncoderNormWeight = "encoder.norm.weight";  // pre-norm only
inline const char* kEncoderNormBias = "encoder.norm.bias";
inline const char* kDecoderNormWeight = "decoder.norm.weight";
inline const char* kDecoderNormBias = "decoder.norm.bias";
inline const char* kHeadWeight = "head.weight";  // [A, D]
inline const char* kHeadBias = "head.bias";

}  // namespace act::blob_names
