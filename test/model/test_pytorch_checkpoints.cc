// PyTorch .pth files written by Debian's python3-torch (test/tools/make_test_pth.py): each saved
// variant converts to the same blob, byte for byte, as the equivalent LeRobot safetensors folder;
// tensors of every dtype and view kind read back exactly; malicious pickles are refused and run nothing.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "actengine/status.h"
#include "support/test_paths.h"
#include "weights/import/config_inference.h"
#include "weights/import/lerobot_import.h"
#include "weights/import/pytorch_checkpoint.h"

namespace act {
namespace {

namespace fs = std::filesystem;

std::string pth_dir() { return test::generated_checkpoint_dir("pth"); }

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::string blob_of(const ImportedModel& model, const std::string& path) {
  write_fp32_blob(model, path);
  return read_file(path);
}

std::string folder_blob(const std::string& folder, const std::string& scratch) {
  return blob_of(import_lerobot_checkpoint(folder), scratch + "/folder.actb");
}

std::string pth_blob(const std::string& file, const ConfigSources& sources, const std::string& scratch) {
  return blob_of(import_pytorch_conversion(plan_pytorch_conversion(file, sources)), scratch + "/pth.actb");
}

struct Equivalence {
  const char* pth;
  const char* folder;  ///< a shared fixture, or "pth/<name>" for a generated folder
  bool with_config;    ///< --config <folder>/config.json, else inferred + flags
};

class PthEquivalenceTest : public ::testing::TestWithParam<Equivalence> {};

TEST_P(PthEquivalenceTest, ConvertsToTheSameBlobAsTheSafetensorsFolder) {
  const Equivalence& e = GetParam();
  const std::string file = pth_dir() + "/" + e.pth;
  ACT_REQUIRE_PATH(file);
  const std::string folder = std::string(e.folder).rfind("pth/", 0) == 0 ? pth_dir() + std::string(e.folder).substr(3)
                                                                          : test::fixture_dir(e.folder);
  ACT_REQUIRE_PATH(folder);
  const bool legacy_layout = !fs::exists(folder + "/policy_preprocessor.json");
  ConfigSources s;
  if (e.with_config) {
    s.config_path = folder + "/config.json";
  } else {
    s.image_size = {{96, 128}};
    s.n_action_steps = 10;
    s.n_heads = 4;
    s.lerobot_defaults = true;
  }
  if (!legacy_layout) s.stats_paths = {folder + "/policy_preprocessor_step_3_normalizer_processor.safetensors"};
  const std::string scratch = test::scratch_dir();
  const std::string expected = folder_blob(folder, scratch);
  const std::string got = pth_blob(file, s, scratch);
  EXPECT_EQ(got.size(), expected.size());
  EXPECT_TRUE(got == expected) << e.pth << " converts to a different blob than " << folder;
}

INSTANTIATE_TEST_SUITE_P(
    Variants, PthEquivalenceTest,
    ::testing::Values(Equivalence{"tiny_plain.pth", "act-tiny", true}, Equivalence{"tiny_plain.pth", "act-tiny", false},
                      Equivalence{"tiny_wrapped_noprefix.pth", "act-tiny", true},
                      Equivalence{"tiny_wrapped_noprefix.pth", "act-tiny", false},
                      Equivalence{"tiny_plain_legacyformat.pth", "act-tiny", true},
                      Equivalence{"tiny_wrapped_proto4.pth", "act-tiny", false},
                      Equivalence{"tiny_f16.pth", "pth/act-tiny-f16", true},
                      Equivalence{"tinylegacy_plain.pth", "act-tiny-legacy", true},
                      Equivalence{"tinylegacy_plain.pth", "act-tiny-legacy", false},
                      Equivalence{"tinylegacy_wrapped_noprefix_legacyformat.pth", "act-tiny-legacy", true},
                      Equivalence{"tinylegacy_wrapped_noprefix_legacyformat.pth", "act-tiny-legacy", false}),
    [](const ::testing::TestParamInfo<Equivalence>& param_info) {
      std::string name = std::string(param_info.param.pth) + (param_info.param.with_config ? "_config" : "_inferred");
      for (char& c : name) {
        if (!isalnum(static_cast<unsigned char>(c))) c = '_';
      }
      return name;
    });

TEST(PthStats, DatasetStatsJsonGivesTheSameBlobAsTheProcessorFile) {
  const std::string file = pth_dir() + "/tiny_plain.pth";
  ACT_REQUIRE_PATH(file);
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  ConfigSources s;
  s.config_path = test::fixture_dir("act-tiny") + "/config.json";
  s.stats_paths = {pth_dir() + "/tiny_stats.json"};
  const std::string scratch = test::scratch_dir();
  EXPECT_TRUE(pth_blob(file, s, scratch) == folder_blob(test::fixture_dir("act-tiny"), scratch));
}

TEST(PthInference, ReportsWhatCannotBeKnownInsteadOfGuessing) {
  const std::string file = pth_dir() + "/tiny_plain.pth";
  ACT_REQUIRE_PATH(file);
  const PyTorchConversion plan = plan_pytorch_conversion(file, {});
  auto missing = [&](const std::string& what) {
    for (const auto& m : plan.missing) {
      if (m.find(what) != std::string::npos) return true;
    }
    return false;
  };
  for (const char* what : {"cameras", "n_action_steps", "normalisation statistics", "n_heads", "feedforward_activation",
                           "replace_final_stride_with_dilation"}) {
    EXPECT_TRUE(missing(what)) << what;
  }
  auto fact = [&](const std::string& field) -> const ConfigFact* {
    for (const auto& f : plan.facts) {
      if (f.field == field) return &f;
    }
    return nullptr;
  };
  ASSERT_NE(fact("dim_model"), nullptr);
  EXPECT_EQ(fact("dim_model")->value, "64");
  EXPECT_NE(fact("dim_model")->source.find("model.encoder_latent_input_proj.weight"), std::string::npos);
  EXPECT_EQ(fact("chunk_size")->value, "10");
  EXPECT_EQ(fact("vision_backbone")->value, "\"resnet18\"");
  EXPECT_EQ(fact("n_encoder_layers")->value, "2");
  try {
    import_pytorch_conversion(plan);
    ADD_FAILURE() << "converted without the missing facts";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("n_action_steps"), std::string::npos) << e.what();
  }
}

TEST(PthInference, RefusesAConfigThatDoesNotMatchTheWeights) {
  const std::string file = pth_dir() + "/tiny_plain.pth";
  ACT_REQUIRE_PATH(file);
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const std::string scratch = test::scratch_dir();
  std::string config = read_file(test::fixture_dir("act-tiny") + "/config.json");
  const std::string from = "\"dim_feedforward\": 128", to = "\"dim_feedforward\": 3200";
  ASSERT_NE(config.find(from), std::string::npos);
  config.replace(config.find(from), from.size(), to);
  std::ofstream(scratch + "/config.json") << config;
  ConfigSources s;
  s.config_path = scratch + "/config.json";
  try {
    plan_pytorch_conversion(file, s);
    ADD_FAILURE() << "accepted a config that contradicts the weights";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dim_feedforward is 3200, but model.encoder.layers.0.linear1.weight [128, 64] says 128"),
              std::string::npos) << e.what();
  }
}

TEST(PthTensors, EveryDtypeAndViewReadsBackExactly) {
  ACT_REQUIRE_PATH(pth_dir() + "/views_expected.safetensors");
  const SafetensorsFile expected = SafetensorsFile::open(pth_dir() + "/views_expected.safetensors");
  for (const char* name : {"views.pth", "views_legacyformat.pth", "views_proto4.pth"}) {
    SCOPED_TRACE(name);
    const PyTorchCheckpoint ckpt = read_pytorch_checkpoint(pth_dir() + "/" + name);
    EXPECT_EQ(ckpt.state_dict.names(), expected.names());
    for (const auto& tensor_name : expected.names()) {
      SCOPED_TRACE(tensor_name);
      const auto& want = expected.get(tensor_name);
      const auto& got = ckpt.state_dict.get(tensor_name);
      // The reference writer stores a 0-d tensor as [1].
      EXPECT_EQ(got.shape, got.shape.empty() ? std::vector<int64_t>{} : want.shape);
      EXPECT_EQ(got.elements(), want.elements());
      if (want.dtype == DType::kI64) {
        ASSERT_EQ(got.dtype, DType::kI64);
        EXPECT_EQ(std::string(reinterpret_cast<const char*>(got.data), got.nbytes),
                  std::string(reinterpret_cast<const char*>(want.data), want.nbytes));
      } else if (got.dtype == DType::kF64) {
        ASSERT_EQ(got.elements(), want.elements());
        const auto w = want.to_f32();
        for (size_t i = 0; i < w.size(); ++i) EXPECT_EQ(static_cast<float>(reinterpret_cast<const double*>(got.data)[i]), w[i]);
      } else {
        EXPECT_EQ(got.to_f32(), want.to_f32());
      }
    }
    EXPECT_EQ(ckpt.state_dict.get("f16").dtype, DType::kF16);
    EXPECT_EQ(ckpt.state_dict.get("bf16").dtype, DType::kBF16);
  }
}

TEST(PthSecurity, MaliciousPicklesAreRefusedAndRunNothing) {
  ACT_REQUIRE_PATH(pth_dir() + "/evil_os_system.pth");
  const struct {
    const char* file;
    const char* message;
  } cases[] = {
      {"evil_os_system.pth", "GLOBAL 'posix.system' is not allowed"},
      {"evil_stack_global.pth", "GLOBAL 'posix.system' is not allowed"},
      {"evil_eval.pth", "GLOBAL '__builtin__.eval' is not allowed"},
      {"evil_in_wrapper.pth", "GLOBAL 'posix.system' is not allowed"},
      {"evil_legacyformat.pth", "GLOBAL 'posix.system' is not allowed"},
      {"evil_huge_length.pth", "length 4294967280 runs past the end"},
      {"evil_inflated_storage.pth", "declares 67108864 bytes, the pickle says 2 elements of 4 bytes"},
      {"not_a_checkpoint.pth", "not a PyTorch checkpoint"},
  };
  for (const auto& c : cases) {
    try {
      read_pytorch_checkpoint(pth_dir() + "/" + c.file);
      ADD_FAILURE() << c.file << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(c.message), std::string::npos) << c.file << ": " << e.what();
    }
  }
  EXPECT_FALSE(fs::exists(pth_dir() + "/PWNED"));
}

TEST(PthSecurity, DamagedFilesAreErrorsNeverCrashes) {
  // Every truncation and many single-byte changes of a small real .pth (zip and legacy format):
  // read, or refused with act::Error (the sanitizer build checks the rest). A changed storage byte
  // is caught by the zip CRC.
  for (const char* name : {"views.pth", "views_legacyformat.pth"}) {
    const std::string path = pth_dir() + "/" + name;
    ACT_REQUIRE_PATH(path);
    const std::string original = read_file(path);
    const std::string damaged_path = test::scratch_dir() + "/damaged.pth";
    size_t refused = 0;
    auto attempt = [&](const std::string& bytes) {
      std::ofstream(damaged_path, std::ios::binary | std::ios::trunc) << bytes;
      try {
        read_pytorch_checkpoint(damaged_path);
      } catch (const Error&) {
        ++refused;
      }
    };
    for (size_t len = 0; len < original.size(); len += 11) attempt(original.substr(0, len));
    for (size_t i = 0; i < original.size(); i += 5) {
      std::string damaged = original;
      damaged[i] = static_cast<char>(damaged[i] ^ 0x5a);
      attempt(damaged);
    }
    EXPECT_GT(refused, original.size() / 11);
  }
}

}  // namespace
}  // namespace act
