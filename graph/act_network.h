// The ACT network (spec §4) built as a graph of FP32 ops from a ModelConfig and the tensors of an
// .actb blob. Inputs are normalised: one NHWC float image per camera, the state vectors. Output: the
// normalised action chunk [chunk_size, action_dim]. Weight pointers point into the blob's mapping.
#pragma once

#include <string>
#include <vector>

#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "weights/actb.h"
#include "weights/model_config.h"

namespace act::graph {

class ActNetwork {
 public:
  /// Builds the graph. Throws act::Error(kDataLoss) when a blob tensor is missing or has a shape
  /// that does not match the config.
  ActNetwork(const ModelConfig& config, const ActbFile& blob);

  void plan(int threads, bool keep_all_values) { graph_.plan(threads, keep_all_values); }
  void run(ThreadPool& pool, StageTimes* times = nullptr) { graph_.run(pool, times); }

  float* camera_input(size_t camera) { return graph_.data(camera_inputs_.at(camera)); }  ///< [H, W, 3]
  float* state_input() { return graph_.data(state_input_); }                          ///< [state_dim]
  float* env_state_input() { return graph_.data(env_input_); }                        ///< [env_state_dim]
  const float* actions_normalized() { return graph_.data(actions_); }                 ///< [T, A]

  Graph& graph() { return graph_; }
  const ModelConfig& config() const { return config_; }

 private:
  const float* weight(const std::string& name, const std::vector<int64_t>& shape) const;
  /// Appends an op to the graph, named and tagged with the stage being built.
  void add(std::unique_ptr<Op> op, const std::string& name);
  ValueId backbone(size_t camera);
  /// [LayerNorm1 (pre-norm)] -> fused qkv projection -> attention -> out projection + residual x
  /// [-> LayerNorm1 (post-norm)]. Weights under `w` ("in_proj.*", "out_proj.*", "norm1.*").
  ValueId self_attention_block(const std::string& prefix, int rows, ValueId x, const std::string& w);
  ValueId encoder_layer(int layer, ValueId x);
  ValueId decoder_layer(int layer, ValueId y, ValueId memory);
  ValueId ffn(const std::string& prefix, int rows, ValueId x, ValueId residual, const std::string& out_name);
  ValueId linear(const std::string& out_name, int rows, int in, int out, MatrixRef x, const std::string& weight_name,
                 MatrixRef bias, MatrixRef residual = {}, Epilogue epilogue = Epilogue::kNone);
  ValueId layernorm(const std::string& out_name, int rows, ValueId x, const std::string& weight_prefix);
  ValueId attention(const std::string& out_name, int nq, int nk, MatrixRef q, MatrixRef k, MatrixRef v);

  ModelConfig config_;
  const ActbFile& blob_;
  Graph graph_;
  std::vector<ValueId> camera_inputs_;
  ValueId state_input_ = kNoValue;
  ValueId env_input_ = kNoValue;
  ValueId actions_ = kNoValue;
  Stage stage_ = Stage::kOther;  // the stage the builder is in (state tokens count as "other")
};

}  // namespace act::graph
