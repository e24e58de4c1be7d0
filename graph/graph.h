// The network as a list of typed ops over planned buffers.
//
// Values are tensors (float32, int8 or int32) that live in one arena. plan() gives every value an arena offset from its
// lifetime (first writer .. last reader), reusing memory of values that are dead, and sizes the
// per-thread scratch the ops asked for; after plan() nothing is allocated again, however many times
// run() is called. With keep_all_values every value gets its own memory, so tests can read every
// intermediate after a run.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "graph/aligned_buffer.h"
#include "graph/thread_pool.h"
#include "kernels/config/kernel_config.h"
#include "kernels/quant/quant_s8.h"

namespace act::graph {

using ValueId = int;
inline constexpr ValueId kNoValue = -1;

/// kU8 holds int8 codes stored unsigned (each code XOR 0x80 = code + 128) for kernels whose
/// activations are unsigned (kernels::GemmS8Kernels::pack_u8a): the static INT8 stem's image.
enum class DataType { kF32, kS8, kU8, kS32 };

struct Value {
  std::string name;
  std::vector<int64_t> shape;
  DataType dtype = DataType::kF32;
  /// int8 values with static quantization: their scale and zero point (for dequantizing them in
  /// reports and tests; the ops hold their own copies). A kU8 value's are those of its codes.
  std::optional<kernels::QuantS8> quant;
  size_t elements = 0;
  size_t offset = 0;   ///< in floats (4-byte units), into the arena (valid after plan())
  int first_use = -1;  ///< op index that writes it (-1: a graph input)
  int last_use = -1;   ///< last op index that reads it
  bool pinned = false; ///< inputs and outputs: alive for the whole run
  /// False when no op reads it and it is neither pinned nor kept (plan()): its producer may leave it
  /// unwritten (an int8 linear whose consumers read only its row codes).
  bool read = true;
  /// A row view (Graph::add_row_view): no memory of its own, its rows those of view_of from
  /// view_offset floats on.
  ValueId view_of = kNoValue;
  size_t view_offset = 0;
};

/// What an op sees when it runs: the arena, the pool, per-thread scratch and the kernels to call (the
/// Engine's one KernelConfig; ops never choose kernels themselves).
class RunContext {
 public:
  RunContext(float* arena, const std::vector<Value>& values, ThreadPool& pool, const kernels::KernelConfig& kernels,
             float* scratch, size_t scratch_per_thread)
      : arena_(arena), values_(values), pool_(pool), kernels_(kernels), scratch_(scratch),
        scratch_per_thread_(scratch_per_thread) {}
  float* data(ValueId id) const { return arena_ + values_[static_cast<size_t>(id)].offset; }
  int8_t* data_s8(ValueId id) const { return reinterpret_cast<int8_t*>(data(id)); }
  int32_t* data_s32(ValueId id) const { return reinterpret_cast<int32_t*>(data(id)); }
  bool read(ValueId id) const { return values_[static_cast<size_t>(id)].read; }
  ThreadPool& pool() const { return pool_; }
  const kernels::KernelConfig& kernels() const { return kernels_; }
  float* scratch(int thread) const { return scratch_ + static_cast<size_t>(thread) * scratch_per_thread_; }
  int8_t* scratch_s8(int thread) const { return reinterpret_cast<int8_t*>(scratch(thread)); }

 private:
  float* arena_;
  const std::vector<Value>& values_;
  ThreadPool& pool_;
  const kernels::KernelConfig& kernels_;
  float* scratch_;
  size_t scratch_per_thread_;
};

/// A read-only matrix operand: a graph value or a constant (weights in the blob), with a column offset
/// and a leading dimension. ld == 0 broadcasts one row to every row.
struct MatrixRef {
  ValueId value = kNoValue;
  const float* constant = nullptr;
  size_t col_offset = 0;
  size_t ld = 0;
  const float* resolve(const RunContext& ctx) const {
    return (value == kNoValue ? constant : ctx.data(value)) + col_offset;
  }
  static MatrixRef of(ValueId v, size_t ld, size_t col_offset = 0) { return {v, nullptr, col_offset, ld}; }
  static MatrixRef of_constant(const float* p, size_t ld) { return {kNoValue, p, 0, ld}; }
};

/// The int8 codes of a float matrix [rows, cols] that int8 linears read, written by the op that
/// produces the matrix while its rows are in cache (LayerNorm, an int8 linear), so that the linears
/// reading it skip a quantization pass. Two kinds:
///   per token  (dynamic) each row's parameters from its own range, exactly as
///              quantize_rows_dynamic_f32_s8 makes them, into `scale` and `zero_point` [rows];
///   per tensor (static)  the calibrated parameters `fixed` for every row (no scale values: the
///              readers take `fixed`), one pass with no range to find.
struct RowCodes {
  ValueId codes = kNoValue;       ///< int8 [rows, cols]
  ValueId scale = kNoValue;       ///< float [rows] (per token only)
  ValueId zero_point = kNoValue;  ///< int32 [rows] (per token only)
  int cols = 0;
  std::optional<kernels::QuantS8> fixed;  ///< per tensor: the calibrated parameters
  bool present() const { return codes != kNoValue; }
  bool per_tensor() const { return fixed.has_value(); }
  std::vector<ValueId> values() const {
    return per_tensor() ? std::vector<ValueId>{codes} : std::vector<ValueId>{codes, scale, zero_point};
  }
  /// Quantizes `rows` rows of x (leading dimension ldx) into their rows r0, r0 + 1, ...
  void write(const RunContext& ctx, const float* x, size_t ldx, int r0, int rows) const;
};

/// An op that can write RowCodes of its float output beside it (the graph builder asks for them
/// when an int8 linear reads that output).
class RowCodesWriter {
 public:
  virtual ~RowCodesWriter() = default;
  /// From now on every run also writes `codes` (adds them to the op's outputs).
  virtual void write_row_codes(const RowCodes& codes) = 0;
};

/// The part of the network an op belongs to, for per-stage timing.
enum class Stage { kOther, kBackbone, kEncoder, kDecoder };
inline constexpr int kStageCount = 4;

/// What Graph::run records of one run when profiling: when each op started and ended on the calling
/// thread, and each thread's span of every parallel section (tagged with the op's index). Reused
/// run after run, so recording allocates nothing once the lists have grown.
struct RunProfile {
  std::vector<std::chrono::steady_clock::time_point> op_start, op_end;
  ThreadSpans spans;
  double op_seconds(size_t op) const { return std::chrono::duration<double>(op_end[op] - op_start[op]).count(); }
};
const char* stage_name(Stage stage);

class Op {
 public:
  virtual ~Op() = default;
  virtual const char* type() const = 0;
  virtual void run(const RunContext& ctx) const = 0;
  /// Floats (4-byte units) of scratch each thread needs while this op runs.
  virtual size_t scratch_per_thread() const { return 0; }
  /// Multiply-accumulates of one run (for profiling and the benchmark's GMAC/s).
  virtual double macs() const { return 0.0; }
  /// The kernel variant this op calls under `kernels`, e.g. "gemm_s8_s8out_6x64c4_avx512vnni" (for
  /// the profiler: which code the time went to).
  virtual std::string kernel(const kernels::KernelConfig& kernels) const = 0;

  std::string name;
  Stage stage = Stage::kOther;
  std::vector<ValueId> inputs;
  std::vector<ValueId> outputs;
};

class Graph {
 public:
  /// int8 values get kGemmS8ReadSlack addressable bytes after their last element (kernels over-read).
  ValueId add_value(std::string name, std::vector<int64_t> shape, DataType dtype = DataType::kF32);
  /// A value the caller writes before run() (pinned).
  ValueId add_input(std::string name, std::vector<int64_t> shape, DataType dtype = DataType::kF32);
  /// Rows [first_row, first_row + rows) of the float matrix `parent`, as a value of their own: its
  /// producer writes them in place (the image projection straight into the encoder's tokens, no
  /// copy). The parent lives while any of its views does.
  ValueId add_row_view(std::string name, ValueId parent, int first_row, int rows);
  /// Keeps a value alive to the end of the run so the caller can read it.
  void mark_output(ValueId id);
  /// Appends an op; its inputs/outputs must already be set.
  template <typename OpT>
  OpT& add_op(std::unique_ptr<OpT> op) {
    OpT& ref = *op;
    ops_.push_back(std::move(op));
    return ref;
  }

  void plan(int threads, bool keep_all_values);
  /// Runs every op in order with `kernels` (the configuration int8 weights were packed for). With
  /// `profile`, records when each op ran (and on which threads).
  void run(ThreadPool& pool, const kernels::KernelConfig& kernels, RunProfile* profile = nullptr);

  float* data(ValueId id) { return arena_.floats() + values_[static_cast<size_t>(id)].offset; }
  int8_t* data_s8(ValueId id) { return reinterpret_cast<int8_t*>(data(id)); }
  Value& value(ValueId id) { return values_[static_cast<size_t>(id)]; }
  /// The value as floats: a copy of an f32 value, or an int8 value dequantized with its static
  /// parameters by the reference kernel (every variant gives its bits); empty when it has none, or
  /// for int32 values.
  std::vector<float> read_f32(ValueId id);
  const Value& value(ValueId id) const { return values_[static_cast<size_t>(id)]; }
  size_t value_count() const { return values_.size(); }
  /// The value of that name, or kNoValue.
  ValueId find(const std::string& name) const;
  const std::vector<std::unique_ptr<Op>>& ops() const { return ops_; }
  size_t arena_bytes() const { return arena_floats_ * sizeof(float); }

 private:
  std::vector<Value> values_;
  std::vector<std::unique_ptr<Op>> ops_;
  AlignedBuffer arena_;  // floats: values, then per-thread scratch
  size_t arena_floats_ = 0;
  size_t scratch_offset_ = 0;
  size_t scratch_per_thread_ = 0;
  bool planned_ = false;
};

}  // namespace act::graph
