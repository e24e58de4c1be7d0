// act_convert: LeRobot ACT checkpoint folder or PyTorch .pth state dict -> .actb blob [+ robot package].
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>

#include "apps/convert/calib_frames.h"
#include "apps/convert/int8_conversion.h"
#include "apps/deploy_package.h"
#include "apps/pytorch_options.h"
#include "weights/import/config_inference.h"
#include "weights/blob/error.h"
#include "weights/blob/file_util.h"
#include "weights/import/lerobot_import.h"
#include "apps/signal_cleanup.h"

namespace {

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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_convert: convert a LeRobot ACT checkpoint folder (current or legacy layout), or a PyTorch .pth "
               "state dict, into an .actb blob that libactengine runs."};
  std::string checkpoint, output, precision = "fp32", package, mode = "static", method = "mse", report_path;
  bool quiet = false, explain = false;
  act::ConfigSources pth_sources;
  act::Int8Options int8;
  double target_mse = 0, max_mse = 0;
  size_t holdout = 0;
  app.add_option("checkpoint", checkpoint,
                 "LeRobot checkpoint folder (config.json + model.safetensors [+ processor files]), or a torch.save "
                 ".pth/.pt file holding the policy's state dict")
      ->required();
  app.add_option("-o,--output", output, "output .actb file (written atomically)");
  app.add_option("--package", package, "write a folder for the robot: the blob (" + std::string(act::kPackageBlobName) +
                 "), a drive calibration template and a README");
  app.add_flag("--explain", explain, "print every config value and where it comes from (for a .pth: which tensor, file "
               "or flag), and what cannot be known; converts too if -o or --package is given");
  act::add_pytorch_options(app, pth_sources);
  app.add_option("--precision", precision, "weight precision of the blob (default fp32)")->check(CLI::IsMember({"fp32", "int8"}));
  auto* int8_group = app.add_option_group("INT8", "with --precision int8");
  int8_group->add_option("--mode", mode,
                         "dynamic: activations quantized at run time, no calibration; static (default): calibrated "
                         "backbone, int8 from layer to layer; mixed: static, keeping in float the fewest layers that "
                         "meet --target-mse")
      ->check(CLI::IsMember({"dynamic", "static", "mixed"}));
  int8_group->add_option("--calib", int8.calib_sources,
                         "calibration frames: a folder of images, a video, a LeRobot dataset folder, an act_drive "
                         "--record folder or an observation .safetensors file (repeatable)");
  int8_group->add_option("--calib-samples", int8.calib_samples, "frames used for calibration (default 64)")->check(CLI::Range(1, 100000));
  int8_group->add_option("--holdout", holdout, "frames kept out of calibration for the accuracy report (default: a fifth, 1..16)");
  int8_group->add_option("--calib-method", method, "activation range choice: minmax, percentile or mse (default)")
      ->check(CLI::IsMember({"minmax", "percentile", "mse"}));
  int8_group->add_option("--percentile", int8.percentile, "percentile for --calib-method percentile (default 99.99)")
      ->check(CLI::Range(50.0, 100.0));
  int8_group->add_option("--target-mse", target_mse, "mixed: held-out action MSE to meet, normalised units");
  int8_group->add_option("--max-mse", max_mse, "fail, writing nothing, when the held-out action MSE (normalised) is above this");
  int8_group->add_option("--report", report_path, "also write the accuracy report as JSON to this file");
  int8_group->add_option("--threads", int8.threads, "threads for calibration and evaluation (0 = all cores)")->check(CLI::Range(0, 256));
  app.add_flag("-q,--quiet", quiet, "print nothing but errors");
  CLI11_PARSE(app, argc, argv);

  act::install_signal_cleanup();  // a killed conversion leaves no partial blob or scratch folder
  try {
    if (precision == "fp32" && (!int8.calib_sources.empty() || app.count("--mode") || app.count("--max-mse") || app.count("--report"))) {
      act::fail(act::ErrorCode::kInvalidArgument, "--mode, --calib, --max-mse and --report need --precision int8");
    }
    if (!package.empty()) {
      if (!output.empty()) act::fail(act::ErrorCode::kInvalidArgument, "give either -o or --package (which writes " +
                                     std::string(act::kPackageBlobName) + " into the folder)");
      output = act::prepare_package_dir(package);
    }
    if (output.empty() && !explain) act::fail(act::ErrorCode::kInvalidArgument, "--output (or --package, or --explain) is required");
    if (!quiet) std::cerr << "reading " << checkpoint << " ...\n";
    act::ImportedModel model;
    std::string source_kind;
    if (std::filesystem::is_directory(checkpoint)) {
      if (act::any_pytorch_option(app)) {
        act::fail(act::ErrorCode::kInvalidArgument, "the .pth options (--config, --stats, ...) do not apply to a LeRobot "
                  "checkpoint folder: its config.json and statistics are in the folder");
      }
      if (explain) std::cout << "checkpoint   " << checkpoint << ": a LeRobot checkpoint folder; every value comes from its config.json\n";
      if (output.empty()) return 0;
      model = act::import_lerobot_checkpoint(checkpoint);
      source_kind = model.layout + " LeRobot layout";
    } else {
      const act::PyTorchConversion plan = act::plan_pytorch_conversion(checkpoint, pth_sources);
      if (explain) act::print_explanation(std::cout, plan);
      if (explain && output.empty()) return plan.missing.empty() ? 0 : 1;
      model = act::import_pytorch_conversion(plan);
      source_kind = "PyTorch " + plan.checkpoint.format + " .pth, " + plan.checkpoint.location + ", statistics from " +
                    plan.statistics_source;
    }
    size_t bytes = 0;
    if (precision == "int8") {
      int8.mode = mode == "dynamic" ? act::QuantMode::kDynamic : mode == "mixed" ? act::QuantMode::kMixed : act::QuantMode::kStatic;
      int8.method = act::parse_calibration_method(method);
      if (app.count("--holdout")) int8.holdout = holdout;
      if (app.count("--target-mse")) int8.target_mse = target_mse;
      if (app.count("--max-mse")) int8.max_mse = max_mse;
      int8.progress = !quiet;
      int8.frame_loader = act::load_calibration_frames;
      const act::Int8Result r = act::convert_to_int8(model, output, int8);
      bytes = r.bytes;
      if (!report_path.empty()) {
        const std::string text = r.report.dump(2) + "\n";
        act::detail::AtomicFileWriter file(report_path);
        file.write(text.data(), text.size());
        file.commit();
      }
      if (!quiet) std::cout << r.text;
    } else {
      bytes = act::write_fp32_blob(model, output);
    }
    if (!package.empty()) act::write_deploy_package(package, model.config, checkpoint);
    if (!quiet) {
      const act::ModelConfig& c = model.config;
      const auto macs = c.macs();
      std::cout << "checkpoint   " << checkpoint << " (" << source_kind << ")\n"
                << "model        " << c.summary() << "\n"
                << "tokens       " << c.n_tokens() << " encoder, " << c.chunk_size << " decoder; n_action_steps "
                << c.n_action_steps;
      if (c.temporal_ensemble_coeff) std::cout << ", temporal ensembling coeff " << *c.temporal_ensemble_coeff;
      std::cout << "\n"
                << "parameters   " << millions(static_cast<double>(model.checkpoint_values)) << " in " << model.checkpoint_tensors
                << " checkpoint tensors; dropped " << millions(static_cast<double>(model.training_only_values))
                << " training-only (" << model.training_only_tensors << " tensors)\n"
                << "blob         " << millions(static_cast<double>(model.blob_values())) << " values after BN folding and "
                << "constant folding, fp32\n"
                << "compute      " << gmac(macs.total()) << " GMAC per inference (backbone " << gmac(macs.backbone)
                << ", encoder " << gmac(macs.encoder) << ", decoder " << gmac(macs.decoder) << ")\n"
                << "wrote        " << output << " (" << human_bytes(static_cast<double>(bytes)) << ")\n";
      if (!package.empty()) std::cout << "package      " << package << " (blob, drive_calibration.json, README.md)\n";
      for (const auto& note : model.notes) std::cout << "note: " << note << "\n";
    }
    return 0;
  } catch (const act::Error& e) {
    std::cerr << "act_convert: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "act_convert: error: " << e.what() << "\n";
    return 1;
  }
}
