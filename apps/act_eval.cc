// act_eval: run an .actb model on observations from a safetensors file; optionally compare with the
// expected action chunks stored in the same file.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "actengine/engine.h"
#include "apps/diff_stats.h"
#include "apps/observation_file.h"
#include "apps/status_error.h"
#include "weights/blob/error.h"
#include "weights/import/safetensors.h"

int main(int argc, char** argv) {
  CLI::App app{"act_eval: run an .actb model on observations stored in a safetensors file "
               "(input.<feature key> tensors, as in the LeRobot fixtures) and write or check the action chunks."};
  std::string model_path, input_path, output_path, images = "auto";
  bool compare = false;
  double tol = 1e-4;
  int threads = 0;
  app.add_option("-m,--model", model_path, "the .actb model")->required();
  app.add_option("-i,--input", input_path, "observations (safetensors)")->required();
  app.add_option("-o,--output", output_path, "write the raw action chunks as 'action' [N, chunk, action_dim]");
  app.add_flag("--compare", compare, "compare with 'output.action' from the input file; exit 1 beyond --tol");
  app.add_option("--tol", tol, "tolerance: |ours - ref| <= tol * (1 + |ref|)")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("-t,--threads", threads, "threads (0 = all cores)")->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--images", images, "which image tensors to read: auto (float if present), f32, u8")->capture_default_str()
      ->check(CLI::IsMember({"auto", "f32", "u8"}));
  CLI11_PARSE(app, argc, argv);

  auto engine_or = act::Engine::open(model_path, {.threads = threads});
  if (!engine_or.ok()) {
    std::cerr << "act_eval: error: " << engine_or.status().to_string() << "\n";
    return 1;
  }
  act::Engine& engine = **engine_or;
  const act::ModelInfo& info = engine.model_info();
  try {
    const act::ImageSource source = images == "u8" ? act::ImageSource::kU8
                                    : images == "f32" ? act::ImageSource::kFloat
                                                      : act::ImageSource::kAuto;
    const act::ObservationBatch batch = act::ObservationBatch::read(input_path, info, source);
    if (compare && !batch.has_expected_actions()) {
      act::fail(act::ErrorCode::kNotFound, input_path + ": --compare needs an 'output.action' tensor");
    }
    const size_t per = info.chunk_values();
    std::vector<float> actions(batch.size() * per);
    act::DiffStats diff;
    for (size_t i = 0; i < batch.size(); ++i) {
      std::span<float> out(actions.data() + i * per, per);
      const act::Status s = engine.infer(batch.at(i), out);
      act::throw_if_failed(s, "observation " + std::to_string(i));
      if (compare) {
        const float* ref = batch.expected_actions(i);
        for (size_t j = 0; j < per; ++j) diff.add(out[j], ref[j]);
      }
    }
    std::cout << "model        " << info.summary << "\n"
              << "observations " << batch.size() << " from " << input_path << "\n";
    if (!output_path.empty()) {
      act::write_safetensors(output_path, {{"action", act::DType::kF32,
                                            {static_cast<int64_t>(batch.size()), info.chunk_size, info.action_dim},
                                            actions.data(), actions.size() * sizeof(float)}});
      std::cout << "wrote        " << output_path << "\n";
    }
    if (compare) {
      const bool pass = diff.within(tol);
      if (diff.non_finite > 0) {
        std::printf("compare      %zu of %zu values are NaN or infinite (ours or the reference's)\n", diff.non_finite,
                    diff.count);
      }
      std::printf("compare      max abs error %.3g, max relative error %.3g, max |diff|/(1+|ref|) %.3g (tol %.3g): %s\n",
                  diff.max_abs, diff.max_rel, diff.max_ratio, tol, pass ? "PASS" : "FAIL");
      return pass ? 0 : 1;
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "act_eval: error: " << e.what() << "\n";
    return 1;
  }
}
