#include "apps/convert/int8_conversion.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <random>
#include <sstream>

#include "engine/src/engine_impl.h"
#include "weights/blob/error.h"
#include "weights/quantize/quantize_model.h"
#include "apps/signal_cleanup.h"

namespace act {

namespace fs = std::filesystem;

namespace {

// A folder for the intermediate blobs next to the output (same file system, so the final rename is
// atomic), removed whatever happens.
class ScratchDir {
 public:
  explicit ScratchDir(const fs::path& output) {
    const fs::path parent = output.has_parent_path() ? output.parent_path() : fs::path(".");
    std::random_device rd;
    path_ = parent / (".act_convert." + std::to_string(::getpid()) + "." + std::to_string(rd()) + ".tmp");
    std::error_code ec;
    if (!fs::create_directory(path_, ec)) {
      fail(ErrorCode::kIoError, "cannot create a scratch folder " + path_.string() + ": " + ec.message());
    }
    remove_on_signal_.emplace_back(std::make_unique<SignalCleanup>(path_.string(), true));
    for (const char* f : kFiles) remove_on_signal_.emplace_back(std::make_unique<SignalCleanup>(file(f)));
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  /// The files the conversion writes in the folder (all of them, for the signal cleanup).
  static constexpr const char* kFiles[] = {"fp32.actb", "int8.actb", "probe.actb"};
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
  std::vector<std::unique_ptr<SignalCleanup>> remove_on_signal_;
};

class Progress {
 public:
  explicit Progress(bool on) : on_(on) {}
  void line(const std::string& s) const {
    if (on_) std::cerr << "act_convert: " << s << "\n";
  }

 private:
  bool on_;
};

struct ActionError {
  double mse = 0, max_abs = 0;            // normalised units, over all dims
  double mse_raw = 0, max_abs_raw = 0;    // physical units
  std::vector<double> dim_mse, dim_max_abs, dim_mse_raw, dim_max_abs_raw;

  nlohmann::json to_json() const {
    return {{"mse", mse}, {"max_abs", max_abs}, {"mse_physical", mse_raw}, {"max_abs_physical", max_abs_raw},
            {"per_dim_mse", dim_mse}, {"per_dim_max_abs", dim_max_abs}, {"per_dim_mse_physical", dim_mse_raw},
            {"per_dim_max_abs_physical", dim_max_abs_raw}};
  }
};

// The FP32 model's chunks on the evaluation frames, computed once.
struct Reference {
  std::vector<std::vector<float>> normalized, raw;
};

std::string fmt(double v, const char* f = "%.3g") {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

class Converter {
 public:
  Converter(const ImportedModel& model, const std::string& output, const Int8Options& options)
      : model_(model), output_(output), opt_(options), scratch_(output), progress_(options.progress) {}

  Int8Result run(const CalibSet* given_frames) {
    const auto t0 = std::chrono::steady_clock::now();
    fp32_path_ = scratch_.file("fp32.actb");
    fp32_bytes_ = write_fp32_blob(model_, fp32_path_);
    EngineOptions eo;
    eo.threads = opt_.threads;
    fp32_ = std::make_unique<Engine::Impl>(fp32_path_, eo, true);
    const ActbFile fp32_blob = ActbFile::open(fp32_path_, false);

    load_frames(given_frames, fp32_blob);
    compute_reference();

    QuantConfig quant;
    quant.mode = opt_.mode;
    if (opt_.mode != QuantMode::kDynamic) {
      quant.calibration = calibration_method_name(opt_.method);
      quant.activations = calibrate();
    }
    std::string blob = scratch_.file("int8.actb");
    ActionError err = write_and_evaluate(quant, blob);
    std::vector<std::pair<std::string, double>> sensitivity;
    if (opt_.mode == QuantMode::kMixed) err = choose_float_layers(quant, blob, err, sensitivity);

    Int8Result result;
    result.report = report(quant, blob, err, sensitivity);
    result.report["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    result.text = text_report(result.report);
    if (opt_.max_mse && !(err.mse <= *opt_.max_mse)) {
      fail(ErrorCode::kFailedPrecondition, "the INT8 model misses --max-mse: held-out MSE " + fmt(err.mse) + " > " +
           fmt(*opt_.max_mse) + " (normalised units); nothing was written. Try --mode mixed --target-mse " +
           fmt(*opt_.max_mse) + ", more calibration frames, or another --calib-method.\n" + result.text);
    }
    std::error_code ec;
    fs::rename(blob, output_, ec);
    if (ec) fail(ErrorCode::kIoError, "cannot move the INT8 blob to " + output_ + ": " + ec.message());
    result.bytes = fs::file_size(output_);
    result.report["int8_bytes"] = result.bytes;
    return result;
  }

 private:
  // The held-out frames when --holdout is not given: one per four calibration frames, 1 to 16.
  static size_t default_holdout(size_t calibration_frames) { return std::clamp<size_t>(calibration_frames / 4, 1, 16); }

  void load_frames(const CalibSet* given, const ActbFile& blob) {
    const ModelConfig& config = fp32_->config();
    if (given) {
      frames_ = *given;
    } else if (!opt_.calib_sources.empty()) {
      if (opt_.frame_loader == nullptr) fail(ErrorCode::kUnimplemented, "this program reads no calibration files (built without OpenCV)");
      const size_t want = opt_.calib_samples + opt_.holdout.value_or(default_holdout(opt_.calib_samples));
      progress_.line("reading calibration frames from " + std::to_string(opt_.calib_sources.size()) + " source(s) ...");
      frames_ = opt_.frame_loader(opt_.calib_sources, config, fp32_->info(), blob, want, opt_.seed);
    } else if (opt_.mode == QuantMode::kDynamic) {
      frames_ = synthetic_calibration_frames(config, blob, opt_.holdout.value_or(8), opt_.seed);
    } else {
      fail(ErrorCode::kInvalidArgument, std::string(quant_mode_name(opt_.mode)) +
           " quantization needs calibration frames: --calib DIR|VIDEO|DATASET|OBS.safetensors "
           "(or --mode dynamic, which needs none)");
    }
    const size_t n = frames_.frames.size();
    if (n == 0) fail(ErrorCode::kInvalidArgument, "no calibration frames");
    // Held-out frames interleaved through the sources, so both sets cover all of them.
    size_t holdout = opt_.holdout.value_or(n >= 2 ? default_holdout(n - n / 5) : 0);  // about a fifth
    holdout = std::min(holdout, n - 1);
    const size_t stride = holdout ? n / holdout : 0;
    for (size_t i = 0; i < n; ++i) {
      const bool held = holdout && i % stride == stride - 1 && eval_.size() < holdout;
      (held ? eval_ : calib_).push_back(i);
    }
    if (eval_.empty()) {
      eval_ = calib_;
      frames_.notes.push_back("only one frame: the accuracy below is measured on the calibration frame itself");
    }
    progress_.line(std::to_string(calib_.size()) + " calibration frames, " + std::to_string(eval_.size()) + " held out");
  }

  Observation obs(size_t i) const { return CalibSet::observation(frames_.frames[i], fp32_->config()); }
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

  // Backbone values (every float value of the camera branches) -> parameters.
  std::map<std::string, ActivationQuant> calibrate() {
    graph::Graph& g = fp32_->network().graph();
    std::vector<graph::ValueId> ids;
    for (size_t v = 0; v < g.value_count(); ++v) {
      const auto id = static_cast<graph::ValueId>(v);
      const graph::Value& value = g.value(id);
      if (value.dtype == graph::DataType::kF32 && value.name.rfind("cam", 0) == 0) ids.push_back(id);
    }
    std::vector<RangeObserver> observers(ids.size());
    const bool histograms = opt_.method != CalibrationMethod::kMinMax;
    const int passes = histograms ? 2 : 1;
    std::vector<float> normalized(chunk_values());
    for (int pass = 1; pass <= passes; ++pass) {
      for (size_t f = 0; f < calib_.size(); ++f) {
        progress_.line("calibrating (" + std::string(calibration_method_name(opt_.method)) + "): pass " + std::to_string(pass) +
                       "/" + std::to_string(passes) + ", frame " + std::to_string(f + 1) + "/" + std::to_string(calib_.size()));
        fp32_->run(obs(calib_[f]), normalized);
        for (size_t k = 0; k < ids.size(); ++k) {
          const std::span<const float> values(g.data(ids[k]), g.value(ids[k]).elements);
          if (pass == 1) {
            observers[k].observe_range(values);
          } else {
            observers[k].observe_histogram(values);
          }
        }
      }
    }
    std::map<std::string, ActivationQuant> out;
    for (size_t k = 0; k < ids.size(); ++k) {
      const std::string& name = g.value(ids[k]).name;
      // The input image's range is known exactly: never clip it.
      const bool input = name.size() > 6 && name.compare(name.size() - 6, 6, ".image") == 0;
      out[name] = observers[k].choose(input ? CalibrationMethod::kMinMax : opt_.method, opt_.percentile);
    }
    return out;
  }

  ActionError evaluate(const std::string& blob_path) {
    EngineOptions eo;
    eo.threads = opt_.threads;
    Engine::Impl int8(blob_path, eo, false);
    return compare(int8);
  }

  ActionError compare(Engine::Impl& int8) {
    const size_t T = static_cast<size_t>(fp32_->config().chunk_size), A = static_cast<size_t>(fp32_->config().action_dim);
    ActionError e;
    e.dim_mse.assign(A, 0.0);
    e.dim_max_abs.assign(A, 0.0);
    e.dim_mse_raw.assign(A, 0.0);
    e.dim_max_abs_raw.assign(A, 0.0);
    std::vector<float> norm(chunk_values()), raw(chunk_values());
    for (size_t f = 0; f < eval_.size(); ++f) {
      int8.run(obs(eval_[f]), norm);
      int8.unnormalize(norm, raw, T);
      for (size_t i = 0; i < norm.size(); ++i) {
        const double d = static_cast<double>(norm[i]) - ref_.normalized[f][i];
        const double dr = static_cast<double>(raw[i]) - ref_.raw[f][i];
        const size_t a = i % A;
        e.dim_mse[a] += d * d;
        e.dim_max_abs[a] = std::max(e.dim_max_abs[a], std::fabs(d));
        e.dim_mse_raw[a] += dr * dr;
        e.dim_max_abs_raw[a] = std::max(e.dim_max_abs_raw[a], std::fabs(dr));
        if (!std::isfinite(d)) e.dim_mse[a] = INFINITY;
      }
    }
    const double per_dim = static_cast<double>(eval_.size() * T);
    for (size_t a = 0; a < A; ++a) {
      e.dim_mse[a] /= per_dim;
      e.dim_mse_raw[a] /= per_dim;
      e.mse += e.dim_mse[a] / static_cast<double>(A);
      e.mse_raw += e.dim_mse_raw[a] / static_cast<double>(A);
      e.max_abs = std::max(e.max_abs, e.dim_max_abs[a]);
      e.max_abs_raw = std::max(e.max_abs_raw, e.dim_max_abs_raw[a]);
    }
    return e;
  }

  ActionError write_and_evaluate(const QuantConfig& quant, const std::string& path) {
    write_int8_blob(model_, quant, path);
    return evaluate(path);
  }

  // Mixed: the fewest float layers (most sensitive first) that meet the target.
  ActionError choose_float_layers(QuantConfig& quant, const std::string& blob, ActionError all_int8,
                                  std::vector<std::pair<std::string, double>>& sensitivity) {
    if (!opt_.target_mse) fail(ErrorCode::kInvalidArgument, "--mode mixed needs --target-mse (held-out MSE in normalised units)");
    const double target = *opt_.target_mse;
    progress_.line("all layers int8: held-out MSE " + fmt(all_int8.mse) + " (target " + fmt(target) + ")");
    if (all_int8.mse <= target) return all_int8;
    const std::vector<std::string> layers = quantizable_layers(model_);
    const std::string probe = scratch_.file("probe.actb");
    for (size_t i = 0; i < layers.size(); ++i) {
      QuantConfig one = quant;
      one.float_layers.clear();
      for (const auto& l : layers) {
        if (l != layers[i]) one.float_layers.push_back(l);
      }
      const double mse = write_and_evaluate(one, probe).mse;
      sensitivity.emplace_back(layers[i], mse);
      progress_.line("sensitivity " + std::to_string(i + 1) + "/" + std::to_string(layers.size()) + ": " + layers[i] +
                     " alone in int8 -> MSE " + fmt(mse));
    }
    std::stable_sort(sensitivity.begin(), sensitivity.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
    // Smallest prefix of the most sensitive layers whose return to float meets the target (binary
    // search: the error shrinks as layers go back to float; all of them in float is the FP32 model).
    const auto try_prefix = [&](size_t count) {
      QuantConfig q = quant;
      for (size_t i = 0; i < count; ++i) q.float_layers.push_back(sensitivity[i].first);
      const ActionError e = write_and_evaluate(q, probe);
      progress_.line(std::to_string(count) + " most sensitive layers in float -> MSE " + fmt(e.mse));
      return std::pair{q, e};
    };
    auto [best, best_err] = try_prefix(layers.size());
    if (!(best_err.mse <= target)) {
      fail(ErrorCode::kFailedPrecondition, "--target-mse " + fmt(target) + " cannot be met: even with every layer in float "
           "the held-out MSE is " + fmt(best_err.mse));
    }
    fs::rename(probe, blob);
    size_t lo = 1, hi = layers.size();
    while (lo < hi) {
      const size_t mid = (lo + hi) / 2;
      auto [q, e] = try_prefix(mid);
      if (e.mse <= target) {
        hi = mid;
        best = q;
        best_err = e;
        fs::rename(probe, blob);
      } else {
        lo = mid + 1;
      }
    }
    quant = best;
    return best_err;
  }

  nlohmann::json report(const QuantConfig& quant, const std::string& blob, const ActionError& err,
                        const std::vector<std::pair<std::string, double>>& sensitivity) {
    nlohmann::json r;
    r["mode"] = quant_mode_name(quant.mode);
    r["calibration"] = quant.calibration;
    r["calibration_frames"] = calib_.size();
    r["holdout_frames"] = eval_.size();
    r["preprocessing"] = frames_.preprocessing;
    r["notes"] = frames_.notes;
    r["fp32_bytes"] = fp32_bytes_;
    r["int8_bytes"] = fs::file_size(blob);
    r["float_layers"] = quant.float_layers;
    r["action_error"] = err.to_json();
    r["action_keys"] = fp32_->config().action_dim;
    if (!sensitivity.empty()) {
      r["sensitivity"] = nlohmann::json::array();
      for (const auto& [name, mse] : sensitivity) r["sensitivity"].push_back({{"layer", name}, {"mse_alone_int8", mse}});
    }
    r["layers"] = opt_.layer_report ? layer_sqnr(blob) : nlohmann::json::array();
    return r;
  }

  // SQNR of every int8 op's output against the same value of the FP32 graph, over (up to 4)
  // held-out frames.
  nlohmann::json layer_sqnr(const std::string& blob) {
    EngineOptions eo;
    eo.threads = opt_.threads;
    Engine::Impl int8(blob, eo, true);
    graph::Graph& gq = int8.network().graph();
    graph::Graph& gf = fp32_->network().graph();
    struct Acc {
      std::string name, op;
      graph::ValueId q, f;
      double signal = 0, noise = 0;
    };
    std::vector<Acc> acc;
    for (const auto& op : gq.ops()) {
      const std::string type = op->type();
      if (type.find("_s8") == std::string::npos || type.rfind("quantize", 0) == 0) continue;
      const graph::ValueId q = op->outputs[0];
      const graph::ValueId f = gf.find(gq.value(q).name);
      if (f != graph::kNoValue) acc.push_back({gq.value(q).name, type, q, f});
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
    nlohmann::json out = nlohmann::json::array();
    for (const auto& a : acc) {
      const double sqnr = a.noise > 0 ? 10.0 * std::log10(a.signal / a.noise) : 200.0;
      out.push_back({{"value", a.name}, {"op", a.op}, {"sqnr_db", sqnr}});
    }
    return out;
  }

  static std::string text_report(const nlohmann::json& r) {
    std::ostringstream s;
    s << "INT8 " << r["mode"].get<std::string>();
    if (!r["calibration"].get<std::string>().empty()) s << ", calibration " << r["calibration"].get<std::string>();
    s << ": " << r["calibration_frames"] << " calibration frames, " << r["holdout_frames"] << " held out\n";
    s << "preprocessing  " << r["preprocessing"].get<std::string>() << "\n";
    const double fp = r["fp32_bytes"].get<double>(), q = r["int8_bytes"].get<double>();
    s << "size           fp32 " << fmt(fp / 1e6, "%.1f") << " MB -> int8 " << fmt(q / 1e6, "%.1f") << " MB ("
      << fmt(100.0 * q / fp, "%.1f") << " %)\n";
    const auto& e = r["action_error"];
    s << "held-out error normalised: MSE " << fmt(e["mse"].get<double>()) << ", max |err| " << fmt(e["max_abs"].get<double>())
      << "; physical: MSE " << fmt(e["mse_physical"].get<double>()) << ", max |err| " << fmt(e["max_abs_physical"].get<double>()) << "\n";
    s << "per action dim (normalised MSE / max | physical MSE / max):\n";
    for (size_t a = 0; a < e["per_dim_mse"].size(); ++a) {
      s << "  [" << a << "] " << fmt(e["per_dim_mse"][a].get<double>()) << " / " << fmt(e["per_dim_max_abs"][a].get<double>())
        << " | " << fmt(e["per_dim_mse_physical"][a].get<double>()) << " / " << fmt(e["per_dim_max_abs_physical"][a].get<double>())
        << "\n";
    }
    const auto& fl = r["float_layers"];
    s << "layers in float " << (fl.empty() ? "none (besides the action head and state projections, always float)" : "") << "\n";
    for (const auto& l : fl) s << "  " << l.get<std::string>() << "\n";
    s << "per-layer SQNR (dB, int8 vs fp32 output):\n";
    for (const auto& l : r["layers"]) {
      s << "  " << fmt(l["sqnr_db"].get<double>(), "%6.1f") << "  " << l["value"].get<std::string>() << " (" << l["op"].get<std::string>() << ")\n";
    }
    for (const auto& n : r["notes"]) s << "note: " << n.get<std::string>() << "\n";
    return s.str();
  }

  const ImportedModel& model_;
  std::string output_;
  Int8Options opt_;
  ScratchDir scratch_;
  Progress progress_;
  std::string fp32_path_;
  size_t fp32_bytes_ = 0;
  std::unique_ptr<Engine::Impl> fp32_;
  CalibSet frames_;
  std::vector<size_t> calib_, eval_;
  Reference ref_;
};

}  // namespace

Int8Result convert_to_int8(const ImportedModel& model, const std::string& output, const Int8Options& options,
                           const CalibSet* frames) {
  Converter converter(model, output, options);
  return converter.run(frames);
}

}  // namespace act
