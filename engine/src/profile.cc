// The per-op profiler behind EngineOptions::profile: sums of each op's time, and the last run as a
// Chrome trace. Graph::run records the raw times (graph::RunProfile); this turns them into the
// public OpProfile rows and the trace's JSON.
#include <nlohmann/json.hpp>

#include "engine/src/engine_impl.h"

namespace act {

void Engine::Impl::record_profile(std::chrono::steady_clock::time_point preprocess_start,
                                  std::chrono::steady_clock::time_point preprocess_end) {
  const graph::Graph& g = network_->graph();
  double stage_seconds[graph::kStageCount] = {};
  op_total_seconds_.resize(g.ops().size());
  for (size_t i = 0; i < g.ops().size(); ++i) {
    const double seconds = last_run_.op_seconds(i);
    stage_seconds[static_cast<int>(g.ops()[i]->stage)] += seconds;
    op_total_seconds_[i] += seconds;
  }
  ++profiled_runs_;
  const auto ms = [&](graph::Stage s) { return stage_seconds[static_cast<int>(s)] * 1e3; };
  timings_.preprocess_ms = std::chrono::duration<double, std::milli>(preprocess_end - preprocess_start).count();
  timings_.backbone_ms = ms(graph::Stage::kBackbone);
  timings_.encoder_ms = ms(graph::Stage::kEncoder);
  timings_.decoder_ms = ms(graph::Stage::kDecoder);
  timings_.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - preprocess_start).count();
  timings_.other_ms = timings_.total_ms - timings_.preprocess_ms - timings_.backbone_ms - timings_.encoder_ms - timings_.decoder_ms;
}

std::vector<OpProfile> Engine::Impl::op_profile() const {
  std::vector<OpProfile> rows;
  if (!profile_) return rows;
  const auto& ops = network_->graph().ops();
  rows.reserve(ops.size());
  for (size_t i = 0; i < ops.size(); ++i) {
    const graph::Op& op = *ops[i];
    rows.push_back({op.name, op.type(), op.kernel(kernels_), graph::stage_name(op.stage), op.macs(), profiled_runs_,
                    i < op_total_seconds_.size() ? op_total_seconds_[i] * 1e3 : 0.0});
  }
  return rows;
}

void Engine::Impl::reset_op_profile() {
  op_total_seconds_.assign(op_total_seconds_.size(), 0.0);
  profiled_runs_ = 0;
}

std::string Engine::Impl::chrome_trace() const {
  if (!profile_) fail(StatusCode::kFailedPrecondition, "chrome_trace: open the engine with EngineOptions::profile");
  if (!has_run_) fail(StatusCode::kFailedPrecondition, "chrome_trace: no inference has run yet");
  const auto& ops = network_->graph().ops();
  const auto origin = last_run_.op_start.front();
  const auto micros = [&](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::micro>(t - origin).count();
  };
  nlohmann::json events = nlohmann::json::array();
  const auto slice = [&](size_t op_index, int thread, std::chrono::steady_clock::time_point start,
                         std::chrono::steady_clock::time_point end) {
    const graph::Op& op = *ops[op_index];
    events.push_back({{"name", op.name}, {"cat", graph::stage_name(op.stage)}, {"ph", "X"}, {"pid", 1}, {"tid", thread},
                      {"ts", micros(start)}, {"dur", micros(end) - micros(start)},
                      {"args", {{"kind", op.type()}, {"kernel", op.kernel(kernels_)}, {"macs", op.macs()}}}});
  };
  // The calling thread's lane shows each op whole (its serial parts too); a worker's lane shows the
  // part of each parallel section it worked on.
  for (size_t i = 0; i < ops.size(); ++i) slice(i, 0, last_run_.op_start[i], last_run_.op_end[i]);
  for (size_t t = 1; t < last_run_.spans.by_thread.size(); ++t) {
    for (const ThreadSpan& span : last_run_.spans.by_thread[t]) {
      slice(static_cast<size_t>(span.tag), static_cast<int>(t), span.start, span.end);
    }
  }
  for (int t = 0; t < pool_.threads(); ++t) {
    events.push_back({{"name", "thread_name"}, {"ph", "M"}, {"pid", 1}, {"tid", t},
                      {"args", {{"name", t == 0 ? std::string("caller") : "worker " + std::to_string(t)}}}});
  }
  return nlohmann::json{{"traceEvents", events}, {"displayTimeUnit", "ms"}}.dump();
}

}  // namespace act
