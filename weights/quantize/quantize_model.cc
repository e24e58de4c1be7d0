#include "weights/quantize/quantize_model.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "actengine/status.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_names.h"

namespace act {

namespace bn = blob_names;

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

std::vector<std::string> quantizable_layers(const ImportedModel& model) {
  const std::set<std::string> always_float = {bn::kHeadWeight, bn::kStateProjWeight, bn::kEnvProjWeight};
  std::vector<std::string> out;
  for (const auto& t : model.tensors) {
    if (t.shape.size() >= 2 && ends_with(t.name, ".weight") && !always_float.count(t.name)) out.push_back(t.name);
  }
  return out;
}

void quantize_weight_per_row(const std::vector<float>& w, size_t rows, size_t cols, std::vector<int8_t>& q,
                             std::vector<float>& scales) {
  q.resize(rows * cols);
  scales.resize(rows);
  for (size_t r = 0; r < rows; ++r) {
    const float* wr = w.data() + r * cols;
    float absmax = 0.0f;
    for (size_t c = 0; c < cols; ++c) absmax = std::max(absmax, std::fabs(wr[c]));
    const float s = absmax > 0.0f ? absmax / 127.0f : 1.0f;
    scales[r] = s;
    for (size_t c = 0; c < cols; ++c) {
      q[r * cols + c] = static_cast<int8_t>(std::clamp(std::nearbyint(wr[c] / s), -127.0f, 127.0f));
    }
  }
}

ActbWriter int8_blob(const ImportedModel& model, const QuantConfig& quant) {
  const std::vector<std::string> layers = quantizable_layers(model);
  const std::set<std::string> quantize(layers.begin(), layers.end());
  for (const auto& name : quant.float_layers) {
    if (!quantize.count(name)) {
      fail(StatusCode::kInvalidArgument, "\"" + name + "\" is not a quantizable layer of this model (the layers are "
           "named by their weights, as the report's per-layer SQNR lists them, e.g. \"" + layers.front() + "\")");
    }
  }
  const std::set<std::string> keep_float(quant.float_layers.begin(), quant.float_layers.end());

  ActbWriter writer;
  writer.set_producer(std::string("act_convert (actengine) from a ") + model.layout + "-layout LeRobot checkpoint, int8 " +
                      quant_mode_name(quant.mode));
  ModelConfig int8_config = model.config;
  int8_config.precision = Precision::kInt8;
  nlohmann::json config = int8_config.to_json();
  config["quantization"] = quant.to_json();
  writer.set_config(config);
  // Tables with a bias vector behind them are rebuilt at load (blob_names.h: bias_vector).
  std::set<std::string> rebuilt_tables;
  for (const auto& t : model.tensors) {
    const std::string suffix = bn::bias_vector("");
    if (ends_with(t.name, suffix)) rebuilt_tables.insert(t.name.substr(0, t.name.size() - suffix.size()));
  }
  std::vector<int8_t> q;
  std::vector<float> scales;
  for (const auto& t : model.tensors) {
    if (rebuilt_tables.count(t.name)) continue;
    if (!quantize.count(t.name) || keep_float.count(t.name)) {
      writer.add_f32_ref(t.name, t.shape, t.values);
      continue;
    }
    const size_t rows = static_cast<size_t>(t.shape[0]);
    const size_t cols = t.values.size() / rows;
    quantize_weight_per_row(t.values, rows, cols, q, scales);
    QuantParams params;
    params.scales = scales;
    params.zero_points.assign(rows, 0);
    params.axis = 0;
    writer.add_tensor(t.name, DType::kI8, t.shape, q.data(), q.size(), params);
  }
  return writer;
}

size_t write_int8_blob(const ImportedModel& model, const QuantConfig& quant, const std::string& path) {
  return int8_blob(model, quant).write(path);
}

}  // namespace act
