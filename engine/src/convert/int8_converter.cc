#include "engine/src/convert/int8_converter.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <span>
#include <tuple>
#include <utility>

#include "actengine/status.h"
#include "engine/src/convert/calibration_frames.h"
#include "engine/src/engine_impl.h"
#include "weights/blob/file_util.h"
#include "weights/quantize/activation_ranges.h"
#include "kernels/quant/quant_s8.h"
#include "weights/quantize/quantize_model.h"

namespace act {

namespace {

// A blob in an unnamed file beside the output (same file system, so commit() can give it the
// output's name atomically). An Engine opens it through /proc/self/fd/N; dropped without commit()
// it leaves nothing, even when the process is killed.
class ScratchBlob {
 public:
  // Written without its checksum (its Engine does not read it back, scratch_engine_options): most
  // trials' blobs are dropped, and the one that is kept gets it at commit().
  ScratchBlob(const ActbWriter& blob, const std::string& output) : file_(output) {
    blob.write_to(file_, ActbWriter::Checksum::kLater);
  }
  std::string path() const { return file_.readable_path(); }
  uint64_t bytes() const { return file_.bytes_written(); }
  void commit() {
    seal_actb_checksum(file_);
    file_.commit();
  }

 private:
  detail::AtomicFileWriter file_;
};

QuantMode quant_mode(Int8Mode mode) {
  switch (mode) {
    case Int8Mode::kDynamic: return QuantMode::kDynamic;
    case Int8Mode::kStatic: return QuantMode::kStatic;
    case Int8Mode::kMixed: return QuantMode::kMixed;
  }
  fail(StatusCode::kInvalidArgument, "unknown INT8 mode");
}

// The FP32 model's chunks on the evaluation frames, computed once.
struct Reference {
  std::vector<std::vector<float>> normalized, raw;
};

// The held-out frames when none is asked for: one per four calibration frames, 1 to 16.
size_t default_holdout(size_t calibration_frames) { return std::clamp<size_t>(calibration_frames / 4, 1, 16); }

double sqnr_db(double signal, double noise) { return noise > 0 ? 10.0 * std::log10(signal / noise) : 200.0; }

// The rounding noise of per-token codes of [rows, cols] matrices: each row quantized with the
// parameters of its own range (choose_quant_s8, as the kernels do) has uniform rounding error of
// its step, step^2 / 12 per value.
struct PerTokenNoise {
  double signal = 0, noise = 0;
  size_t count = 0;
  void observe(const float* x, const std::vector<int64_t>& shape) {
    const size_t rows = static_cast<size_t>(shape.at(0)), cols = static_cast<size_t>(shape.at(1));
    for (size_t r = 0; r < rows; ++r) {
      const float* row = x + r * cols;
      float lo = 0.0f, hi = 0.0f;
      for (size_t c = 0; c < cols; ++c) {
        if (!std::isfinite(row[c])) continue;
        lo = std::min(lo, row[c]);
        hi = std::max(hi, row[c]);
        signal += static_cast<double>(row[c]) * row[c];
      }
      const double step = kernels::choose_quant_s8(lo, hi).scale;
      noise += step * step / 12.0 * static_cast<double>(cols);
    }
    count += rows * cols;
  }
  double sqnr_db() const { return act::sqnr_db(signal, noise); }
};

class Converter {
 public:
  Converter(const ImportedModel& model, const std::string& output, const Int8Options& options)
      : model_(model), output_(output), opt_(options), states_(model, options.seed) {}

  Int8Report run(const CalibrationSet& calibration) {
    const auto t0 = std::chrono::steady_clock::now();
    if (opt_.mode == Int8Mode::kMixed && !opt_.target_mse) {
      fail(StatusCode::kInvalidArgument, "mixed mode needs a target MSE (held-out, normalised units)");
    }
    if (opt_.mode == Int8Mode::kDynamic && opt_.linear_inputs != LinearInputCodes::kAuto) {
      fail(StatusCode::kInvalidArgument,
           "linear_inputs needs calibration (static or mixed mode): dynamic mode's linear "
           "inputs are all per token, with no calibrated ranges for per-tensor codes");
    }
    if (!(opt_.percentile >= 50.0 && opt_.percentile <= 100.0)) {
      fail(StatusCode::kInvalidArgument, "percentile " + format_number(opt_.percentile) + " is outside [50, 100]");
    }
    if (opt_.calib_samples == 0) fail(StatusCode::kInvalidArgument, "calib_samples must be at least 1");
    choose_frames(calibration);
    const ScratchBlob fp32(fp32_blob(model_), output_);
    fp32_ = std::make_unique<Engine::Impl>(fp32.path(), scratch_engine_options(true));
    compute_reference();

    QuantConfig quant;
    quant.mode = quant_mode(opt_.mode);
    quant.float_layers = opt_.keep_float;
    if (opt_.mode != Int8Mode::kDynamic) {
      quant.calibration = calibration_method_name(opt_.method);
      quant.activations = calibrate();
    }
    auto [blob, err] = write_and_evaluate(quant);
    std::vector<LayerSensitivity> sensitivity;
    if (opt_.mode == Int8Mode::kMixed) choose_float_layers(quant, blob, err, sensitivity);
    choose_linear_input_codes(quant, blob, err);
    choose_attention(quant, blob, err);

    Int8Report r = report(quant, *blob, err, std::move(sensitivity), fp32.bytes());
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (opt_.max_mse && !(err.mse <= *opt_.max_mse)) {
      fail(StatusCode::kFailedPrecondition,
           "the INT8 model misses the maximum held-out MSE: " + format_number(err.mse) + " > " +
               format_number(*opt_.max_mse) + " (normalised units); nothing was written.\n" + r.to_text());
    }
    blob->commit();
    return r;
  }

 private:
  // An Engine over one of this conversion's own scratch blobs: an unnamed file that it has just
  // written and that nothing else can open, so its pages are shared rather than copied and its
  // checksum is not read back (a mixed search opens dozens of them: copying and checking act-tiny's
  // 45 MB each time made its search take 20 s instead of 12). The int8 ones share the FP32 engine's
  // packed float weights: every blob here is written from model_, a float tensor under its own name.
  EngineOptions scratch_engine_options(bool keep_intermediates) const {
    EngineOptions eo;
    eo.threads = opt_.threads;
    eo.keep_intermediates = keep_intermediates;
    eo.share_blob_pages = true;
    eo.verify_checksum = false;
    return eo;
  }

  void progress(const std::string& message) const {
    if (opt_.progress) opt_.progress({message, 0, 0, ""});
  }
  void progress(const std::string& task, size_t done, size_t total, const char* unit) const {
    if (opt_.progress) opt_.progress({task, done, total, unit});
  }

  void choose_frames(const CalibrationSet& given) {
    if (!given.frames.empty()) {
      frames_ = given;
    } else if (opt_.mode == Int8Mode::kDynamic) {
      frames_ = synthetic_calibration_frames(states_, opt_.holdout.value_or(8), opt_.seed);
    } else {
      fail(StatusCode::kInvalidArgument, std::string(int8_mode_name(opt_.mode)) +
           " quantization needs calibration frames (dynamic mode needs none)");
    }
    complete_calibration_frames(frames_, states_);
    const size_t n = frames_.frames.size();
    // Held-out frames interleaved through the set, so both sets cover all of it.
    size_t holdout = opt_.holdout.value_or(n >= 2 ? default_holdout(n - n / 5) : 0);  // about a fifth
    holdout = std::min(holdout, n - 1);
    const size_t stride = holdout ? n / holdout : 0;
    for (size_t i = 0; i < n; ++i) {
      const bool held = holdout && i % stride == stride - 1 && eval_.size() < holdout;
      if (held) {
        eval_.push_back(i);
      } else if (calib_.size() < opt_.calib_samples) {
        calib_.push_back(i);
      }
    }
    if (eval_.empty()) {
      eval_ = calib_;
      frames_.notes.push_back("only one frame: the accuracy below is measured on the calibration frame itself");
    }
    if (!given.frames.empty() && calib_.size() < opt_.calib_samples) {
      frames_.notes.push_back("calibrated on " + std::to_string(calib_.size()) + " frames, fewer than the " +
                              std::to_string(opt_.calib_samples) + " asked: the calibration set holds " + std::to_string(n) +
                              " frames and " + std::to_string(eval_.size()) + " of them are held out for the accuracy report");
    }
    progress(std::to_string(calib_.size()) + " calibration frames, " + std::to_string(eval_.size()) + " held out");
  }

  Observation obs(size_t i) const { return calibration_observation(frames_.frames[i], fp32_->config()); }
  size_t chunk_values() const { return fp32_->info().chunk_values(); }

  void compute_reference() {
    for (size_t i : eval_) {
      std::vector<float> norm(chunk_values()), raw(chunk_values());
      fp32_->run(obs(i), norm);
      fp32_->unnormalize(norm, raw, static_cast<size_t>(fp32_->config().chunk_size));
      ref_.normalized.push_back(std::move(norm));
      ref_.raw.push_back(std::move(raw));
    }
  }

  ActivationQuant choose(const RangeObserver& observer, graph::CalibrationRole role) const {
    // The input image's range is known exactly: never clip it.
    if (role == graph::CalibrationRole::kCameraImage) return observer.choose_minmax();
    switch (opt_.method) {
      case CalibrationMethod::kMinMax: return observer.choose_minmax();
      case CalibrationMethod::kPercentile: return observer.choose_percentile(opt_.percentile);
      case CalibrationMethod::kMse: return observer.choose_mse();
    }
    fail(StatusCode::kInvalidArgument, "unknown calibration method");
  }

  // The calibration points' ranges over the calibration frames -> the backbone's parameters, by
  // value name; the transformer's linear inputs become candidates for per-tensor codes
  // (linear_inputs_), each with its estimated SQNR per tensor and per token.
  std::map<std::string, ActivationQuant> calibrate() {
    graph::ActNetwork& network = fp32_->network();
    graph::Graph& g = network.graph();
    const std::vector<graph::CalibrationPoint>& points = network.calibration_points();
    std::vector<RangeObserver> observers(points.size());
    std::vector<PerTokenNoise> per_token(points.size());
    std::vector<float> normalized(chunk_values());
    // One pass: each observer keeps its range and its histogram together.
    const std::string task = "calibrating (" + std::string(calibration_method_name(opt_.method)) + ")";
    progress(task, 0, calib_.size(), "frames");
    for (size_t f = 0; f < calib_.size(); ++f) {
      fp32_->run(obs(calib_[f]), normalized);
      for (size_t k = 0; k < points.size(); ++k) {
        const graph::Value& v = g.value(points[k].value);
        observers[k].observe(std::span<const float>(g.data(points[k].value), v.elements));
        if (points[k].role == graph::CalibrationRole::kLinearInput) per_token[k].observe(g.data(points[k].value), v.shape);
      }
      progress(task, f + 1, calib_.size(), "frames");
    }
    std::map<std::string, ActivationQuant> out;
    for (size_t k = 0; k < points.size(); ++k) {
      const std::string& name = g.value(points[k].value).name;
      const ActivationQuant q = choose(observers[k], points[k].role);
      if (points[k].role == graph::CalibrationRole::kLinearInput) {
        const double per_value = per_token[k].signal / static_cast<double>(std::max<size_t>(1, per_token[k].count));
        linear_inputs_.push_back({{name, points[k].reader, points[k].ffn, false, q.scale, q.zero_point,
                                   sqnr_db(per_value, observers[k].expected_squared_error(q)), per_token[k].sqnr_db()},
                                  {name, q.scale, q.zero_point, observers[k].min(), observers[k].max()}});
        continue;
      }
      out[name] = q;
      activations_.push_back({name, q.scale, q.zero_point, observers[k].min(), observers[k].max()});
    }
    return out;
  }

  ActionError evaluate(const std::string& blob_path) {
    Engine::Impl int8(blob_path, scratch_engine_options(false), fp32_.get());
    const size_t T = static_cast<size_t>(fp32_->config().chunk_size), A = static_cast<size_t>(fp32_->config().action_dim);
    ActionError e;
    e.per_dim_mse.assign(A, 0.0);
    e.per_dim_max_abs.assign(A, 0.0);
    e.per_dim_mse_physical.assign(A, 0.0);
    e.per_dim_max_abs_physical.assign(A, 0.0);
    std::vector<float> norm(chunk_values()), raw(chunk_values());
    for (size_t f = 0; f < eval_.size(); ++f) {
      int8.run(obs(eval_[f]), norm);
      int8.unnormalize(norm, raw, T);
      for (size_t i = 0; i < norm.size(); ++i) {
        const double d = static_cast<double>(norm[i]) - ref_.normalized[f][i];
        const double dr = static_cast<double>(raw[i]) - ref_.raw[f][i];
        const size_t a = i % A;
        e.per_dim_mse[a] += d * d;
        e.per_dim_max_abs[a] = std::max(e.per_dim_max_abs[a], std::fabs(d));
        e.per_dim_mse_physical[a] += dr * dr;
        e.per_dim_max_abs_physical[a] = std::max(e.per_dim_max_abs_physical[a], std::fabs(dr));
        if (!std::isfinite(d)) e.per_dim_mse[a] = INFINITY;
      }
    }
    const double per_dim = static_cast<double>(eval_.size() * T);
    for (size_t a = 0; a < A; ++a) {
      e.per_dim_mse[a] /= per_dim;
      e.per_dim_mse_physical[a] /= per_dim;
      e.mse += e.per_dim_mse[a] / static_cast<double>(A);
      e.mse_physical += e.per_dim_mse_physical[a] / static_cast<double>(A);
      e.max_abs = std::max(e.max_abs, e.per_dim_max_abs[a]);
      e.max_abs_physical = std::max(e.max_abs_physical, e.per_dim_max_abs_physical[a]);
    }
    return e;
  }

  std::pair<std::unique_ptr<ScratchBlob>, ActionError> write_and_evaluate(const QuantConfig& quant) {
    auto blob = std::make_unique<ScratchBlob>(int8_blob(model_, quant), output_);
    const ActionError e = evaluate(blob->path());
    return {std::move(blob), e};
  }

  // Mixed: the fewest float layers (most sensitive first) that meet the target.
  void choose_float_layers(QuantConfig& quant, std::unique_ptr<ScratchBlob>& blob, ActionError& err,
                           std::vector<LayerSensitivity>& sensitivity) {
    const double target = *opt_.target_mse;
    progress("all layers int8: held-out MSE " + format_number(err.mse) + " (target " + format_number(target) + ")");
    if (err.mse <= target) return;
    // The layers asked to stay float (Int8Options::keep_float) are already in quant.float_layers.
    std::vector<std::string> layers;
    for (const auto& l : quantizable_layers(model_)) {
      if (std::find(quant.float_layers.begin(), quant.float_layers.end(), l) == quant.float_layers.end()) layers.push_back(l);
    }
    const std::string task = "sensitivity search (one layer in int8 at a time)";
    progress(task, 0, layers.size(), "layers");
    for (size_t i = 0; i < layers.size(); ++i) {
      QuantConfig one = quant;
      for (const auto& l : layers) {
        if (l != layers[i]) one.float_layers.push_back(l);
      }
      const double mse = write_and_evaluate(one).second.mse;
      sensitivity.push_back({layers[i], mse});
      progress(task, i + 1, layers.size(), "layers");
    }
    std::stable_sort(sensitivity.begin(), sensitivity.end(),
                     [](const auto& a, const auto& b) { return a.mse_alone_int8 > b.mse_alone_int8; });
    // Smallest prefix of the most sensitive layers whose return to float meets the target (binary
    // search: the error shrinks as layers go back to float; all of them in float is the FP32 model).
    const auto try_prefix = [&](size_t count) {
      QuantConfig q = quant;
      for (size_t i = 0; i < count; ++i) q.float_layers.push_back(sensitivity[i].layer);
      auto [candidate, e] = write_and_evaluate(q);
      progress(std::to_string(count) + " most sensitive layers in float -> MSE " + format_number(e.mse));
      return std::tuple{q, std::move(candidate), e};
    };
    auto [best, best_blob, best_err] = try_prefix(layers.size());
    if (!(best_err.mse <= target)) {
      fail(StatusCode::kFailedPrecondition, "the target MSE " + format_number(target) +
           " cannot be met: even with every layer in float the held-out MSE is " + format_number(best_err.mse));
    }
    size_t lo = 1, hi = layers.size();
    while (lo < hi) {
      const size_t mid = (lo + hi) / 2;
      auto [q, candidate, e] = try_prefix(mid);
      if (e.mse <= target) {
        hi = mid;
        best = std::move(q);
        best_blob = std::move(candidate);
        best_err = e;
      } else {
        lo = mid + 1;
      }
    }
    quant = std::move(best);
    blob = std::move(best_blob);
    err = best_err;
  }

  // Per-tensor codes for the transformer's linear inputs (Int8Options::linear_inputs), tried for the
  // FFNs' hidden activations (what lets a hidden layer requantize), those whose codes lose least
  // first (estimated SQNR); the longest prefix of them that keeps the held-out error within the
  // budget (binary search, as the mixed search: the error grows as more inputs go per tensor).
  void choose_linear_input_codes(QuantConfig& quant, std::unique_ptr<ScratchBlob>& blob, ActionError& err) {
    const std::vector<std::string> quantizable = quantizable_layers(model_);
    // Only the inputs of int8 linears matter.
    std::erase_if(linear_inputs_, [&](const LinearInput& l) {
      return std::find(quantizable.begin(), quantizable.end(), l.choice.reader) == quantizable.end() ||
             std::find(quant.float_layers.begin(), quant.float_layers.end(), l.choice.reader) != quant.float_layers.end();
    });
    std::vector<size_t> ffns;  // the candidates, least SQNR lost first
    for (size_t i = 0; i < linear_inputs_.size(); ++i) {
      if (linear_inputs_[i].choice.ffn >= 0) ffns.push_back(i);
    }
    const auto loss = [&](size_t i) {
      return linear_inputs_[i].choice.sqnr_per_token_db - linear_inputs_[i].choice.sqnr_per_tensor_db;
    };
    std::stable_sort(ffns.begin(), ffns.end(), [&](size_t a, size_t b) { return loss(a) < loss(b); });
    if (ffns.empty() || opt_.linear_inputs == LinearInputCodes::kPerToken) return;
    const auto with_first = [&](size_t count) {
      QuantConfig q = quant;
      for (size_t f = 0; f < count; ++f) {
        const LinearInputChoice& c = linear_inputs_[ffns[f]].choice;
        q.activations[c.value] = {c.scale, c.zero_point};
      }
      return q;
    };
    const ActionError base = err;
    const auto within_budget = [&](const ActionError& e) {
      return e.mse <= (1.0 + kPerTensorCodesErrorBudget) * base.mse &&
             e.max_abs <= (1.0 + kPerTensorCodesMaxErrorBudget) * base.max_abs && meets_mixed_target(e);
    };
    const auto try_count = [&](size_t count) {
      auto [candidate, e] = write_and_evaluate(with_first(count));
      progress(std::to_string(count) + " of " + std::to_string(ffns.size()) + " FFNs with per-tensor codes: held-out MSE " +
               format_number(e.mse) + ", max |err| " + format_number(e.max_abs) + " (all per token: " + format_number(base.mse) +
               ", " + format_number(base.max_abs) + ")");
      return std::pair{std::move(candidate), e};
    };
    size_t chosen = 0;
    auto [all_blob, all_err] = try_count(ffns.size());
    if (opt_.linear_inputs == LinearInputCodes::kPerTensor || within_budget(all_err)) {
      chosen = ffns.size();
      blob = std::move(all_blob);
      err = all_err;
    } else {
      size_t good = 0, bad = ffns.size();  // counts known to meet and to miss the budget
      while (bad - good > 1) {
        const size_t mid = (good + bad) / 2;
        auto [candidate, e] = try_count(mid);
        if (within_budget(e)) {
          good = mid;
          blob = std::move(candidate);
          err = e;
        } else {
          bad = mid;
        }
      }
      chosen = good;
    }
    for (size_t f = 0; f < chosen; ++f) linear_inputs_[ffns[f]].choice.per_tensor = true;
    quant = with_first(chosen);
    per_token_inputs_error_ = base;
    chosen_inputs_error_ = err;
  }

  // A later choice's error still meets mixed mode's target (any error does in the other modes).
  bool meets_mixed_target(const ActionError& e) const {
    return !opt_.target_mse || opt_.mode != Int8Mode::kMixed || e.mse <= *opt_.target_mse;
  }

  // Attention's matmuls on the int8 GEMM (Int8Options::attention). Tried last, on the model as
  // chosen so far, so its cost is measured against everything else's.
  void choose_attention(QuantConfig& quant, std::unique_ptr<ScratchBlob>& blob, ActionError& err) {
    if (opt_.attention == AttentionPrecision::kFp32) return;
    fp32_attention_error_ = err;
    QuantConfig with = quant;
    with.int8_attention = true;
    auto [candidate, e] = write_and_evaluate(with);
    int8_attention_error_ = e;
    const double allowed = 1.0 + kInt8AttentionErrorBudget;
    const bool within_budget = e.mse <= allowed * err.mse && e.max_abs <= allowed * err.max_abs && meets_mixed_target(e);
    const bool keep = opt_.attention == AttentionPrecision::kInt8 || within_budget;
    progress(std::string("attention in int8: held-out MSE ") + format_number(e.mse) + ", max |err| " +
             format_number(e.max_abs) + " (float: " + format_number(err.mse) + ", " + format_number(err.max_abs) + ") -> " +
             (keep ? "int8" : "float"));
    if (keep) {
      quant = std::move(with);
      blob = std::move(candidate);
      err = e;
    }
  }

  Int8Report report(const QuantConfig& quant, const ScratchBlob& blob, const ActionError& err,
                    std::vector<LayerSensitivity> sensitivity, uint64_t fp32_bytes) {
    Int8Report r;
    r.mode = opt_.mode;
    r.calibration = quant.calibration;
    r.calibration_frames = calib_.size();
    r.holdout_frames = eval_.size();
    r.preprocessing = frames_.preprocessing;
    r.notes = frames_.notes;
    r.fp32_bytes = fp32_bytes;
    r.int8_bytes = blob.bytes();
    r.float_layers = quant.float_layers;
    r.int8_attention = quant.int8_attention;
    r.fp32_attention_error = fp32_attention_error_;
    r.int8_attention_error = int8_attention_error_;
    r.action_error = err;
    r.action_keys = fp32_->config().action_dim;
    r.sensitivity = std::move(sensitivity);
    r.activations = activations_;
    for (const LinearInput& l : linear_inputs_) {
      r.linear_inputs.push_back(l.choice);
      if (l.choice.per_tensor) r.activations.push_back(l.range);
    }
    r.per_token_inputs_error = per_token_inputs_error_;
    r.chosen_inputs_error = chosen_inputs_error_;
    if (opt_.layer_report) r.layers = layer_sqnr(blob.path(), quant.float_layers);
    return r;
  }

  // SQNR of every int8 layer's output, and of every layer kept in float, against the FP32 network's
  // value of the same name (both networks are built from one config, so a layer's output has one
  // name in both), over (up to 4) held-out frames.
  std::vector<LayerSqnr> layer_sqnr(const std::string& blob, const std::vector<std::string>& float_layers) {
    Engine::Impl int8(blob, scratch_engine_options(true), fp32_.get());
    graph::Graph& gq = int8.network().graph();
    graph::Graph& gf = fp32_->network().graph();
    struct Acc {
      LayerSqnr layer;
      graph::ValueId q, f;
      double signal = 0, noise = 0;
    };
    std::vector<Acc> acc;
    for (const graph::NetworkLayer& l : int8.network().layers()) {
      const bool kept_float = std::find(float_layers.begin(), float_layers.end(), l.weight) != float_layers.end();
      if (!l.int8 && !kept_float) continue;  // always float (action head, state projections)
      const std::string& value = gq.value(l.output).name;
      const graph::ValueId f = gf.find(value);
      check(f != graph::kNoValue, StatusCode::kInternal, "layer " + value + " has no FP32 twin");
      acc.push_back({{l.weight.empty() ? value : l.weight, value, l.op->type(), kept_float, 0.0}, l.output, f});
    }
    std::vector<float> tmp(chunk_values());
    for (size_t k = 0; k < std::min<size_t>(4, eval_.size()); ++k) {
      fp32_->run(obs(eval_[k]), tmp);
      int8.run(obs(eval_[k]), tmp);
      for (auto& a : acc) {
        const std::vector<float> qv = gq.read_f32(a.q);
        const float* fv = gf.data(a.f);
        for (size_t i = 0; i < qv.size(); ++i) {
          a.signal += static_cast<double>(fv[i]) * fv[i];
          const double d = static_cast<double>(qv[i]) - fv[i];
          a.noise += d * d;
        }
      }
    }
    std::vector<LayerSqnr> out;
    for (auto& a : acc) {
      a.layer.sqnr_db = a.noise > 0 ? 10.0 * std::log10(a.signal / a.noise) : 200.0;
      out.push_back(std::move(a.layer));
    }
    return out;
  }

  const ImportedModel& model_;
  std::string output_;
  Int8Options opt_;
  StateSampler states_;
  std::unique_ptr<Engine::Impl> fp32_;
  CalibrationSet frames_;
  std::vector<size_t> calib_, eval_;
  Reference ref_;
  std::optional<ActionError> fp32_attention_error_, int8_attention_error_;
  std::vector<ActivationRange> activations_;  // calibrate()'s choices, for the report
  std::optional<ActionError> per_token_inputs_error_, chosen_inputs_error_;
  struct LinearInput {
    LinearInputChoice choice;
    ActivationRange range;  // for the report's activations, when chosen
  };
  std::vector<LinearInput> linear_inputs_;  // the candidates for per-tensor codes, graph order
};

}  // namespace

Int8Report convert_to_int8(const ImportedModel& model, const std::string& output, const CalibrationSet& calibration,
                           const Int8Options& options) {
  Converter converter(model, output, options);
  return converter.run(calibration);
}

}  // namespace act
