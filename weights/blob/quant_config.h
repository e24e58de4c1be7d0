// How an INT8 blob was quantized: the "quantization" object of the blob's config. Written by
// act_convert, read by the graph builder.
//
//   {"mode": "dynamic" | "static" | "mixed",
//    "calibration": "minmax" | "percentile" | "mse" | "",       (static and mixed)
//    "activations": {"<value name>": [scale, zero_point], ...},  (static and mixed: every backbone
//                                                                 value, and the transformer's linear
//                                                                 inputs read as per-tensor codes)
//    "float_layers": ["<weight name>", ...],                     (layers kept in FP32)
//    "attention": "int8" | "fp32"}                                (QK^T and PV; absent: fp32)
//
// Which layers are int8 is also visible in the tensors themselves (dtype I8 with per-channel
// scales); float_layers records the converter's choice for reports.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace act {

/// The largest activation scale a blob may hold (a value range of 2.55e8; the converter's come from
/// calibration, kernels/quant's choose_quant_s8, and are at least FLT_MIN).
inline constexpr float kMaxActivationScale = 1e6f;

struct ActivationQuant {
  float scale = 1.0f;
  int32_t zero_point = 0;
};

enum class QuantMode { kDynamic, kStatic, kMixed };
const char* quant_mode_name(QuantMode mode);

struct QuantConfig {
  QuantMode mode = QuantMode::kDynamic;
  std::string calibration;
  std::map<std::string, ActivationQuant> activations;
  std::vector<std::string> float_layers;
  /// Attention's two matmuls (Q K^T, P V) on the int8 GEMM; the converter sets it when the held-out
  /// error allows (blobs written before it existed keep float attention).
  bool int8_attention = false;

  /// True when activations between int8 backbone layers stay int8 (static and mixed).
  bool static_activations() const { return mode != QuantMode::kDynamic; }
  /// The parameters of a value; throws kDataLoss naming it when the blob has none.
  const ActivationQuant& activation(const std::string& value_name) const;

  nlohmann::json to_json() const;
  /// Throws act::Error(kDataLoss) on a malformed object (bad mode, a scale outside [FLT_MIN,
  /// kMaxActivationScale], a zero point outside [-128, 127], ...), naming the activation.
  static QuantConfig from_json(const nlohmann::json& j);
};

}  // namespace act
