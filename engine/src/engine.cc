#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>

#include "engine/src/engine_impl.h"
#include "weights/blob/blob_names.h"
#include "actengine/status.h"

namespace act {

namespace bn = blob_names;

const char* version() { return ACT_VERSION; }  // engine/CMakeLists.txt defines it

// ---------------------------------------------------------------------------------------- Impl

namespace {

// Float images hold [0, 1]; a resampling filter may overshoot a little, a 0-255 image does not fit.
constexpr float kFloatImageSlack = 0.05f;
// A normalised state value beyond this (a million standard deviations, or ranges) is no observation.
constexpr float kMaxNormalizedInput = 1e6f;

// An inference that succeeds hands out finite numbers only.
void check_finite(std::span<const float> values, const char* what) {
  const size_t bad = static_cast<size_t>(std::count_if(values.begin(), values.end(), [](float v) { return !std::isfinite(v); }));
  if (bad > 0) {
    fail(StatusCode::kInvalidArgument, std::string(what) + " is not finite (" + std::to_string(bad) + " of " +
         std::to_string(values.size()) + " values NaN or infinite): is the observation far outside what the model " +
         "was trained on, or are the weights damaged?");
  }
}

// An option, or the environment variable's value when the option is "auto" and the variable is set;
// `source` names where it came from, for the error.
std::string option_or_env(const std::string& option, const char* env_name, std::string& source) {
  if (const char* env = std::getenv(env_name); option == "auto" && env != nullptr && env[0] != '\0') {
    source = env_name;
    return env;
  }
  return option;
}

// The kernels of an Engine: EngineOptions::isa and ::uarch, or ACT_ISA's and ACT_UARCH's when the
// option is "auto" and the variable is set. A name that is unknown, or an ISA this CPU lacks, is an
// error, never a silent fallback.
kernels::KernelConfig engine_kernels(const EngineOptions& options) {
  std::string isa_source = "EngineOptions::isa", uarch_source = "EngineOptions::uarch";
  const std::string isa = option_or_env(options.isa, "ACT_ISA", isa_source);
  const std::string uarch = option_or_env(options.uarch, "ACT_UARCH", uarch_source);
  kernels::KernelConfigChoice choice = kernels::kernel_config(isa, uarch);
  if (!choice.config) fail(StatusCode::kInvalidArgument, (choice.tuning_error ? uarch_source : isa_source) + ": " + choice.error);
  return *choice.config;
}

}  // namespace

float Engine::Impl::InputNorm::apply(float x, size_t i) const {
  switch (mode) {
    case NormMode::kIdentity: return x;
    case NormMode::kMeanStd: return (x - sub[i]) / div[i];
    case NormMode::kMinMax: return (x - sub[i]) / div[i] * 2.0f - 1.0f;
  }
  return x;
}

float Engine::Impl::InputNorm::invert(float z, size_t i) const {
  switch (mode) {
    case NormMode::kIdentity: return z;
    case NormMode::kMeanStd: return z * div[i] + sub[i];
    case NormMode::kMinMax: return (z + 1.0f) / 2.0f * div[i] + sub[i];
  }
  return z;
}

Engine::Impl::InputNorm Engine::Impl::input_norm(const std::string& key, size_t size) {
  InputNorm n;
  n.mode = config_.input_norm_mode(key);
  if (n.mode == NormMode::kIdentity) return n;
  const std::vector<int64_t> shape = {static_cast<int64_t>(size)};
  n.sub = blob_tensors_.f32(bn::norm_sub(key), shape);
  n.div = blob_tensors_.f32(bn::norm_div(key), shape);
  return n;
}

ModelInfo model_info_of(const ModelConfig& config) {
  ModelInfo info;
  for (const auto& cam : config.cameras) {
    info.cameras.push_back({cam.key, cam.height, cam.width, config.feature_height(cam), config.feature_width(cam)});
  }
  info.dim_model = config.dim_model;
  info.state_dim = config.state_dim;
  info.env_state_dim = config.env_state_dim;
  info.env_state_key = config.env_state_key;
  info.action_dim = config.action_dim;
  info.action_names = config.action_names;
  info.chunk_size = config.chunk_size;
  info.n_action_steps = config.n_action_steps;
  info.temporal_ensembling = config.temporal_ensemble_coeff.has_value();
  info.temporal_ensemble_coeff = config.temporal_ensemble_coeff.value_or(0.0);
  info.precision = precision_name(config.precision);
  info.summary = config.summary();
  return info;
}

Engine::Impl::Impl(const std::string& blob_path, const EngineOptions& options, const Impl* packed_weights_from)
    : blob_(ActbFile::open(blob_path, options.verify_checksum,
                           options.share_blob_pages ? FileMapping::Mode::kMap : FileMapping::Mode::kPrivateCopy)),
      blob_tensors_(blob_),
      config_(blob_model_config(blob_)),
      pool_(options.threads),
      kernels_(engine_kernels(options)),
      profile_(options.profile),
      keep_intermediates_(options.keep_intermediates),
      external_backbone_(options.external_backbone) {
  network_ = std::make_unique<graph::ActNetwork>(config_, blob_tensors_, kernels_, external_backbone_,
                                                 packed_weights_from ? packed_weights_from->network_.get() : nullptr);

  for (const auto& cam : config_.cameras) camera_norm_.push_back(input_norm(cam.key, 3));
  if (config_.state_dim > 0) state_norm_ = input_norm(config_.state_key, static_cast<size_t>(config_.state_dim));
  if (config_.env_state_dim > 0) env_norm_ = input_norm(config_.env_state_key, static_cast<size_t>(config_.env_state_dim));
  if (config_.action_norm != NormMode::kIdentity) {
    const std::vector<int64_t> shape = {config_.action_dim};
    unnorm_shift_ = blob_tensors_.f32(bn::kUnnormShift, shape);
    unnorm_scale_ = blob_tensors_.f32(bn::kUnnormScale, shape);
    unnorm_offset_ = blob_tensors_.f32(bn::kUnnormOffset, shape);
  }
  // Everything the model reads has been read: a tensor left over means the config does not describe the blob.
  blob_tensors_.check_all_read();
  network_->plan(pool_.threads(), keep_intermediates_);
  info_ = model_info_of(config_);
  const size_t action_dim = static_cast<size_t>(config_.action_dim);
  info_.action_low.assign(action_dim, -1.0f);
  info_.action_high.assign(action_dim, 1.0f);
  unnormalize(info_.action_low, info_.action_low, 1);
  unnormalize(info_.action_high, info_.action_high, 1);
  for (size_t i = 0; i < static_cast<size_t>(config_.state_dim); ++i) {
    info_.state_low.push_back(state_norm_.invert(-1.0f, i));
    info_.state_high.push_back(state_norm_.invert(1.0f, i));
  }
  info_.isa = kernels::isa_name(kernels_.isa);
  info_.kernels = kernels_.describe();
  if (config_.precision == Precision::kInt8) info_.precision += std::string(" ") + blob_.config()["quantization"].value("mode", "?");
  info_.placement = std::string("backbone: ") + (external_backbone_ ? "external (features given by the caller)" : "actengine (cpu)") +
                    ", transformer: actengine (cpu)";
}

void Engine::Impl::load_features(size_t camera, const ImageView& features) {
  const CameraConfig& cam = config_.cameras[camera];
  const std::string what = "backbone features " + std::to_string(camera) + " (" + cam.key + ")";
  if (features.format != ImageView::Format::kBackboneFeaturesF32Chw) {
    fail(StatusCode::kInvalidArgument, "image " + std::to_string(camera) + " (" + cam.key + ") is an image, but the engine " +
         "was opened with external_backbone: pass the backbone's output, ImageView::backbone_features");
  }
  if (features.data == nullptr) fail(StatusCode::kInvalidArgument, what + " has no data");
  const int fh = config_.feature_height(cam), fw = config_.feature_width(cam);
  if (features.height != fh || features.width != fw) {
    fail(StatusCode::kInvalidArgument, what + " are " + std::to_string(features.height) + "x" + std::to_string(features.width) +
         ", the model's feature map is " + std::to_string(fh) + "x" + std::to_string(fw) + " (height x width)");
  }
  const size_t pixels = static_cast<size_t>(fh) * static_cast<size_t>(fw), d = static_cast<size_t>(config_.dim_model);
  const auto* src = static_cast<const float*>(features.data);
  float* dst = network_->camera_input(camera);
  for (size_t c = 0; c < d; ++c) {
    for (size_t i = 0; i < pixels; ++i) {
      const float v = src[c * pixels + i];
      if (!std::isfinite(v)) fail(StatusCode::kInvalidArgument, what + " contain NaN or Inf");
      dst[i * d + c] = v;
    }
  }
}

void Engine::Impl::load_image(size_t camera, const ImageView& image) {
  if (external_backbone_) return load_features(camera, image);
  const CameraConfig& cam = config_.cameras[camera];
  const std::string what = "image " + std::to_string(camera) + " (" + cam.key + ")";
  if (image.format == ImageView::Format::kBackboneFeaturesF32Chw) {
    fail(StatusCode::kInvalidArgument, what + " holds backbone features: open the engine with EngineOptions::external_backbone");
  }
  if (image.data == nullptr) fail(StatusCode::kInvalidArgument, what + " has no data");
  if (image.height != cam.height || image.width != cam.width) {
    fail(StatusCode::kInvalidArgument, what + " is " + std::to_string(image.height) + "x" + std::to_string(image.width) +
         ", the model expects " + std::to_string(cam.height) + "x" + std::to_string(cam.width) + " (height x width)");
  }
  if (image.format == ImageView::Format::kRgbU8Hwc) return load_rgb_u8(camera, image, what);
  load_float_chw(camera, image, what);
}

// A static INT8 stem takes int8 codes (ActNetwork::camera_input_s8): the same quantize kernel the
// graph would run on the normalised float image, so the codes are bit-identical and no float image
// is written; stored unsigned (XOR 0x80) where the stem's kernels read them so.
void Engine::Impl::quantize_camera_codes(size_t camera, size_t n, const float* x, int8_t* y) const {
  const kernels::QuantS8 q = network_->camera_input_quant(camera);
  const auto sign_flip = static_cast<int8_t>(network_->camera_input_unsigned(camera) ? 0x80 : 0);
  kernels_.quant.quantize(n, x, 1.0f / q.scale, q.zero_point, y);
  if (sign_flip != 0) {
    for (size_t i = 0; i < n; ++i) y[i] = static_cast<int8_t>(y[i] ^ sign_flip);
  }
}

// uint8 RGB HWC: each channel value through a 256-entry table (normalised, and quantized for an
// int8 stem).
void Engine::Impl::load_rgb_u8(size_t camera, const ImageView& image, const std::string& what) {
  const CameraConfig& cam = config_.cameras[camera];
  const InputNorm& norm = camera_norm_[camera];
  int8_t* dst_s8 = network_->camera_input_s8(camera);
  const size_t h = static_cast<size_t>(cam.height), w = static_cast<size_t>(cam.width);
  const size_t stride = image.row_stride == 0 ? w * 3 : image.row_stride;
  if (stride < w * 3) fail(StatusCode::kInvalidArgument, what + ": row stride " + std::to_string(stride) + " < width * 3");
  // uint8 -> [0, 1] by a float32 division, as LeRobot does (255 -> exactly 1.0); then normalise.
  float lut[3][256];
  for (size_t c = 0; c < 3; ++c) {
    for (int v = 0; v < 256; ++v) lut[c][v] = norm.apply(static_cast<float>(v) / 255.0f, c);
  }
  // Each pixel's channel value through its channel's table, into the network's input (float or int8),
  // in bands of rows over the pool: the first parallel section of a run, it also wakes the workers
  // while this thread maps its share.
  const auto map_pixels = [&](auto* dst, const auto& table) {
    constexpr size_t kBandRows = 8;
    const auto* src = static_cast<const uint8_t*>(image.data);
    pool_.parallel_for((h + kBandRows - 1) / kBandRows, [&](size_t band, int) {
      // Locals, not the captures: an int8 store may alias anything in memory, which would reload
      // every captured value after each store.
      const auto* tables = &table[0];
      const size_t width = w, row_stride = stride, end = std::min(h, (band + 1) * kBandRows);
      for (size_t y = band * kBandRows; y < end; ++y) {
        const uint8_t* row = src + y * row_stride;
        auto* out = dst + y * width * 3;
        for (size_t x = 0; x < width; ++x) {
          for (size_t c = 0; c < 3; ++c) out[3 * x + c] = tables[c][row[3 * x + c]];
        }
      }
    });
  };
  if (dst_s8 != nullptr) {
    int8_t lut_s8[3][256];
    for (size_t c = 0; c < 3; ++c) quantize_camera_codes(camera, 256, lut[c], lut_s8[c]);
    map_pixels(dst_s8, lut_s8);
  } else {
    map_pixels(network_->camera_input(camera), lut);
  }
}

// Float CHW in [0, 1]: normalised into the float input, or into a scratch image then quantized.
void Engine::Impl::load_float_chw(size_t camera, const ImageView& image, const std::string& what) {
  const CameraConfig& cam = config_.cameras[camera];
  const InputNorm& norm = camera_norm_[camera];
  int8_t* dst_s8 = network_->camera_input_s8(camera);
  const size_t h = static_cast<size_t>(cam.height), w = static_cast<size_t>(cam.width);
  if (dst_s8 != nullptr) float_image_.resize(h * w * 3);
  float* dst = dst_s8 != nullptr ? float_image_.data() : network_->camera_input(camera);
  const auto* src = static_cast<const float*>(image.data);
  for (size_t c = 0; c < 3; ++c) {
    for (size_t i = 0; i < h * w; ++i) {
      const float v = src[c * h * w + i];
      if (!std::isfinite(v)) fail(StatusCode::kInvalidArgument, what + " contains NaN or Inf");
      if (v < -kFloatImageSlack || v > 1.0f + kFloatImageSlack) {
        fail(StatusCode::kInvalidArgument, what + " has the value " + std::to_string(v) + " (channel " +
             std::to_string(c) + ", pixel " + std::to_string(i) + "): float images hold [0, 1]" +
             (v > 2.0f ? " (a 0-255 image? divide it by 255, or pass it as uint8)" : ""));
      }
      dst[i * 3 + c] = norm.apply(v, c);
    }
  }
  if (dst_s8 != nullptr) quantize_camera_codes(camera, h * w * 3, dst, dst_s8);
}

void Engine::Impl::load_vector(const char* what, std::span<const float> values, size_t expected, const InputNorm& norm,
                               float* dst) {
  if (values.size() != expected) {
    fail(StatusCode::kInvalidArgument, std::string(what) + " has " + std::to_string(values.size()) +
         " values, the model expects " + std::to_string(expected));
  }
  for (size_t i = 0; i < expected; ++i) {
    const std::string name = std::string(what) + "[" + std::to_string(i) + "]";
    if (!std::isfinite(values[i])) fail(StatusCode::kInvalidArgument, name + " is not finite");
    dst[i] = norm.apply(values[i], i);
    if (!(std::fabs(dst[i]) <= kMaxNormalizedInput)) {
      char text[160];
      std::snprintf(text, sizeof text, " = %g is %g after normalisation: far outside anything the model was trained on",
                    values[i], dst[i]);
      fail(StatusCode::kInvalidArgument, name + text);
    }
  }
}

void Engine::Impl::run(const Observation& obs, std::span<float> actions_normalized) {
  if (obs.images.size() != config_.cameras.size()) {
    fail(StatusCode::kInvalidArgument, "observation has " + std::to_string(obs.images.size()) + " images, the model has " +
         std::to_string(config_.cameras.size()) + " cameras");
  }
  if (actions_normalized.size() != info_.chunk_values()) {
    fail(StatusCode::kInvalidArgument, "action buffer holds " + std::to_string(actions_normalized.size()) +
         " values, the chunk has " + std::to_string(info_.chunk_values()));
  }
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  for (size_t c = 0; c < obs.images.size(); ++c) load_image(c, obs.images[c]);
  if (config_.state_dim > 0) {
    load_vector("state", obs.state, static_cast<size_t>(config_.state_dim), state_norm_, network_->state_input());
  } else if (!obs.state.empty()) {
    fail(StatusCode::kInvalidArgument, "the model takes no robot state, but the observation has one");
  }
  if (config_.env_state_dim > 0) {
    load_vector("environment state", obs.env_state, static_cast<size_t>(config_.env_state_dim), env_norm_,
                network_->env_state_input());
  } else if (!obs.env_state.empty()) {
    fail(StatusCode::kInvalidArgument, "the model takes no environment state, but the observation has one");
  }
  const auto preprocessed = Clock::now();
  network_->run(pool_, profile_ ? &last_run_ : nullptr);
  const float* out = network_->actions_normalized();
  std::copy(out, out + actions_normalized.size(), actions_normalized.begin());
  check_finite(actions_normalized, "the network's output");
  has_run_ = true;
  if (profile_) record_profile(start, preprocessed);
}

void Engine::Impl::unnormalize(std::span<const float> normalized, std::span<float> raw, size_t rows) const {
  const size_t a = static_cast<size_t>(config_.action_dim);
  for (size_t r = 0; r < rows; ++r) {
    for (size_t i = 0; i < a; ++i) {
      const float y = normalized[r * a + i];
      raw[r * a + i] = unnorm_scale_ ? (y + unnorm_shift_[i]) * unnorm_scale_[i] + unnorm_offset_[i] : y;
    }
  }
}

std::vector<float> Engine::Impl::intermediate(const std::string& name) {
  graph::Graph& g = network_->graph();
  const graph::ValueId id = g.find(name);
  if (id == graph::kNoValue) fail(StatusCode::kNotFound, "the network has no value \"" + name + "\"");
  if (!keep_intermediates_) {
    fail(StatusCode::kFailedPrecondition, "intermediate \"" + name + "\": open the engine with EngineOptions::keep_intermediates");
  }
  if (!has_run_) fail(StatusCode::kFailedPrecondition, "intermediate \"" + name + "\": no inference has run yet");
  const graph::Value& v = g.value(id);
  if (v.dtype == graph::DataType::kS32) fail(StatusCode::kUnimplemented, "intermediate \"" + name + "\" is an int32 accumulator");
  if (v.dtype == graph::DataType::kS8 && !v.quant) {
    fail(StatusCode::kUnimplemented, "intermediate \"" + name + "\" is int8 quantized at run time; its scale is not kept");
  }
  return g.read_f32(id);
}

// -------------------------------------------------------------------------------------- Engine

static_assert(kMaxThreads == ThreadPool::kMaxThreads, "the public limit is the pool's");

Engine::Engine(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Engine::~Engine() = default;

StatusOr<std::unique_ptr<Engine>> Engine::open(const std::string& blob_path, const EngineOptions& options) {
  std::unique_ptr<Engine> engine;
  Status s = guarded([&] {
    ThreadPool::checked_threads(options.threads);  // a count outside 0..kMaxThreads, before any work
    engine.reset(new Engine(std::make_unique<Impl>(blob_path, options)));
  });
  if (!s.ok()) return s;
  return engine;
}

const ModelInfo& Engine::model_info() const { return impl_->info(); }
int Engine::threads() const { return impl_->threads(); }

Status Engine::infer_normalized(const Observation& observation, std::span<float> actions_normalized) {
  return guarded([&] { impl_->run(observation, actions_normalized); });
}

Status Engine::infer(const Observation& observation, std::span<float> actions) {
  return guarded([&] {
    const auto start = std::chrono::steady_clock::now();
    impl_->run(observation, actions);
    impl_->unnormalize(actions, actions, static_cast<size_t>(impl_->info().chunk_size));
    check_finite(actions, "the un-normalised actions");
    if (impl_->profiling()) {
      InferenceTimings& t = impl_->timings();
      const double total = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      t.other_ms += total - t.total_ms;  // un-normalising
      t.total_ms = total;
    }
  });
}

const InferenceTimings& Engine::last_timings() const { return impl_->timings(); }

std::vector<OpProfile> Engine::op_profile() const { return impl_->op_profile(); }

void Engine::reset_op_profile() { impl_->reset_op_profile(); }

StatusOr<std::string> Engine::chrome_trace() const {
  std::string trace;
  Status s = guarded([&] { trace = impl_->chrome_trace(); });
  if (!s.ok()) return s;
  return trace;
}

std::vector<std::string> Engine::intermediate_names() const {
  const graph::Graph& g = impl_->network().graph();
  std::vector<std::string> names;
  names.reserve(g.value_count());
  for (size_t i = 0; i < g.value_count(); ++i) names.push_back(g.value(static_cast<graph::ValueId>(i)).name);
  return names;
}

StatusOr<std::vector<float>> Engine::intermediate(const std::string& name) const {
  std::vector<float> values;
  Status s = guarded([&] { values = impl_->intermediate(name); });
  if (!s.ok()) return s;
  return values;
}

}  // namespace act
