// actengine._actengine: the Python binding of the public API (engine.h, scheduler.h, convert.h).
// The pure-Python package (actengine/__init__.py) re-exports it. Every call that runs the network or
// converts a checkpoint releases the GIL; an Engine's mutex keeps two Python threads from running one
// Engine (and the Policies on it) at once, as engine.h requires.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cerrno>
#include <filesystem>
#include <system_error>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "actengine/scheduler.h"
#include "actengine/status.h"
#include "media_api.h"
#include "observation.h"

namespace act::python {

namespace py = pybind11;

namespace {

/// actengine.Error: the engine failed (a file it cannot read, a checkpoint it cannot convert, ...).
/// Bad input (a malformed observation or argument) raises ValueError instead.
class EngineError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

[[noreturn]] void raise(const Status& status) {
  if (status.code() == StatusCode::kInvalidArgument) throw py::value_error(status.message());
  throw EngineError(status.message());
}

/// An Engine shared by the Python objects that use it (Policy keeps it alive).
class PyEngine {
 public:
  PyEngine(const std::filesystem::path& path, int threads, const std::string& isa, const std::string& uarch) {
    EngineOptions options;
    options.threads = threads;
    options.isa = isa;
    options.uarch = uarch;
    auto opened = [&] {
      py::gil_scoped_release release;
      return Engine::open(path.string(), options);
    }();
    if (!opened.ok()) raise(opened.status());
    engine_ = std::move(opened).value();
  }

  const ModelInfo& model_info() const { return engine_->model_info(); }
  int threads() const { return engine_->threads(); }
  Engine& engine() { return *engine_; }
  std::mutex& mutex() { return mutex_; }

  py::array_t<float> infer(const py::dict& observation, bool normalized) {
    const HeldObservation held = observation_from_dict(model_info(), observation);
    const ModelInfo& info = model_info();
    py::array_t<float> chunk({info.chunk_size, info.action_dim});
    const std::span<float> out(chunk.mutable_data(), info.chunk_values());
    Status status;
    {
      py::gil_scoped_release release;
      const std::lock_guard lock(mutex_);
      status = normalized ? engine_->infer_normalized(held.view(), out) : engine_->infer(held.view(), out);
    }
    if (!status.ok()) raise(status);
    return chunk;
  }

 private:
  std::unique_ptr<Engine> engine_;
  std::mutex mutex_;
};

/// `self` of a method, refused with a TypeError when its __init__ never ran (`T.__new__(T)` in Python):
/// pybind11 would hand such an object over as freshly allocated, never constructed memory.
template <class T>
T& initialised(py::handle self, const char* type) {
  auto* instance = reinterpret_cast<py::detail::instance*>(self.ptr());
  const py::detail::value_and_holder v_h = instance->get_value_and_holder(py::detail::get_type_info(typeid(T)), false);
  if (!v_h || !v_h.holder_constructed()) {
    throw py::type_error(std::string("this actengine.") + type + " was never initialised (made by " + type +
                         ".__new__ without __init__): create it as actengine." + type + "(...)");
  }
  return *v_h.value_ptr<T>();
}

/// A method of T bound for Python: an uninitialised object is a TypeError (initialised()).
template <const char* kType, class T, class R, class... Args>
auto checked(R (T::*method)(Args...)) {
  return [method](py::handle self, Args... args) -> R {
    return (initialised<T>(self, kType).*method)(std::forward<Args>(args)...);
  };
}
template <const char* kType, class T, class R, class... Args>
auto checked(R (T::*method)(Args...) const) {
  return [method](py::handle self, Args... args) -> R {
    return (initialised<T>(self, kType).*method)(std::forward<Args>(args)...);
  };
}
constexpr char kEngineType[] = "Engine";
constexpr char kPolicyType[] = "Policy";
constexpr char kSchedulerType[] = "ChunkScheduler";

// An Engine for Policy(engine): None (which pybind11 passes as an empty pointer) is a TypeError.
std::shared_ptr<PyEngine> engine_given(std::shared_ptr<PyEngine> engine) {
  if (!engine) throw py::type_error("Policy(engine): engine must be an actengine.Engine, not None");
  return engine;
}

class PyPolicy {
 public:
  explicit PyPolicy(std::shared_ptr<PyEngine> engine) : engine_(engine_given(std::move(engine))), policy_(engine_->engine()) {}

  py::array_t<float> select_action(const py::dict& observation) {
    const HeldObservation held = observation_from_dict(engine_->model_info(), observation);
    py::array_t<float> action(engine_->model_info().action_dim);
    const std::span<float> out(action.mutable_data(), static_cast<size_t>(action.size()));
    Status status;
    {
      py::gil_scoped_release release;
      const std::lock_guard lock(engine_->mutex());
      status = policy_.select_action(held.view(), out);
    }
    if (!status.ok()) raise(status);
    return action;
  }

  void reset() {
    const std::lock_guard lock(engine_->mutex());
    policy_.reset();
  }

  bool will_infer_next() {
    const std::lock_guard lock(engine_->mutex());
    return policy_.will_infer_next();
  }

 private:
  std::shared_ptr<PyEngine> engine_;
  Policy policy_;
};

/// The scheduler with the chunk shape it checks its input against.
class PyChunkScheduler {
 public:
  explicit PyChunkScheduler(const ModelInfo& info)
      : scheduler_(created(info)), chunk_size_(static_cast<size_t>(info.chunk_size)),
        action_dim_(static_cast<size_t>(info.action_dim)) {}

  void add(const py::handle& chunk, int64_t observation_tick) {
    const py::array_t<float> values = float_matrix(chunk, "chunk", chunk_size_, action_dim_);
    const Status status = scheduler_.add({values.data(), static_cast<size_t>(values.size())}, observation_tick);
    if (!status.ok()) raise(status);
  }

  /// The action for `tick`, or None when no chunk covers it (hold a safe action then).
  std::optional<py::array_t<float>> action_at(int64_t tick) const {
    py::array_t<float> action(static_cast<py::ssize_t>(action_dim_));
    const Status status = scheduler_.action_at(tick, {action.mutable_data(), action_dim_});
    if (status.code() == StatusCode::kNotFound) return std::nullopt;
    if (!status.ok()) raise(status);
    return action;
  }

  bool wants_inference(int64_t tick, int lead_ticks) const { return scheduler_.wants_inference(tick, lead_ticks); }
  void clear() { scheduler_.clear(); }

 private:
  static ChunkScheduler created(const ModelInfo& info) {
    auto scheduler = ChunkScheduler::create(info);
    if (!scheduler.ok()) raise(scheduler.status());
    return std::move(scheduler).value();
  }

  ChunkScheduler scheduler_;
  size_t chunk_size_, action_dim_;
};

// ------------------------------------------------------------------------------------------ convert

/// convert()'s arguments, act_convert's options by their Python names.
struct ConvertArgs {
  std::filesystem::path checkpoint, output;
  std::string precision;
  std::optional<std::string> mode;
  std::vector<py::dict> calib;          // observation dicts, or
  std::vector<std::string> calib_paths;  // sources as act_convert --calib takes them
  size_t calib_samples = 64;
  std::optional<size_t> holdout;
  std::string calib_method;
  double percentile = 99.99;
  std::optional<double> target_mse, max_mse;
  int threads = 0;
  uint64_t seed = 1;
  bool layer_report = true;
  py::object progress;
  std::string attention = "auto";
  std::string linear_inputs = "auto";
  PthOptions pth;
  DeploymentOptions deployment;
};

bool any_pth_option(const PthOptions& p) {
  return !p.config_path.empty() || !p.stats_paths.empty() || p.image_size || p.n_heads ||
         p.activation || !p.cameras.empty() || p.lerobot_defaults || p.no_normalization || !p.state_dict_key.empty();
}

// A conversion's progress, to the logger "actengine" and to convert()'s progress callback if given.
// The callback gets every line (as act_convert prints them on a terminal); the logger, at INFO, a
// task's start, each quarter and its end (as act_convert prints them to a log file), the other lines
// at DEBUG. Used with the GIL held. Handles, not objects: copies of the conversion's callback may be
// destroyed in threads that hold no GIL; convert()'s arguments keep the callback alive, logging's
// registry the logger.
class ProgressLog {
 public:
  explicit ProgressLog(py::handle callback)
      : callback_(callback), logger_(py::module_::import("logging").attr("getLogger")("actengine")) {}

  /// A line of its own: "info" or "warning".
  void message(const char* level, const std::string& text) {
    logger_.attr(level)("%s", text);
    call(text);
  }

  void update(const ConversionProgress& p) {
    if (p.total == 0) return message("info", p.task);
    const std::string line = p.task + ": " + std::to_string(p.done) + "/" + std::to_string(p.total) + " " + p.unit;
    const size_t quarter = p.done * 4 / p.total;
    const bool milestone = p.task != task_ || quarter != quarter_;
    task_ = p.task;
    quarter_ = quarter;
    logger_.attr(milestone ? "info" : "debug")("%s", line);
    call(line);
  }

 private:
  void call(const std::string& line) {
    if (callback_.is_none()) return;
    try {
      callback_(line);
    } catch (py::error_already_set& e) {
      e.discard_as_unraisable("actengine.convert progress callback");
    }
  }

  py::handle callback_, logger_;
  std::string task_;
  size_t quarter_ = 0;
};

// act_convert's option checks (check_options), in the same words with the Python argument names.
Int8Options int8_options(const ConvertArgs& a, const std::shared_ptr<ProgressLog>& log) {
  Int8Options o;
  const std::string mode = a.mode.value_or("static");
  if (mode == "dynamic") {
    o.mode = Int8Mode::kDynamic;
  } else if (mode == "mixed") {
    o.mode = Int8Mode::kMixed;
  } else if (mode != "static") {
    throw py::value_error("mode must be 'dynamic', 'static' or 'mixed', got '" + mode + "'");
  }
  auto method = parse_calibration_method(a.calib_method);
  if (!method.ok()) raise(method.status());
  o.method = *method;
  if (!(a.percentile >= 50.0 && a.percentile <= 100.0)) throw py::value_error("percentile must be in [50, 100]");
  if (a.calib_samples < 1) throw py::value_error("calib_samples must be at least 1");
  o.percentile = a.percentile;
  o.calib_samples = a.calib_samples;
  o.holdout = a.holdout;
  o.target_mse = a.target_mse;
  o.max_mse = a.max_mse;
  o.threads = a.threads;
  o.seed = a.seed;
  o.layer_report = a.layer_report;
  if (o.mode != Int8Mode::kDynamic && a.calib.empty() && a.calib_paths.empty()) {
    throw py::value_error(mode + " quantization needs calibration frames: calib=[observation dict, ...] or calib=path "
                          "(a folder of images, a video, a LeRobot dataset, an act_drive recording; or a list of them), "
                          "or mode='dynamic', which needs none");
  }
  if (a.attention == "int8") {
    o.attention = AttentionPrecision::kInt8;
  } else if (a.attention == "fp32") {
    o.attention = AttentionPrecision::kFp32;
  } else if (a.attention != "auto") {
    throw py::value_error("attention must be 'auto', 'int8' or 'fp32', got '" + a.attention + "'");
  }
  if (a.linear_inputs == "per-token") {
    o.linear_inputs = LinearInputCodes::kPerToken;
  } else if (a.linear_inputs == "per-tensor") {
    o.linear_inputs = LinearInputCodes::kPerTensor;
  } else if (a.linear_inputs != "auto") {
    throw py::value_error("linear_inputs must be 'auto', 'per-token' or 'per-tensor', got '" + a.linear_inputs + "'");
  }
  if (o.mode == Int8Mode::kDynamic && a.linear_inputs != "auto") {
    throw py::value_error("linear_inputs needs calibration (mode='static' or 'mixed'): dynamic mode's linear inputs "
                          "are always per token");
  }
  if (o.mode == Int8Mode::kMixed && !o.target_mse) {
    throw py::value_error("mode='mixed' needs target_mse (held-out MSE in normalised units)");
  }
  o.progress = [log](const ConversionProgress& p) {
    const py::gil_scoped_acquire acquire;
    log->update(p);
  };
  return o;
}

std::unique_ptr<ImportedCheckpoint> import(const ConvertArgs& a, std::vector<std::string>& notes) {
  auto location = locate_checkpoint(a.checkpoint.string());
  if (!location.ok()) raise(location.status());
  if (!location->note.empty()) notes.push_back(location->note);
  if (location->lerobot_folder && any_pth_option(a.pth)) {
    throw py::value_error("the .pth options (config, stats, ...) do not apply to a LeRobot checkpoint folder: its "
                          "config.json and statistics are in the folder");
  }
  py::gil_scoped_release release;
  if (location->lerobot_folder) {
    auto model = import_checkpoint(location->path, {}, a.deployment);
    if (!model.ok()) {
      const py::gil_scoped_acquire acquire;
      raise(model.status());
    }
    return std::move(model).value();
  }
  auto plan = PthPlan::read(location->path, a.pth, a.deployment);
  auto model = plan.ok() ? import_checkpoint(**plan) : StatusOr<std::unique_ptr<ImportedCheckpoint>>(plan.status());
  if (!model.ok()) {
    const py::gil_scoped_acquire acquire;
    raise(model.status());
  }
  return std::move(model).value();
}

// calib=: observation dicts, or paths (str, bytes or os.PathLike; one, or a list) to what act_convert
// --calib takes. Fills a.calib or a.calib_paths.
void read_calib_argument(const py::object& calib, ConvertArgs& a) {
  const auto is_path = [](py::handle h) {
    return py::isinstance<py::str>(h) || py::isinstance<py::bytes>(h) || py::hasattr(h, "__fspath__");
  };
  const py::object fsdecode = py::module_::import("os").attr("fsdecode");
  if (calib.is_none()) return;
  if (is_path(calib)) {
    a.calib_paths.push_back(fsdecode(calib).cast<std::string>());
    return;
  }
  const char* what = "calib takes observation dicts or paths (str or os.PathLike) to frame folders, videos, LeRobot "
                     "datasets, act_drive recordings or observation .safetensors files";
  if (py::isinstance<py::dict>(calib)) throw py::type_error(std::string(what) + ", in a list; got one dict");
  if (!py::isinstance<py::iterable>(calib)) {
    throw py::type_error(std::string(what) + "; got " + py::type::of(calib).attr("__name__").cast<std::string>());
  }
  size_t index = 0;
  for (const py::handle item : calib) {
    if (py::isinstance<py::dict>(item)) {
      a.calib.push_back(py::reinterpret_borrow<py::dict>(item));
    } else if (is_path(item)) {
      a.calib_paths.push_back(fsdecode(item).cast<std::string>());
    } else {
      throw py::type_error(std::string(what) + "; calib[" + std::to_string(index) + "] is a " +
                           py::type::of(item).attr("__name__").cast<std::string>());
    }
    ++index;
  }
  if (!a.calib.empty() && !a.calib_paths.empty()) {
    throw py::value_error("calib takes observation dicts or paths, not both in one list");
  }
}

// The calibration frames: convert()'s dicts, or the files of a.calib_paths read as act_convert reads
// them (through actengine._media, media_api.h). `given`: how many frames the files hold.
CalibrationSet calibration_frames(const ConvertArgs& a, const ModelInfo& model, const Int8Options& int8, ProgressLog& log,
                                  size_t& given) {
  CalibrationSet set;
  if (a.calib_paths.empty()) {
    for (const py::dict& observation : a.calib) set.frames.push_back(calibration_frame_from_dict(model, observation));
    set.preprocessing = "frames given to actengine.convert";
    return set;
  }
  for (const std::string& path : a.calib_paths) {  // act_convert's words, as Python's exception
    std::error_code error;
    if (!std::filesystem::exists(path, error)) {
      PyErr_SetObject(PyExc_FileNotFoundError,
                      py::make_tuple(ENOENT, "calibration source not found", path).ptr());
      throw py::error_already_set();
    }
  }
  py::object media;
  try {
    media = py::module_::import(kMediaModule);
  } catch (py::error_already_set& e) {
    if (!e.matches(PyExc_ImportError)) throw;
    throw EngineError("calibration from files (calib=path) needs actengine's image and video support, the module " +
                      std::string(kMediaModule) + ", which this installation lacks (" + py::str(e.value()).cast<std::string>() +
                      "): build actengine where OpenCV is installed (libopencv-dev), or pass observation dicts");
  }
  const py::object capsule = py::getattr(media, kMediaApiAttribute, py::none());
  const auto* api = static_cast<const MediaApi*>(PyCapsule_IsValid(capsule.ptr(), kMediaApiCapsule)
                                                     ? PyCapsule_GetPointer(capsule.ptr(), kMediaApiCapsule)
                                                     : nullptr);
  if (api == nullptr || api->version != kMediaApiVersion) {
    throw EngineError(std::string(kMediaModule) + " is from another build of actengine: reinstall actengine");
  }
  log.message("info", "reading calibration frames from " + std::to_string(a.calib_paths.size()) + " source(s) ...");
  Status status;
  {
    py::gil_scoped_release release;
    status = api->load_calibration_frames(a.calib_paths, model, calibration_frames_wanted(int8), set, given);
  }
  if (!status.ok()) raise(status);
  for (const auto& note : set.notes) {
    const bool warning = note.rfind("warning: ", 0) == 0;
    log.message(warning ? "warning" : "info", warning ? note : "note: " + note);
  }
  return set;
}

py::dict convert(const ConvertArgs& a) {
  if (a.precision != "fp32" && a.precision != "int8") {
    throw py::value_error("precision must be 'fp32' or 'int8', got '" + a.precision + "'");
  }
  if (a.precision == "fp32" && (!a.calib.empty() || !a.calib_paths.empty() || a.mode || a.max_mse)) {
    throw py::value_error("mode, calib and max_mse need precision='int8'");
  }
  if (a.threads < 0 || a.threads > kMaxThreads) {
    throw py::value_error("threads must be in 0.." + std::to_string(kMaxThreads) + " (0 = one per online core), got " +
                          std::to_string(a.threads));
  }
  const auto log = std::make_shared<ProgressLog>(a.progress);
  const std::optional<Int8Options> int8 = a.precision == "int8" ? std::optional(int8_options(a, log)) : std::nullopt;
  std::vector<std::string> notes;
  const std::unique_ptr<ImportedCheckpoint> model = import(a, notes);
  const ImportSummary& summary = model->summary();
  notes.insert(notes.end(), summary.notes.begin(), summary.notes.end());

  py::dict result;
  result["precision"] = a.precision;
  result["model"] = summary.model.summary;
  result["notes"] = notes;
  if (!int8) {
    StatusOr<uint64_t> bytes = [&] {
      py::gil_scoped_release release;
      return model->write_fp32(a.output.string());
    }();
    if (!bytes.ok()) raise(bytes.status());
    result["bytes"] = *bytes;
    return result;
  }
  size_t frames_given = 0;
  const CalibrationSet calibration = calibration_frames(a, summary.model, *int8, *log, frames_given);
  StatusOr<Int8Report> report = [&] {
    py::gil_scoped_release release;
    return model->write_int8(a.output.string(), calibration, *int8);
  }();
  if (!report.ok()) {
    if (report.status().code() == StatusCode::kFailedPrecondition && int8->max_mse) {
      const std::string target = py::repr(py::float_(*int8->max_mse)).cast<std::string>();
      throw EngineError(report.status().message() + "\nmax_mse " + target + " missed: try mode='mixed', target_mse=" +
                        target + ", more calibration frames, or another calib_method.");
    }
    raise(report.status());
  }
  if (frames_given > 0) report->note_frames_given(frames_given, int8->calib_samples);
  result["bytes"] = report->int8_bytes;
  result["report"] = py::module_::import("json").attr("loads")(report->to_json());
  return result;
}

// CameraInfo and ModelInfo: what a loaded model expects and produces.
void define_model_info(py::module_& m) {
  py::class_<CameraInfo>(m, "CameraInfo", "One camera input: its LeRobot feature key and image size.")
      .def_readonly("key", &CameraInfo::key)
      .def_readonly("height", &CameraInfo::height)
      .def_readonly("width", &CameraInfo::width)
      .def("__repr__", [](const CameraInfo& c) {
        return "CameraInfo('" + c.key + "', " + std::to_string(c.height) + "x" + std::to_string(c.width) + ")";
      });

  py::class_<ModelInfo>(m, "ModelInfo", "What a loaded model expects and produces (from the blob's config).")
      .def_readonly("cameras", &ModelInfo::cameras)
      .def_readonly("state_dim", &ModelInfo::state_dim)
      .def_readonly("env_state_dim", &ModelInfo::env_state_dim)
      .def_readonly("env_state_key", &ModelInfo::env_state_key)
      .def_readonly("action_dim", &ModelInfo::action_dim)
      .def_readonly("action_names", &ModelInfo::action_names)
      .def_readonly("chunk_size", &ModelInfo::chunk_size)
      .def_readonly("n_action_steps", &ModelInfo::n_action_steps)
      .def_readonly("action_low", &ModelInfo::action_low)
      .def_readonly("action_high", &ModelInfo::action_high)
      .def_readonly("state_low", &ModelInfo::state_low)
      .def_readonly("state_high", &ModelInfo::state_high)
      .def_readonly("temporal_ensembling", &ModelInfo::temporal_ensembling)
      .def_readonly("temporal_ensemble_coeff", &ModelInfo::temporal_ensemble_coeff)
      .def_readonly("precision", &ModelInfo::precision)
      .def_readonly("isa", &ModelInfo::isa)
      .def_readonly("kernels", &ModelInfo::kernels)
      .def_readonly("summary", &ModelInfo::summary)
      .def("__repr__", [](const ModelInfo& i) { return "ModelInfo(" + i.summary + ", " + i.precision + ")"; });
}

// Engine, Policy and ChunkScheduler: running a model.
void define_runtime(py::module_& m) {
  py::class_<PyEngine, std::shared_ptr<PyEngine>>(m, "Engine", R"(A converted ACT policy (.actb) ready to run.

Engine(path, threads=0, isa="auto", uarch="auto"): threads 0 = one per online core; isa "auto" (or
ACT_ISA) picks the best kernels this CPU runs, uarch "auto" (or ACT_UARCH) tunes them for this core
(model_info.kernels says which). Observations are dicts keyed by LeRobot feature names.)")
      .def(py::init<const std::filesystem::path&, int, const std::string&, const std::string&>(), py::arg("path"),
           py::arg("threads") = 0, py::arg("isa") = "auto", py::arg("uarch") = "auto")
      .def_property_readonly("model_info", checked<kEngineType>(&PyEngine::model_info), py::return_value_policy::reference_internal)
      .def_property_readonly("threads", checked<kEngineType>(&PyEngine::threads))
      .def("infer", [](py::handle e, const py::dict& obs) { return initialised<PyEngine>(e, kEngineType).infer(obs, false); },
           py::arg("observation"), "The raw action chunk, float32 (chunk_size, action_dim), for one observation.")
      .def("infer_normalized", [](py::handle e, const py::dict& obs) { return initialised<PyEngine>(e, kEngineType).infer(obs, true); },
           py::arg("observation"), "The network's normalised action chunk (before un-normalisation).");

  py::class_<PyPolicy>(m, "Policy", R"(LeRobot's select_action on an Engine: the n_action_steps queue, or
temporal ensembling when the model's config asks for it. One action per call.)")
      .def(py::init<std::shared_ptr<PyEngine>>(), py::arg("engine"))
      .def("select_action", checked<kPolicyType>(&PyPolicy::select_action), py::arg("observation"),
           "The raw action (float32, action_dim) for this control step.")
      .def("reset", checked<kPolicyType>(&PyPolicy::reset), "Empties the queue / ensemble (call at the start of an episode).")
      .def("will_infer_next", checked<kPolicyType>(&PyPolicy::will_infer_next), "True when the next select_action runs the network.");

  py::class_<PyChunkScheduler>(m, "ChunkScheduler", R"(Chunks in, one action per control tick out, for a
robot that keeps acting while the next chunk is inferred (actengine/scheduler.h).)")
      .def(py::init<const ModelInfo&>(), py::arg("model_info"))
      .def("add", checked<kSchedulerType>(&PyChunkScheduler::add), py::arg("chunk"), py::arg("observation_tick"),
           "Adds a chunk (chunk_size, action_dim) predicted from the observation captured at observation_tick.")
      .def("action_at", checked<kSchedulerType>(&PyChunkScheduler::action_at), py::arg("tick"),
           "The action for tick, or None when no chunk covers it.")
      .def("wants_inference", checked<kSchedulerType>(&PyChunkScheduler::wants_inference), py::arg("tick"), py::arg("lead_ticks") = 0,
           "True when the next inference should start at tick (lead_ticks: its latency in ticks plus a margin).")
      .def("clear", checked<kSchedulerType>(&PyChunkScheduler::clear), "Forgets every chunk (a new episode, or a fault).");
}

// convert(): act_convert's conversion, with its options as keyword arguments.
void define_convert(py::module_& m) {
  m.def(
      "convert",
      [](const std::filesystem::path& checkpoint, const std::filesystem::path& output, const std::string& precision,
         const std::optional<std::string>& mode, const py::object& calib, size_t calib_samples,
         const std::optional<size_t>& holdout, const std::string& calib_method, double percentile,
         const std::optional<double>& target_mse, const std::optional<double>& max_mse, int threads, uint64_t seed,
         bool layer_report, const py::object& progress, const std::string& attention, const std::string& linear_inputs,
         const std::optional<double>& temporal_ensemble_coeff, bool no_temporal_ensembling,
         const std::optional<std::string>& config,
         const std::vector<std::string>& stats, const std::optional<std::pair<int, int>>& image_size,
         const std::optional<int>& n_action_steps, const std::optional<int>& n_heads,
         const std::optional<std::string>& activation, const std::vector<std::string>& cameras, bool lerobot_defaults,
         bool no_normalization, const std::optional<std::string>& state_dict_key) {
        ConvertArgs a{checkpoint, output, precision, mode, {}, {}, calib_samples, holdout, calib_method, percentile,
                      target_mse, max_mse, threads, seed, layer_report, progress, attention, linear_inputs, {}, {}};
        read_calib_argument(calib, a);
        if (temporal_ensemble_coeff && no_temporal_ensembling) {
          throw py::value_error("give temporal_ensemble_coeff or no_temporal_ensembling, not both");
        }
        a.deployment.n_action_steps = n_action_steps;
        if (temporal_ensemble_coeff) a.deployment.temporal_ensemble_coeff = temporal_ensemble_coeff;
        if (no_temporal_ensembling) a.deployment.temporal_ensemble_coeff = std::optional<double>{};
        a.pth.config_path = config.value_or("");
        a.pth.stats_paths = stats;
        a.pth.image_size = image_size;
        a.pth.n_heads = n_heads;
        a.pth.activation = activation;
        a.pth.cameras = cameras;
        a.pth.lerobot_defaults = lerobot_defaults;
        a.pth.no_normalization = no_normalization;
        a.pth.state_dict_key = state_dict_key.value_or("");
        return convert(a);
      },
      R"(Converts a LeRobot ACT checkpoint (folder, training output or .pth) into an .actb blob, as act_convert does.

precision "int8" (default) or "fp32". INT8: mode "static" (default; needs calib), "dynamic" (no
calibration) or "mixed" (needs target_mse); calib is what act_convert --calib takes: a path (str or
os.PathLike) or a list of paths to folders of images, videos, LeRobot datasets, act_drive recordings or
observation .safetensors files (read with OpenCV, as act_convert reads them), or a list of observation
dicts (uint8 HxWx3 images at the model's input size, states optional); calib_samples, holdout, calib_method ("minmax", "percentile",
"mse"), percentile, max_mse (fail, writing nothing, above it), threads, seed, layer_report,
attention ("auto", "int8", "fp32": act_convert --attention), linear_inputs ("auto", "per-token",
"per-tensor": act_convert --linear-inputs) and progress (called with each
progress line). Progress also goes to the logger "actengine" (logging: INFO for each task's start,
quarters and end, the calibration frames' notes and warnings; DEBUG for every other line). Deployment settings for every input: n_action_steps, temporal_ensemble_coeff (turns
ensembling on; needs n_action_steps 1) or no_temporal_ensembling. A .pth takes act_convert's
options: config, stats, image_size (height, width), n_heads, activation, cameras, lerobot_defaults,
no_normalization, state_dict_key.

Returns a dict: precision, bytes (the blob's size), model (one-line summary), notes, and for INT8 the
accuracy report against FP32 (report: act_convert --report's JSON). Nothing is written on failure.)",
      py::arg("checkpoint"), py::arg("output"), py::arg("precision") = "int8", py::kw_only(),
      py::arg("mode") = py::none(), py::arg("calib") = py::none(), py::arg("calib_samples") = 64,
      py::arg("holdout") = py::none(), py::arg("calib_method") = "mse", py::arg("percentile") = 99.99,
      py::arg("target_mse") = py::none(), py::arg("max_mse") = py::none(), py::arg("threads") = 0,
      py::arg("seed") = 1, py::arg("layer_report") = true, py::arg("progress") = py::none(),
      py::arg("attention") = "auto", py::arg("linear_inputs") = "auto", py::arg("temporal_ensemble_coeff") = py::none(),
      py::arg("no_temporal_ensembling") = false,
      py::arg("config") = py::none(), py::arg("stats") = std::vector<std::string>{},
      py::arg("image_size") = py::none(), py::arg("n_action_steps") = py::none(), py::arg("n_heads") = py::none(),
      py::arg("activation") = py::none(), py::arg("cameras") = std::vector<std::string>{},
      py::arg("lerobot_defaults") = false, py::arg("no_normalization") = false,
      py::arg("state_dict_key") = py::none());
}

void define_module(py::module_& m) {
  m.doc() = "actengine: run a converted LeRobot ACT policy (.actb) on the CPU, and convert checkpoints";
  m.attr("__version__") = version();
  py::register_exception<EngineError>(m, "Error", PyExc_RuntimeError);

  define_model_info(m);
  define_runtime(m);
  define_convert(m);
}

}  // namespace
}  // namespace act::python

PYBIND11_MODULE(_actengine, m) { act::python::define_module(m); }
