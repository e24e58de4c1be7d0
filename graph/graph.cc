#include "graph/graph.h"

#include <algorithm>
#include <chrono>
#include <map>

#include "actengine/status.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/quant/quant_s8_variants.h"

namespace act::graph {

namespace {
constexpr size_t kAlignFloats = 16;  // 64 bytes
size_t align_up(size_t n) { return (n + kAlignFloats - 1) / kAlignFloats * kAlignFloats; }
// Arena units (4 bytes) a value occupies.
size_t value_units(const Value& v) {
  if (v.dtype != DataType::kS8 && v.dtype != DataType::kU8) return v.elements;
  return (v.elements + kernels::kGemmS8ReadSlack + 3) / 4;
}
}  // namespace

ValueId Graph::add_value(std::string name, std::vector<int64_t> shape, DataType dtype) {
  Value v;
  v.name = std::move(name);
  v.dtype = dtype;
  v.elements = 1;
  for (int64_t d : shape) v.elements *= static_cast<size_t>(d);
  v.shape = std::move(shape);
  values_.push_back(std::move(v));
  return static_cast<ValueId>(values_.size() - 1);
}

ValueId Graph::add_input(std::string name, std::vector<int64_t> shape, DataType dtype) {
  const ValueId id = add_value(std::move(name), std::move(shape), dtype);
  values_.back().pinned = true;
  return id;
}

ValueId Graph::add_row_view(std::string name, ValueId parent, int first_row, int rows) {
  const Value& p = value(parent);
  check(p.dtype == DataType::kF32 && p.shape.size() == 2 && p.view_of == kNoValue && first_row >= 0 && rows >= 0 &&
            first_row + rows <= p.shape[0],
        StatusCode::kInternal, "row view of \"" + p.name + "\": not rows of a float matrix");
  const int64_t cols = p.shape[1];
  const ValueId id = add_value(std::move(name), {rows, cols});
  values_.back().view_of = parent;
  values_.back().view_offset = static_cast<size_t>(first_row) * static_cast<size_t>(cols);
  return id;
}

void Graph::mark_output(ValueId id) { values_[static_cast<size_t>(id)].pinned = true; }

ValueId Graph::find(const std::string& name) const {
  for (size_t i = 0; i < values_.size(); ++i) {
    if (values_[i].name == name) return static_cast<ValueId>(i);
  }
  return kNoValue;
}

std::vector<float> Graph::read_f32(ValueId id) {
  const Value& v = value(id);
  std::vector<float> out;
  if (v.dtype == DataType::kF32) {
    const float* p = data(id);
    out.assign(p, p + v.elements);
  } else if (v.dtype == DataType::kS8 && v.quant) {
    out.resize(v.elements);
    kernels::quant_s8_table_ref()->dequantize(v.elements, data_s8(id), v.quant->scale, v.quant->zero_point, out.data());
  } else if (v.dtype == DataType::kU8 && v.quant) {
    // Back to the int8 codes they store (XOR 0x80 = code - 128), dequantized by the same rule.
    std::vector<int8_t> codes(data_s8(id), data_s8(id) + v.elements);
    for (int8_t& c : codes) c = static_cast<int8_t>(c ^ 0x80);
    out.resize(v.elements);
    kernels::quant_s8_table_ref()->dequantize(v.elements, codes.data(), v.quant->scale, v.quant->zero_point, out.data());
  }
  return out;
}

void RowCodes::write(const RunContext& ctx, const float* x, size_t ldx, int r0, int rows) const {
  const size_t row = static_cast<size_t>(r0), ldy = static_cast<size_t>(cols);
  int8_t* y = ctx.data_s8(codes) + row * ldy;
  const kernels::QuantS8Kernels& quant = ctx.kernels().quant;
  if (per_tensor()) {
    const float inv_scale = 1.0f / fixed->scale;
    for (size_t r = 0; r < static_cast<size_t>(rows); ++r) quant.quantize(ldy, x + r * ldx, inv_scale, fixed->zero_point, y + r * ldy);
    return;
  }
  kernels::quantize_rows_dynamic_f32_s8(quant, rows, cols, x, ldx, y, ldy, ctx.data(scale) + row, ctx.data_s32(zero_point) + row);
}

void Graph::plan(int threads, bool keep_all_values) {
  // Lifetimes.
  for (auto& v : values_) {
    v.first_use = v.last_use = -1;
    v.read = v.pinned || keep_all_values;
  }
  for (size_t i = 0; i < ops_.size(); ++i) {
    const int idx = static_cast<int>(i);
    for (ValueId in : ops_[i]->inputs) {
      values_[static_cast<size_t>(in)].last_use = idx;
      values_[static_cast<size_t>(in)].read = true;
    }
    for (ValueId out : ops_[i]->outputs) {
      Value& v = values_[static_cast<size_t>(out)];
      if (v.first_use < 0) v.first_use = idx;
      v.last_use = std::max(v.last_use, idx);
    }
  }
  // A view's uses are its parent's: the parent's memory holds the view's rows.
  for (Value& v : values_) {
    if (v.view_of == kNoValue) continue;
    Value& parent = values_[static_cast<size_t>(v.view_of)];
    if (v.first_use >= 0) parent.first_use = parent.first_use < 0 ? v.first_use : std::min(parent.first_use, v.first_use);
    parent.last_use = std::max(parent.last_use, v.last_use);
    parent.pinned = parent.pinned || v.pinned;
    parent.read = parent.read || v.read;
  }
  for (Value& v : values_) {
    if (v.view_of != kNoValue) v.read = v.read || values_[static_cast<size_t>(v.view_of)].read;
  }
  const int end = static_cast<int>(ops_.size());
  // Greedy placement, largest values first, each at the lowest offset that does not overlap a value
  // whose lifetime intersects its own.
  std::vector<size_t> order(values_.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return value_units(values_[a]) > value_units(values_[b]); });
  struct Placed {
    size_t begin, end;
    int first, last;
  };
  std::vector<Placed> placed;
  size_t total = 0;
  for (size_t i : order) {
    Value& v = values_[i];
    if (v.view_of != kNoValue) continue;  // placed with its parent
    const bool whole_run = v.pinned || keep_all_values;
    const int first = whole_run ? -1 : v.first_use;
    const int last = whole_run ? end : v.last_use;
    const size_t size = align_up(std::max<size_t>(value_units(v), 1));
    std::vector<std::pair<size_t, size_t>> busy;
    for (const auto& p : placed) {
      if (p.first <= last && first <= p.last) busy.emplace_back(p.begin, p.end);
    }
    std::sort(busy.begin(), busy.end());
    size_t offset = 0;
    for (const auto& [b, e] : busy) {
      if (offset + size <= b) break;
      offset = std::max(offset, e);
    }
    v.offset = offset;
    placed.push_back({offset, offset + size, first, last});
    total = std::max(total, offset + size);
  }
  for (Value& v : values_) {
    if (v.view_of != kNoValue) v.offset = values_[static_cast<size_t>(v.view_of)].offset + v.view_offset;
  }
  scratch_per_thread_ = 0;
  for (const auto& op : ops_) scratch_per_thread_ = std::max(scratch_per_thread_, align_up(op->scratch_per_thread()));
  scratch_offset_ = total;
  arena_floats_ = total + scratch_per_thread_ * static_cast<size_t>(std::max(threads, 1));
  arena_ = AlignedBuffer(arena_floats_ * sizeof(float));
  planned_ = true;
}

const char* stage_name(Stage stage) {
  switch (stage) {
    case Stage::kBackbone: return "backbone";
    case Stage::kEncoder: return "encoder";
    case Stage::kDecoder: return "decoder";
    case Stage::kOther: break;
  }
  return "other";
}

void Graph::run(ThreadPool& pool, const kernels::KernelConfig& kernels, RunProfile* profile) {
  check(planned_, StatusCode::kInternal, "Graph::run before plan");
  check(arena_floats_ >= scratch_offset_ + scratch_per_thread_ * static_cast<size_t>(pool.threads()), StatusCode::kInternal,
        "graph planned for fewer threads than the pool has");
  RunContext ctx(arena_.floats(), values_, pool, kernels, arena_.floats() + scratch_offset_, scratch_per_thread_);
  if (profile == nullptr) {
    for (const auto& op : ops_) op->run(ctx);
    return;
  }
  profile->op_start.resize(ops_.size());
  profile->op_end.resize(ops_.size());
  for (auto& spans : profile->spans.by_thread) spans.clear();
  pool.record_spans(&profile->spans);
  struct StopRecording {
    ThreadPool& pool;
    ~StopRecording() { pool.record_spans(nullptr); }  // also when an op throws
  } stop_recording{pool};
  for (size_t i = 0; i < ops_.size(); ++i) {
    profile->spans.tag = static_cast<int>(i);
    profile->op_start[i] = std::chrono::steady_clock::now();
    ops_[i]->run(ctx);
    profile->op_end[i] = std::chrono::steady_clock::now();
  }
}

}  // namespace act::graph
