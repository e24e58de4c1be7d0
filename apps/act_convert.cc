// act_convert: LeRobot ACT checkpoint folder or PyTorch .pth state dict -> .actb blob [+ robot package]
// [+ ONNX model]; or an .actb blob -> ONNX model.
// A command line over the conversion API (actengine/convert.h) and the ONNX export
// (actengine/onnx_export.h); calibration frames are read from files here (apps/convert/calib_frames.h, OpenCV).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <fcntl.h>
#include <unistd.h>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "actengine/calibration_files.h"
#include "apps/convert/npy_file.h"
#include "apps/deploy_package.h"
#include "apps/eval/html_report.h"
#include "apps/progress.h"
#include "apps/pytorch_options.h"
#include "apps/version.h"
#ifdef ACT_ONNX_EXPORT
#include "actengine/onnx_export.h"
#endif
#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace {

struct Options {
  std::string checkpoint, output, package, report_path;
  std::string precision = "fp32", mode = "static", method = "mse", attention = "auto", linear_inputs = "auto";
  bool quiet = false, explain = false;
  act::PthOptions pth;
  act::DeploymentOptions deployment;
  std::vector<std::string> calib_sources;
  act::Int8Options int8;
  double target_mse = 0, max_mse = 0, percentile = 99.99;
  size_t holdout = 0;
  std::string onnx_path, onnx_part = "full", onnx_normalization = "in";
  std::string calib_npy;
  std::vector<std::string> action_names;  // --action-names: stored in the blob, used by the report
};

bool is_blob(const std::string& path) { return std::filesystem::path(path).extension() == ".actb"; }

void add_options(CLI::App& app, Options& o) {
  app.add_option("checkpoint", o.checkpoint,
                 "LeRobot checkpoint folder (config.json + model.safetensors [+ processor files]), or a torch.save "
                 ".pth/.pt file holding the policy's state dict")
      ->required();
  app.add_option("-o,--output", o.output, "output .actb file (written atomically)");
  app.add_option("--package", o.package, "write a folder for the robot: the blob (" + std::string(act::kPackageBlobName) +
                 "), a drive calibration template, a README, and LeRobot's config.json and processor files (--policy.path with the lerobot_policy_actengine plugin)");
  app.add_flag("--explain", o.explain, "print every config value and where it comes from (for a .pth: which tensor, file "
               "or flag), and what cannot be known; converts too if -o or --package is given");
  act::add_pytorch_options(app, o.pth);
  act::add_deployment_options(app, o.deployment);
  app.add_option("--precision", o.precision, "weight precision of the blob (default fp32)")->check(CLI::IsMember({"fp32", "int8"}));
  auto* int8_group = app.add_option_group("INT8", "with --precision int8");
  int8_group->add_option("--mode", o.mode,
                         "dynamic: activations quantized at run time, no calibration; static (default): calibrated "
                         "backbone, int8 from layer to layer; mixed: static, keeping in float the fewest layers that "
                         "meet --target-mse")
      ->check(CLI::IsMember({"dynamic", "static", "mixed"}));
  int8_group->add_option("--calib", o.calib_sources,
                         "calibration frames: a folder of images, a video, a LeRobot dataset folder, an act_drive "
                         "--record folder or an observation .safetensors file (repeatable)");
  int8_group->add_option("--calib-samples", o.int8.calib_samples, "frames used for calibration (default 64)")->check(CLI::Range(1, 100000));
  int8_group->add_option("--holdout", o.holdout, "frames kept out of calibration for the accuracy report (default: a fifth, 1..16)");
  int8_group->add_option("--calib-method", o.method, "activation range choice: minmax, percentile or mse (default)")
      ->check(CLI::IsMember({"minmax", "percentile", "mse"}));
  int8_group->add_option("--percentile", o.percentile, "percentile for --calib-method percentile (default 99.99)")
      ->check(CLI::Range(50.0, 100.0));
  int8_group->add_option("--attention", o.attention,
                         "attention's matmuls: auto (default: int8 when that raises the held-out error by 25 % at "
                         "most), int8 or fp32")
      ->check(CLI::IsMember({"auto", "int8", "fp32"}));
  int8_group->add_option("--linear-inputs", o.linear_inputs,
                         "codes of the transformer linears' inputs (static, mixed): auto (default: calibrated per "
                         "tensor for the FFNs' hidden activations where that raises the held-out MSE by 10 % and "
                         "max |err| by 25 % at most, else per token), per-token or per-tensor")
      ->check(CLI::IsMember({"auto", "per-token", "per-tensor"}));
  int8_group->add_option("--keep-float", o.int8.keep_float, "layers to keep in float, comma-separated, named as the "
                         "report's per-layer SQNR names them (their weights, e.g. backbone.conv1.weight)")->delimiter(',');
  int8_group->add_option("--target-mse", o.target_mse, "mixed: held-out action MSE to meet, normalised units");
  int8_group->add_option("--max-mse", o.max_mse, "fail, writing nothing, when the held-out action MSE (normalised) is above this");
  int8_group->add_option("--report", o.report_path, "also write the accuracy report to this file: JSON, or a "
                         "self-contained HTML page when the name ends in .html");
  app.add_option("--action-names", o.action_names, "names of the action dimensions, comma-separated, e.g. "
                 "steering,throttle: stored in the blob for the INT8 report, act_eval's reports and act_drive's "
                 "recordings (default [0], [1], ...; recordings action.0, command.0, ...)")->delimiter(',');
  int8_group->add_option("--threads", o.int8.threads, "threads for calibration and evaluation (0 = all cores)")->check(CLI::Range(0, act::kMaxThreads));
  app.add_flag("-q,--quiet", o.quiet, "print nothing but errors");
#ifdef ACT_ONNX_EXPORT
  auto* onnx = app.add_option_group("ONNX", "export an ONNX model (from the blob just converted, or from an .actb given "
                                    "as the checkpoint; an int8 blob exports as QDQ)");
  onnx->add_option("--export-onnx", o.onnx_path, "write the ONNX model here (opset 17, batch 1, static shapes)");
  onnx->add_option("--onnx-part", o.onnx_part, "full (default): the whole policy; backbone: each camera's ResNet and input "
                   "projection (for an accelerator; run the rest with the split engine)")
      ->check(CLI::IsMember({"full", "backbone"}));
  onnx->add_option("--onnx-normalization", o.onnx_normalization, "in (default): raw observations in, raw actions out; "
                   "out: the caller normalises")
      ->check(CLI::IsMember({"in", "out"}));
#endif
  app.add_option("--export-calib", o.calib_npy, "write --calib-samples frames of the --calib sources as NumPy float32 "
                 "[N, H, W, 3] RGB in [0, 1] (NHWC: what the Hailo Dataflow Compiler calibrates on for the ONNX model's "
                 "camera input); with several cameras one file per camera, FILE.<camera>.npy");
}

// The checks that need to know which flags were given; fills what depends on them.
void check_options(const CLI::App& app, Options& o) {
  if (o.onnx_path.empty() && (app.count("--onnx-part") || app.count("--onnx-normalization"))) {
    act::fail(act::StatusCode::kInvalidArgument, "--onnx-part and --onnx-normalization need --export-onnx FILE.onnx");
  }
  // The ONNX model is written last: a folder that is not there fails now, before any conversion.
  if (const auto dir = std::filesystem::path(o.onnx_path).parent_path(); !o.onnx_path.empty() && !dir.empty() &&
                                                                         !std::filesystem::is_directory(dir)) {
    act::fail(act::StatusCode::kIoError, "--export-onnx " + o.onnx_path + ": there is no folder " + dir.string());
  }
  if (!o.calib_npy.empty() && o.calib_sources.empty()) {
    act::fail(act::StatusCode::kInvalidArgument, "--export-calib needs the frames' sources: --calib DIR|VIDEO|DATASET|OBS.safetensors");
  }
  if (!o.calib_npy.empty() && o.onnx_normalization == "out") {
    act::fail(act::StatusCode::kInvalidArgument, "--export-calib writes images in [0, 1], the input of an ONNX model exported "
              "with --onnx-normalization in (the default)");
  }
  if (is_blob(o.checkpoint)) {
    // A blob only exports: say what it is when nothing is asked that a blob can give.
    if (o.onnx_path.empty() && o.calib_npy.empty()) {
      const auto location = act::locate_checkpoint(o.checkpoint);
      if (!location.ok()) throw act::Error(location.status());
    }
    if (app.count("--precision") || !o.output.empty() || !o.package.empty() || o.explain) {
      act::fail(act::StatusCode::kInvalidArgument, o.checkpoint + " is an .actb blob, already converted: with a blob, "
                "act_convert only exports (--export-onnx, --export-calib); -o, --package, --precision and --explain need a checkpoint");
    }
    return;
  }
  if (o.precision == "fp32" && ((!o.calib_sources.empty() && o.calib_npy.empty()) || app.count("--mode") || app.count("--max-mse") ||
                                app.count("--report") || app.count("--attention") || app.count("--keep-float") ||
                                app.count("--linear-inputs"))) {
    act::fail(act::StatusCode::kInvalidArgument, "--mode, --calib, --attention, --linear-inputs, --keep-float, --max-mse "
              "and --report need --precision int8");
  }
  if (!o.package.empty()) {
    if (!o.output.empty()) act::fail(act::StatusCode::kInvalidArgument, "give either -o or --package (which writes " +
                                     std::string(act::kPackageBlobName) + " into the folder)");
    o.output = act::prepare_package_dir(o.package);
  }
  if (o.output.empty() && !o.explain && o.onnx_path.empty() && o.calib_npy.empty()) {
    act::fail(act::StatusCode::kInvalidArgument, "--output (or --package, --explain, --export-onnx or --export-calib) is required");
  }
  if (std::filesystem::is_directory(o.checkpoint) && act::any_pytorch_option(app)) {
    act::fail(act::StatusCode::kInvalidArgument, "the .pth options (--config, --stats, ...) do not apply to a LeRobot "
              "checkpoint folder: its config.json and statistics are in the folder");
  }
  act::Int8Options& int8 = o.int8;
  int8.mode = o.mode == "dynamic" ? act::Int8Mode::kDynamic : o.mode == "mixed" ? act::Int8Mode::kMixed : act::Int8Mode::kStatic;
  int8.method = act::parse_calibration_method(o.method).value();  // CLI11 checked the name
  int8.percentile = o.percentile;
  int8.attention = o.attention == "int8"   ? act::AttentionPrecision::kInt8
                   : o.attention == "fp32" ? act::AttentionPrecision::kFp32
                                           : act::AttentionPrecision::kAuto;
  int8.linear_inputs = o.linear_inputs == "per-token"    ? act::LinearInputCodes::kPerToken
                       : o.linear_inputs == "per-tensor" ? act::LinearInputCodes::kPerTensor
                                                         : act::LinearInputCodes::kAuto;
  if (int8.mode == act::Int8Mode::kDynamic && app.count("--linear-inputs")) {
    act::fail(act::StatusCode::kInvalidArgument, "--linear-inputs needs calibration (--mode static or mixed): dynamic "
              "mode's linear inputs are always per token");
  }
  if (app.count("--holdout")) int8.holdout = o.holdout;
  if (app.count("--target-mse")) int8.target_mse = o.target_mse;
  if (app.count("--max-mse")) int8.max_mse = o.max_mse;
  if (o.precision == "int8" && int8.mode != act::Int8Mode::kDynamic && o.calib_sources.empty()) {
    act::fail(act::StatusCode::kInvalidArgument, o.mode + " quantization needs calibration frames: --calib "
              "DIR|VIDEO|DATASET|OBS.safetensors (or --mode dynamic, which needs none)");
  }
  if (int8.mode == act::Int8Mode::kMixed && !int8.target_mse) {
    act::fail(act::StatusCode::kInvalidArgument, "--mode mixed needs --target-mse (held-out MSE in normalised units)");
  }
}

// Imports the checkpoint, printing the --explain report first when asked. Null when only the
// explanation was asked for (`exit_code` then says whether everything could be known).
std::unique_ptr<act::ImportedCheckpoint> import(const Options& o, int& exit_code) {
  const auto location = act::locate_checkpoint(o.checkpoint);
  if (!location.ok()) throw act::Error(location.status());
  if (!o.quiet) std::cerr << "reading " << location->path << " ...\n";
  if (!location->note.empty()) std::cerr << "act_convert: " << location->note << "\n";
  if (location->lerobot_folder) {
    if (o.explain) {
      std::cout << "checkpoint   " << location->path << ": a LeRobot checkpoint folder; every value comes from its config.json"
                << (o.deployment.n_action_steps || o.deployment.temporal_ensemble_coeff ? " but the deployment options given" : "")
                << "\n";
    }
    exit_code = 0;
    if (o.output.empty() && o.onnx_path.empty() && o.calib_npy.empty()) return nullptr;
    auto model = act::import_checkpoint(location->path, {}, o.deployment);
    if (!model.ok()) throw act::Error(model.status());
    return std::move(model).value();
  }
  auto plan = act::PthPlan::read(location->path, o.pth, o.deployment);
  if (!plan.ok()) throw act::Error(plan.status());
  if (o.explain) act::print_explanation(std::cout, (*plan)->explanation());
  exit_code = (*plan)->explanation().missing.empty() ? 0 : 1;
  if (o.explain && o.output.empty() && o.onnx_path.empty() && o.calib_npy.empty()) return nullptr;
  auto model = act::import_checkpoint(**plan);
  if (!model.ok()) throw act::Error(model.status());
  return std::move(model).value();
}

// The report as JSON, with the action names.
nlohmann::ordered_json report_json(const act::Int8Report& report, const Options& o) {
  nlohmann::ordered_json int8 = nlohmann::ordered_json::parse(report.to_json());
  if (!o.action_names.empty()) int8["action_names"] = o.action_names;
  return int8;
}

// The printed report with the action dimensions named ("  [0] " -> "  steering ").
std::string report_text(const act::Int8Report& report, const Options& o) {
  std::string text = report.to_text();
  for (size_t a = 0; a < o.action_names.size(); ++a) {
    const std::string label = "\n  [" + std::to_string(a) + "] ";
    if (const size_t at = text.find(label); at != std::string::npos) text.replace(at, label.size(), "\n  " + o.action_names[a] + " ");
  }
  return text;
}

// --report FILE.html: the conversion report as a page (the one renderer act_eval's reports use too).
std::string html_report(const act::Int8Report& report, const Options& o) {
  nlohmann::ordered_json int8 = report_json(report, o);
  int8["calibration_sources"] = o.calib_sources;
  return act::eval::render_html_report({{"title", "act_convert: " + o.checkpoint + " -> " + o.output}, {"int8", int8}});
}

// --action-names into the model, so that the blobs written carry them.
void name_actions(act::ImportedCheckpoint& model, const Options& o) {
  if (o.action_names.empty()) return;
  const int action_dim = model.summary().model.action_dim;
  if (o.action_names.size() != static_cast<size_t>(action_dim)) {
    act::fail(act::StatusCode::kInvalidArgument, "--action-names gives " + std::to_string(o.action_names.size()) +
              " names but the model's actions have " + std::to_string(action_dim) + " values");
  }
  if (const act::Status named = model.set_action_names(o.action_names); !named.ok()) {
    act::fail(act::StatusCode::kInvalidArgument, "--action-names: " + named.message());
  }
}

// Writes the blob (INT8: calibrated on the --calib frames, its report printed). Returns its size.
uint64_t convert(const act::ImportedCheckpoint& model, const Options& o) {
  if (o.precision != "int8") {
    auto bytes = model.write_fp32(o.output);
    if (!bytes.ok()) throw act::Error(bytes.status());
    return *bytes;
  }
  std::optional<act::ProgressLine> progress;
  act::Int8Options int8 = o.int8;
  if (!o.quiet) {
    progress.emplace(stderr, "act_convert", act::ProgressLine::stderr_is_terminal());
    int8.progress = [&progress](const act::ConversionProgress& p) {
      if (p.total == 0) {
        progress->message(p.task);
      } else {
        progress->update(p.task, p.done, p.total, p.unit);
      }
    };
  }
  act::CalibrationSet frames;
  size_t frames_given = 0;
  if (!o.calib_sources.empty()) {
    if (progress) progress->message("reading calibration frames from " + std::to_string(o.calib_sources.size()) + " source(s) ...");
    auto read = act::load_calibration_frames(o.calib_sources, model.summary().model, act::calibration_frames_wanted(int8),
                                             &frames_given);
    if (!read.ok()) throw act::Error(read.status());
    frames = std::move(read).value();
    if (progress) {
      for (const auto& note : frames.notes) progress->message(note.rfind("warning: ", 0) == 0 ? note : "note: " + note);
    }
  }
  // The report file is created (unnamed until written) before the conversion, so a folder that does
  // not exist fails at once instead of after the blob was written.
  std::optional<act::detail::AtomicFileWriter> report_file;
  if (!o.report_path.empty()) report_file.emplace(o.report_path);
  auto report = model.write_int8(o.output, frames, int8);
  if (progress) progress->finish();
  if (!report.ok() && report.status().code() == act::StatusCode::kFailedPrecondition && o.int8.max_mse) {
    std::cerr << "act_convert: --max-mse " << *o.int8.max_mse << " missed: try --mode mixed --target-mse "
              << *o.int8.max_mse << ", more calibration frames, or another --calib-method.\n";
  }
  if (!report.ok()) throw act::Error(report.status());
  if (frames_given > 0) report->note_frames_given(frames_given, int8.calib_samples);
  if (report_file) {
    report_file->write(std::filesystem::path(o.report_path).extension() == ".html" ? html_report(*report, o)
                                                                                  : report_json(*report, o).dump(2) + "\n");
    report_file->commit();
  }
  if (!o.quiet) std::cout << report_text(*report, o);
  return report->int8_bytes;
}

std::string human_bytes(double bytes) {
  char buf[32];
  if (bytes >= 1e6) {
    std::snprintf(buf, sizeof buf, "%.1f MB", bytes / 1e6);
  } else {
    std::snprintf(buf, sizeof buf, "%.1f kB", bytes / 1e3);
  }
  return buf;
}

std::string gmac(double macs) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", macs / 1e9);
  return buf;
}

std::string millions(double n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f M", n / 1e6);
  return buf;
}

void print_summary(const act::ImportSummary& s, const Options& o, uint64_t bytes) {
  const act::ModelInfo& m = s.model;
  std::cout << "checkpoint   " << o.checkpoint << " (" << s.source << ")\n"
            << "model        " << m.summary << "\n"
            << "tokens       " << s.encoder_tokens << " encoder, " << m.chunk_size << " decoder; n_action_steps "
            << m.n_action_steps;
  if (m.temporal_ensembling) std::cout << ", temporal ensembling coeff " << m.temporal_ensemble_coeff;
  std::cout << "\n";
  if (!m.action_names.empty()) {
    std::cout << "actions     ";
    for (size_t a = 0; a < m.action_names.size(); ++a) std::cout << (a ? ", " : " ") << m.action_names[a];
    std::cout << " (stored in the blob: reports and recordings use them)\n";
  }
  std::cout
            << "parameters   " << millions(static_cast<double>(s.checkpoint_values)) << " in " << s.checkpoint_tensors
            << " checkpoint tensors; dropped " << millions(static_cast<double>(s.training_only_values))
            << " training-only (" << s.training_only_tensors << " tensors)\n"
            << "blob         " << millions(static_cast<double>(s.blob_values)) << " values after BN folding and "
            << "constant folding, fp32\n"
            << "compute      " << gmac(s.macs) << " GMAC per inference (backbone " << gmac(s.backbone_macs)
            << ", encoder " << gmac(s.encoder_macs) << ", decoder " << gmac(s.decoder_macs) << ")\n"
            << "wrote        " << o.output << " (" << human_bytes(static_cast<double>(bytes)) << ")\n";
  if (!o.package.empty()) std::cout << "package      " << o.package << " (blob, drive_calibration.json, README.md, LeRobot's config.json and processors)\n";
  for (const auto& note : s.notes) std::cout << "note: " << note << "\n";
}

// --export-calib: the frames as the ONNX model's camera inputs take them, NHWC, one file per camera
// (all of them or none).
void export_calibration(const act::ModelInfo& model, const Options& o) {
  auto read = act::load_calibration_frames(o.calib_sources, model, o.int8.calib_samples);
  if (!read.ok()) throw act::Error(read.status());
  const act::CalibrationSet set = std::move(read).value();
  const std::filesystem::path given(o.calib_npy);
  std::vector<std::unique_ptr<act::detail::AtomicFileWriter>> files;
  std::string lines;
  for (size_t c = 0; c < model.cameras.size(); ++c) {
    const act::CameraInfo& cam = model.cameras[c];
    std::string path = o.calib_npy;
    if (model.cameras.size() > 1) {
      const std::string name = cam.key.substr(cam.key.rfind('.') + 1);  // "observation.images.top" -> "top"
      path = (given.parent_path() / (given.stem().string() + "." + name + ".npy")).string();
    }
    std::vector<float> values;
    values.reserve(set.frames.size() * static_cast<size_t>(cam.height) * cam.width * 3);
    for (const auto& frame : set.frames) {
      for (uint8_t v : frame.images[c]) values.push_back(static_cast<float>(v) / 255.0f);  // as the engine converts
    }
    files.push_back(std::make_unique<act::detail::AtomicFileWriter>(path));
    act::write_npy_f32(*files.back(), {static_cast<int64_t>(set.frames.size()), cam.height, cam.width, 3}, values);
    lines += "calibration  " + path + " (" + std::to_string(set.frames.size()) + " frames of " + cam.key + ", float32 [N, " +
             std::to_string(cam.height) + ", " + std::to_string(cam.width) + ", 3], RGB in [0, 1])\n";
  }
  for (auto& file : files) file->commit();
  if (!o.quiet) std::cout << lines;
}

#ifdef ACT_ONNX_EXPORT
void export_onnx(const std::string& blob, const Options& o) {
  act::OnnxExportOptions options;
  options.part = act::parse_onnx_part(o.onnx_part).value();  // CLI11 checked the names
  options.normalization = act::parse_onnx_normalization(o.onnx_normalization).value();
  auto summary = act::export_onnx(blob, o.onnx_path, options);
  if (!summary.ok()) throw act::Error(summary.status());
  if (o.quiet) return;
  const auto list = [](const std::vector<act::OnnxTensorInfo>& tensors) {
    std::string text;
    for (const auto& t : tensors) {
      text += (text.empty() ? "" : ", ") + t.name + " [";
      for (size_t i = 0; i < t.shape.size(); ++i) text += (i ? ", " : "") + std::to_string(t.shape[i]);
      text += "]";
    }
    return text;
  };
  std::cout << "onnx         " << o.onnx_path << " (" << o.onnx_part << ", " << summary->precision
            << (summary->precision == "fp32" ? "" : " as QDQ") << ", normalization " << o.onnx_normalization << ", "
            << summary->nodes << " nodes, " << human_bytes(static_cast<double>(summary->bytes)) << "; passes onnx::checker)\n"
            << "  inputs     " << list(summary->inputs) << "\n"
            << "  outputs    " << list(summary->outputs) << "\n";
}

// A blob only for the export, in the ONNX file's folder: written atomically like any blob (no name
// until complete), then opened and its name removed at once, so that the export reads it through
// /proc/self/fd and an interrupted run leaves nothing behind.
class ScratchBlob {
 public:
  explicit ScratchBlob(const std::string& beside) {
    const std::filesystem::path dir = std::filesystem::path(beside).parent_path();
    path_ = ((dir.empty() ? std::filesystem::path(".") : dir) / (".act_convert_export." + std::to_string(getpid()) + ".actb")).string();
  }
  ~ScratchBlob() {
    if (fd_ >= 0) close(fd_);
    else std::remove(path_.c_str());
  }
  ScratchBlob(const ScratchBlob&) = delete;
  ScratchBlob& operator=(const ScratchBlob&) = delete;
  /// Where the conversion writes the blob.
  const std::string& path() const { return path_; }
  /// After the conversion: the blob, its name removed, as a path that still opens it.
  std::string unnamed() {
    fd_ = open(path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) act::fail(act::StatusCode::kIoError, "cannot reopen the blob converted for the export, " + path_);
    std::remove(path_.c_str());
    return "/proc/self/fd/" + std::to_string(fd_);
  }

 private:
  std::string path_;
  int fd_ = -1;
};
#endif

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_convert: convert a LeRobot ACT checkpoint folder (current or legacy layout), or a PyTorch .pth "
               "state dict, into an .actb blob that libactengine runs."};
  Options o;
  add_options(app, o);
  app.set_version_flag("--version", act::version_line("act_convert"));
  CLI11_PARSE(app, argc, argv);

  // No signal handling needed: every file (blob, intermediate blobs, report) is written as an unnamed
  // file that gets its name only when complete, so SIGINT or SIGTERM at any point leaves nothing.
  try {
    check_options(app, o);
    if (is_blob(o.checkpoint)) {
      if (!o.calib_npy.empty()) {
        auto engine = act::Engine::open(o.checkpoint, {.threads = 1});
        if (!engine.ok()) throw act::Error(engine.status());
        export_calibration((*engine)->model_info(), o);
      }
#ifdef ACT_ONNX_EXPORT
      if (!o.onnx_path.empty()) export_onnx(o.checkpoint, o);
#endif
      return 0;
    }
#ifdef ACT_ONNX_EXPORT
    std::optional<ScratchBlob> scratch;
    if (!o.onnx_path.empty() && o.output.empty()) {
      scratch.emplace(o.onnx_path);
      o.output = scratch->path();
    }
#endif
    int exit_code = 0;
    const std::unique_ptr<act::ImportedCheckpoint> model = import(o, exit_code);
    if (!model) return exit_code;
    name_actions(*model, o);
    if (o.action_names.empty()) o.action_names = model->summary().model.action_names;  // the checkpoint's, for the report
    if (!o.calib_npy.empty()) export_calibration(model->summary().model, o);
    if (o.output.empty()) return 0;  // only the calibration set was asked for
    const uint64_t bytes = convert(*model, o);
    if (!o.package.empty()) act::write_deploy_package(o.package, model->summary().model, o.checkpoint);
#ifdef ACT_ONNX_EXPORT
    if (scratch) {  // only the ONNX model was asked for
      export_onnx(scratch->unnamed(), o);
      return 0;
    }
    if (!o.onnx_path.empty()) export_onnx(o.output, o);
#endif
    if (!o.quiet) print_summary(model->summary(), o, bytes);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "act_convert: error: " << e.what() << "\n";
    return 1;
  }
}
