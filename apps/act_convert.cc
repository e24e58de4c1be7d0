// act_convert: LeRobot ACT checkpoint folder -> .actb blob.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>

#include "weights/error.h"
#include "weights/lerobot_import.h"

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
  CLI::App app{"act_convert: convert a LeRobot ACT checkpoint folder (current or legacy layout) into an .actb blob "
               "that libactengine runs."};
  std::string checkpoint, output, precision = "fp32";
  bool quiet = false;
  app.add_option("checkpoint", checkpoint, "LeRobot checkpoint folder (config.json + model.safetensors [+ processor files])")
      ->required();
  app.add_option("-o,--output", output, "output .actb file (written atomically)")->required();
  app.add_option("--precision", precision, "weight precision of the blob")->check(CLI::IsMember({"fp32", "int8"}));
  app.add_flag("-q,--quiet", quiet, "print nothing but errors");
  CLI11_PARSE(app, argc, argv);

  try {
    if (precision != "fp32") {
      act::fail(act::StatusCode::kUnimplemented, "--precision " + precision + " is not available yet in this build; use fp32");
    }
    if (!quiet) std::cerr << "reading " << checkpoint << " ...\n";
    const act::ImportedModel model = act::import_lerobot_checkpoint(checkpoint);
    const size_t bytes = act::write_fp32_blob(model, output);
    if (!quiet) {
      const act::ModelConfig& c = model.config;
      const auto macs = c.macs();
      std::cout << "checkpoint   " << checkpoint << " (" << model.layout << " LeRobot layout)\n"
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
