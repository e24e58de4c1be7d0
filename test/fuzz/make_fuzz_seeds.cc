// Writes the generated part of the seed corpora (test/fuzz/corpus/): small valid inputs made by the
// project's own writers, so that the fuzzers start from files the parsers accept.
//   make_fuzz_seeds CORPUS_DIR LEROBOT_CONFIG_JSON   (the act-tiny fixture's config.json)
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

#include "test/fuzz/fuzz_models.h"
#include "weights/blob/actb.h"
#include "weights/import/lerobot_import.h"
#include "weights/blob/quant_config.h"
#include "weights/import/safetensors.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR LEROBOT_CONFIG_JSON\n", argv[0]);
    return 2;
  }
  const fs::path corpus = argv[1];
  for (const char* target : {"fuzz_safetensors", "fuzz_actb", "fuzz_observation_file"}) {
    fs::create_directories(corpus / target);
  }

  // safetensors: one tensor of each float dtype and a u8 one, with metadata.
  const std::vector<float> f32 = {1.0f, -2.5f, 3.25f, 0.0f, 1e-3f, 7.0f};
  const std::vector<uint16_t> f16 = {0x3c00, 0xc000, 0x7bff, 0x0001};
  const std::vector<uint8_t> u8 = {0, 1, 2, 255};
  act::write_safetensors((corpus / "fuzz_safetensors" / "dtypes.safetensors").string(),
                         {{"weight", act::DType::kF32, {2, 3}, f32.data(), f32.size() * sizeof(float)},
                          {"half", act::DType::kF16, {4}, f16.data(), f16.size() * sizeof(uint16_t)},
                          {"bf16", act::DType::kBF16, {2, 2}, f16.data(), f16.size() * sizeof(uint16_t)},
                          {"bytes", act::DType::kU8, {1, 4}, u8.data(), u8.size()}},
                         {{"format", "pt"}});

  // .actb: the fixture's model config as an int8 blob states it (every input feature normalised, a
  // quantization section), a float layer and an int8 per-channel quantized one: blob_model_config
  // accepts it, so mutations reach each of its checks.
  std::ifstream config_file(argv[2]);
  act::ModelConfig model_config = act::lerobot_model_config(nlohmann::ordered_json::parse(config_file), argv[2]);
  for (const std::string& key : model_config.input_keys()) model_config.input_norm.emplace_back(key, act::NormMode::kMeanStd);
  model_config.precision = act::Precision::kInt8;
  act::QuantConfig quant;
  quant.mode = act::QuantMode::kStatic;
  quant.calibration = "mse";
  quant.activations["backbone.conv1"] = {0.05f, -3};
  quant.float_layers = {"backbone.layer4.1.conv2.weight"};
  nlohmann::json blob_config = model_config.to_json();
  blob_config["quantization"] = quant.to_json();
  act::ActbWriter blob;
  blob.set_config(blob_config);
  blob.add_f32("backbone.layer4.1.conv2.weight", {2, 3}, f32);
  const std::vector<int8_t> i8 = {1, -2, 3, -4, 5, -6};
  blob.add_tensor("encoder.weight", act::DType::kI8, {2, 3}, i8.data(), i8.size(),
                  act::QuantParams{{0.5f, 0.25f}, {0, 0}, 0});
  blob.write((corpus / "fuzz_actb" / "tiny.actb").string());

  // Observations for act::fuzz::observation_model(): two samples, float and u8 images.
  const act::ModelInfo model = act::fuzz::observation_model();
  const act::CameraInfo& cam = model.cameras[0];
  const int64_t n = 2;
  const std::vector<float> image(static_cast<size_t>(n * 3 * cam.height * cam.width), 0.5f);
  const std::vector<uint8_t> image_u8(image.size(), 128);
  const std::vector<float> state(static_cast<size_t>(n * model.state_dim), 0.1f);
  const std::vector<float> env(static_cast<size_t>(n * model.env_state_dim), -0.2f);
  const std::vector<float> action(static_cast<size_t>(n) * model.chunk_values(), 1.5f);
  const std::string image_name = "input." + cam.key;
  act::write_safetensors(
      (corpus / "fuzz_observation_file" / "observations.safetensors").string(),
      {{image_name, act::DType::kF32, {n, 3, cam.height, cam.width}, image.data(), image.size() * sizeof(float)},
       {image_name + ".u8_nhwc", act::DType::kU8, {n, cam.height, cam.width, 3}, image_u8.data(), image_u8.size()},
       {"input.observation.state", act::DType::kF32, {n, model.state_dim}, state.data(), state.size() * sizeof(float)},
       {"input." + model.env_state_key, act::DType::kF32, {n, model.env_state_dim}, env.data(), env.size() * sizeof(float)},
       {"output.action", act::DType::kF32, {n, model.chunk_size, model.action_dim}, action.data(),
        action.size() * sizeof(float)}});
  std::printf("seeds written to %s\n", corpus.c_str());
  return 0;
}
