// The conversion API (actengine/convert.h) through its public types only: bad inputs are named,
// blobs appear only when complete, and the report struct says what its JSON says.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace act {
namespace {

std::unique_ptr<ImportedCheckpoint> import_tiny() {
  auto model = import_checkpoint(test::fixture_dir("act-tiny"));
  EXPECT_TRUE(model.ok()) << model.status().to_string();
  return model.ok() ? std::move(model).value() : nullptr;
}

Int8Options quick_options() {
  Int8Options o;
  o.threads = 2;
  o.holdout = 2;
  return o;
}

// The op profile of a blob opened with profiling on (what ran, by op); empty, and a failure, when
// it does not open.
std::vector<OpProfile> profiled_ops(const std::string& blob) {
  auto e = Engine::open(blob, {.threads = 1, .profile = true});
  EXPECT_TRUE(e.ok()) << e.status().to_string();
  return e.ok() ? (*e)->op_profile() : std::vector<OpProfile>{};
}

// Files in `dir` (a conversion must leave only its output).
std::vector<std::string> files_in(const std::string& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  return out;
}

TEST(ConvertApi, MissingCheckpointIsNamed) {
  const std::string missing = test::scratch_dir() + "/no-such-checkpoint";
  auto model = import_checkpoint(missing);
  ASSERT_FALSE(model.ok());
  EXPECT_EQ(model.status().code(), StatusCode::kNotFound) << model.status().to_string();
  EXPECT_NE(model.status().message().find(missing), std::string::npos) << model.status().to_string();
}

TEST(ConvertApi, LocatesLeRobotsTrainingLayouts) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = test::scratch_dir();
  // outputs/train/<run>/checkpoints/last/pretrained_model/, as LeRobot's training writes it.
  const std::string last = dir + "/checkpoints/last";
  fs::create_directories(last);
  fs::copy(fixture, last + "/pretrained_model", fs::copy_options::recursive);
  const auto from_training = locate_checkpoint(last);
  ASSERT_TRUE(from_training.ok()) << from_training.status().to_string();
  EXPECT_EQ(from_training->path, last + "/pretrained_model");
  EXPECT_TRUE(from_training->lerobot_folder);
  EXPECT_NE(from_training->note.find("pretrained_model"), std::string::npos);
  auto model = import_checkpoint(last);
  ASSERT_TRUE(model.ok()) << model.status().to_string();

  const auto itself = locate_checkpoint(fixture);
  ASSERT_TRUE(itself.ok());
  EXPECT_EQ(itself->path, fixture);
  EXPECT_TRUE(itself->note.empty());
  // Its weights file given directly: the folder around it.
  const auto from_weights = locate_checkpoint(fixture + "/model.safetensors");
  ASSERT_TRUE(from_weights.ok()) << from_weights.status().to_string();
  EXPECT_EQ(from_weights->path, fixture);
  EXPECT_TRUE(from_weights->lerobot_folder);

  const auto typo = locate_checkpoint(dir + "/checkpoints/lsat");
  EXPECT_EQ(typo.status().code(), StatusCode::kNotFound);
  EXPECT_NE(typo.status().message().find("no such file or folder"), std::string::npos) << typo.status().message();
  fs::create_directories(dir + "/empty");
  const auto empty = locate_checkpoint(dir + "/empty");
  EXPECT_EQ(empty.status().code(), StatusCode::kNotFound);
  EXPECT_NE(empty.status().message().find("not a LeRobot checkpoint"), std::string::npos) << empty.status().message();
  std::ofstream(dir + "/m.actb") << "x";
  const auto blob = locate_checkpoint(dir + "/m.actb");
  EXPECT_EQ(blob.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(blob.status().message().find("already converted"), std::string::npos) << blob.status().message();
}

// Action names reach the FP32 and INT8 blobs and their ModelInfo; a blob written without them (as
// every blob before they were stored) has none, and its config has no "action_names" key at all.
TEST(ConvertApi, ActionNamesReachTheBlobsAndOlderBlobsHaveNone) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = test::scratch_dir();
  auto model = import_checkpoint(fixture);
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  ASSERT_TRUE((*model)->write_fp32(dir + "/plain.actb").ok());
  const Status wrong = (*model)->set_action_names({"steering"});
  EXPECT_EQ(wrong.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(wrong.message().find("1 action names for the model's 2 action values"), std::string::npos) << wrong.message();
  EXPECT_EQ((*model)->set_action_names({"steering", "a,b"}).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE((*model)->set_action_names({"steering", "throttle"}).ok());
  EXPECT_EQ((*model)->summary().model.action_names, (std::vector<std::string>{"steering", "throttle"}));
  ASSERT_TRUE((*model)->write_fp32(dir + "/named.actb").ok());
  Int8Options int8;
  int8.mode = Int8Mode::kDynamic;
  int8.threads = 1;
  ASSERT_TRUE((*model)->write_int8(dir + "/named-int8.actb", {}, int8).ok());
  for (const char* name : {"/named.actb", "/named-int8.actb"}) {
    auto engine = Engine::open(dir + name);
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    EXPECT_EQ((*engine)->model_info().action_names, (std::vector<std::string>{"steering", "throttle"})) << name;
  }
  auto plain = Engine::open(dir + "/plain.actb");
  ASSERT_TRUE(plain.ok()) << plain.status().to_string();
  EXPECT_TRUE((*plain)->model_info().action_names.empty());
}

// A checkpoint whose action feature carries names (as a LeRobot dataset's features do) names the
// actions; set_action_names replaces them.
TEST(ConvertApi, ActionNamesFromTheCheckpointsFeatures) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = test::scratch_dir() + "/named";
  fs::create_directories(dir);
  for (const auto& entry : fs::directory_iterator(fixture)) fs::copy(entry.path(), dir / entry.path().filename());
  nlohmann::ordered_json config = nlohmann::ordered_json::parse(std::ifstream(dir + "/config.json"));
  config["output_features"]["action"]["names"] = {"steer", "gas"};
  std::ofstream(dir + "/config.json") << config.dump(2);
  auto model = import_checkpoint(dir);
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  EXPECT_EQ((*model)->summary().model.action_names, (std::vector<std::string>{"steer", "gas"}));
  ASSERT_TRUE((*model)->write_fp32(dir + "/m.actb").ok());
  auto engine = Engine::open(dir + "/m.actb");
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  EXPECT_EQ((*engine)->model_info().action_names, (std::vector<std::string>{"steer", "gas"}));
  ASSERT_TRUE((*model)->set_action_names({"steering", "throttle"}).ok());
  EXPECT_EQ((*model)->summary().model.action_names, (std::vector<std::string>{"steering", "throttle"}));
}

TEST(ConvertApi, DeploymentOptionsReplaceTheFoldersAndReachTheBlob) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string blob = test::scratch_dir() + "/ensemble.actb";
  auto model = import_checkpoint(fixture, {}, {.n_action_steps = 1, .temporal_ensemble_coeff = 0.01});
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  ASSERT_TRUE((*model)->write_fp32(blob).ok());
  auto engine = Engine::open(blob);
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  EXPECT_EQ((*engine)->model_info().n_action_steps, 1);
  EXPECT_TRUE((*engine)->model_info().temporal_ensembling);
  EXPECT_DOUBLE_EQ((*engine)->model_info().temporal_ensemble_coeff, 0.01);
  // "none" turns a checkpoint's ensembling off again.
  DeploymentOptions off;
  off.temporal_ensemble_coeff.emplace(std::nullopt);
  auto plain = import_checkpoint(fixture, {}, off);
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE((*plain)->summary().model.temporal_ensembling);
  EXPECT_EQ((*plain)->summary().model.n_action_steps, 10);

  const auto refused = import_checkpoint(fixture, {}, {.n_action_steps = std::nullopt, .temporal_ensemble_coeff = 0.01});
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("needs n_action_steps == 1"), std::string::npos) << refused.status().message();

  // A bad override is refused from config.json alone, before the weights are read: here there are
  // none to read, and the override is still what the error names.
  const std::string no_weights = test::scratch_dir() + "/no-weights";
  fs::create_directories(no_weights);
  fs::copy_file(fixture + "/config.json", no_weights + "/config.json");
  const auto early = import_checkpoint(no_weights, {}, {.n_action_steps = 11, .temporal_ensemble_coeff = std::nullopt});
  EXPECT_EQ(early.status().code(), StatusCode::kInvalidArgument) << early.status().to_string();
  EXPECT_NE(early.status().message().find("n_action_steps 11 must be in [1, chunk_size 10]"), std::string::npos)
      << early.status().message();
  const auto good = import_checkpoint(no_weights, {}, {.n_action_steps = 5, .temporal_ensemble_coeff = std::nullopt});
  EXPECT_EQ(good.status().code(), StatusCode::kNotFound) << good.status().to_string();
}

TEST(ConvertApi, PthOptionsOnAFolderAreRefused) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  PthOptions pth;
  pth.n_heads = 4;
  auto model = import_checkpoint(test::fixture_dir("act-tiny"), pth);
  ASSERT_FALSE(model.ok());
  EXPECT_EQ(model.status().code(), StatusCode::kInvalidArgument);
}

TEST(ConvertApi, ImportSummaryDescribesTheModel) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  const ImportSummary& s = model->summary();
  EXPECT_EQ(s.source, "current LeRobot layout");
  ASSERT_EQ(s.model.cameras.size(), 1u);
  EXPECT_GT(s.model.action_dim, 0);
  EXPECT_GT(s.blob_values, 0u);
  EXPECT_LT(s.blob_values, s.checkpoint_values);  // the VAE encoder is dropped
  EXPECT_GT(s.macs, s.backbone_macs + s.encoder_macs);
}

TEST(ConvertApi, StaticWithoutFramesWritesNothing) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  const std::string dir = test::scratch_dir();
  const auto r = model->write_int8(dir + "/s.actb", CalibrationSet{}, quick_options());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("calibration frames"), std::string::npos) << r.status().to_string();
  EXPECT_TRUE(files_in(dir).empty());
}

TEST(ConvertApi, WrongFrameSizeIsNamed) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  auto frames = model->synthetic_calibration_set(4, 1);
  ASSERT_TRUE(frames.ok()) << frames.status().to_string();
  frames->frames[2].images[0].resize(10);
  const std::string dir = test::scratch_dir();
  const auto r = model->write_int8(dir + "/w.actb", *frames, quick_options());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("calibration frame 2"), std::string::npos) << r.status().to_string();
  EXPECT_TRUE(files_in(dir).empty());

  frames = model->synthetic_calibration_set(4, 1);
  ASSERT_TRUE(frames.ok());
  frames->frames[1].state.push_back(0.0f);
  const auto bad_state = model->write_int8(dir + "/w.actb", *frames, quick_options());
  ASSERT_FALSE(bad_state.ok());
  EXPECT_NE(bad_state.status().message().find("state"), std::string::npos) << bad_state.status().to_string();
}

TEST(ConvertApi, MixedNeedsATarget) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  auto frames = model->synthetic_calibration_set(4, 1);
  ASSERT_TRUE(frames.ok());
  Int8Options o = quick_options();
  o.mode = Int8Mode::kMixed;
  const auto r = model->write_int8(test::scratch_dir() + "/m.actb", *frames, o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
}

// Linear-input codes are chosen from calibrated ranges: dynamic mode has none to choose from, and
// says so rather than silently running per token.
TEST(ConvertApi, LinearInputCodesNeedCalibration) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  for (const LinearInputCodes codes : {LinearInputCodes::kPerToken, LinearInputCodes::kPerTensor}) {
    Int8Options o = quick_options();
    o.mode = Int8Mode::kDynamic;
    o.linear_inputs = codes;
    const std::string dir = test::scratch_dir();
    const auto r = model->write_int8(dir + "/d.actb", CalibrationSet{}, o);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(r.status().message().find("linear_inputs needs calibration"), std::string::npos) << r.status().to_string();
    EXPECT_TRUE(files_in(dir).empty()) << testing::PrintToString(files_in(dir));
  }
}

TEST(ConvertApi, MissedMaxMseWritesNothing) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  Int8Options o = quick_options();
  o.mode = Int8Mode::kDynamic;
  o.max_mse = 1e-300;
  const std::string dir = test::scratch_dir();
  const auto r = model->write_int8(dir + "/d.actb", CalibrationSet{}, o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition) << r.status().message();
  EXPECT_NE(r.status().message().find("held-out error"), std::string::npos) << "the message holds the report";
  EXPECT_TRUE(files_in(dir).empty()) << testing::PrintToString(files_in(dir));
}

// Attention's precision: forced either way, the blob runs what was chosen (its op profile names the
// ops); auto keeps int8 exactly when both errors stay within the budget, and reports both.
TEST(ConvertApi, AttentionPrecisionIsChosenByHeldOutErrorAndRunsAsChosen) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  auto frames = model->synthetic_calibration_set(6, 3);
  ASSERT_TRUE(frames.ok());
  const std::string dir = test::scratch_dir();
  const auto attention_kinds = [](const std::string& blob) {
    std::set<std::string> kinds;
    for (const OpProfile& op : profiled_ops(blob)) {
      if (op.kind.rfind("attention", 0) == 0) kinds.insert(op.kind);
    }
    return kinds;
  };
  for (AttentionPrecision p : {AttentionPrecision::kInt8, AttentionPrecision::kFp32, AttentionPrecision::kAuto}) {
    Int8Options o = quick_options();
    o.attention = p;
    const std::string blob = dir + "/a" + std::to_string(static_cast<int>(p)) + ".actb";
    const auto r = model->write_int8(blob, *frames, o);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    const nlohmann::json j = nlohmann::json::parse(r->to_json());
    EXPECT_EQ(j["attention"]["precision"], r->int8_attention ? "int8" : "fp32");
    const std::set<std::string> kinds = attention_kinds(blob);
    EXPECT_EQ(kinds, std::set<std::string>{r->int8_attention ? "attention_s8" : "attention_f32"});
    if (p == AttentionPrecision::kFp32) {
      EXPECT_FALSE(r->int8_attention);
      EXPECT_FALSE(r->int8_attention_error) << "not tried";
      continue;
    }
    ASSERT_TRUE(r->fp32_attention_error && r->int8_attention_error);
    const ActionError& with = *r->int8_attention_error;
    const ActionError& without = *r->fp32_attention_error;
    EXPECT_NE(with.mse, without.mse) << "int8 attention changes the actions";
    if (p == AttentionPrecision::kInt8) {
      EXPECT_TRUE(r->int8_attention);
    } else {
      const double allowed = 1.0 + kInt8AttentionErrorBudget;
      EXPECT_EQ(r->int8_attention, with.mse <= allowed * without.mse && with.max_abs <= allowed * without.max_abs);
    }
    EXPECT_EQ(r->action_error.mse, r->int8_attention ? with.mse : without.mse) << "the report is the blob's";
  }
}

// The linear inputs' codes: forced either way, the blob runs what was chosen (per tensor: the FFNs'
// hidden activations, which their hidden layers then requantize into in their GEMMs; the other
// inputs stay per token); auto makes per tensor those that lose least by estimated SQNR, within
// the error budget when any, and reports both errors. Attention stays float so that the report's
// error is the choice's.
TEST(ConvertApi, LinearInputCodesAreChosenByHeldOutErrorAndRunAsChosen) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  auto frames = model->synthetic_calibration_set(6, 3);
  ASSERT_TRUE(frames.ok());
  const std::string dir = test::scratch_dir();
  for (LinearInputCodes codes : {LinearInputCodes::kPerToken, LinearInputCodes::kPerTensor, LinearInputCodes::kAuto}) {
    Int8Options o = quick_options();
    o.linear_inputs = codes;
    o.attention = AttentionPrecision::kFp32;
    const std::string blob = dir + "/l" + std::to_string(static_cast<int>(codes)) + ".actb";
    const auto r = model->write_int8(blob, *frames, o);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    ASSERT_FALSE(r->linear_inputs.empty());
    std::map<int, const LinearInputChoice*> ffns;
    size_t per_tensor = 0;
    for (const LinearInputChoice& l : r->linear_inputs) {
      EXPECT_TRUE(std::isfinite(l.sqnr_per_tensor_db) && std::isfinite(l.sqnr_per_token_db)) << l.value;
      EXPECT_GT(l.sqnr_per_token_db, 10.0) << l.value;
      EXPECT_GT(l.scale, 0.0f) << l.value;
      per_tensor += l.per_tensor;
      if (l.ffn >= 0) {
        EXPECT_TRUE(l.value.ends_with(".ffn_hidden")) << l.value << ": tried per tensor, but no FFN's hidden activation";
        EXPECT_TRUE(ffns.emplace(l.ffn, &l).second) << "FFN " << l.ffn << " twice";
      }
      if (l.ffn < 0) {
        EXPECT_FALSE(l.per_tensor) << l.value << ": no FFN's, never per tensor";
      }
    }
    ASSERT_FALSE(ffns.empty()) << r->to_text();
    const nlohmann::json j = nlohmann::json::parse(r->to_json());
    ASSERT_EQ(j["linear_inputs"].size(), r->linear_inputs.size());
    for (size_t i = 0; i < r->linear_inputs.size(); ++i) {
      EXPECT_EQ(j["linear_inputs"][i]["value"], r->linear_inputs[i].value);
      EXPECT_EQ(j["linear_inputs"][i]["ffn"], r->linear_inputs[i].ffn);
      EXPECT_EQ(j["linear_inputs"][i]["codes"], r->linear_inputs[i].per_tensor ? "per_tensor" : "per_token");
    }
    // The blob's hidden layers that requantize, and its int8 linears reading per-tensor codes.
    const std::vector<OpProfile> ops = profiled_ops(blob);
    ASSERT_FALSE(ops.empty());
    size_t static_linears = 0, requantizing = 0;
    for (const OpProfile& op : ops) {
      static_linears += op.kind == "linear_s8" || op.kind.starts_with("linear_s8+");  // + a fused LayerNorm
      requantizing += op.name.ends_with(".ffn_hidden") && op.kernel.find("s8out") != std::string::npos;
    }
    EXPECT_EQ(requantizing, per_tensor) << "each FFN per tensor requantizes";
    EXPECT_EQ(static_linears, per_tensor) << "each per-tensor input has one reader here";
    if (codes == LinearInputCodes::kPerToken) {
      EXPECT_EQ(per_tensor, 0u);
      EXPECT_FALSE(r->chosen_inputs_error) << "not tried";
      continue;
    }
    ASSERT_TRUE(r->per_token_inputs_error && r->chosen_inputs_error);
    EXPECT_EQ(r->action_error.mse, r->chosen_inputs_error->mse) << "the report is the blob's";
    if (codes == LinearInputCodes::kPerTensor) {
      EXPECT_EQ(per_tensor, ffns.size());
      EXPECT_NE(r->chosen_inputs_error->mse, r->per_token_inputs_error->mse) << "per-tensor codes change the actions";
      continue;
    }
    if (per_tensor > 0) {
      EXPECT_LE(r->chosen_inputs_error->mse, (1.0 + kPerTensorCodesErrorBudget) * r->per_token_inputs_error->mse);
      EXPECT_LE(r->chosen_inputs_error->max_abs, (1.0 + kPerTensorCodesMaxErrorBudget) * r->per_token_inputs_error->max_abs);
    }
    // The FFNs chosen are those whose codes lose least.
    double worst_chosen = -INFINITY, best_left = INFINITY;
    for (const auto& [ffn, l] : ffns) {
      const double loss = l->sqnr_per_token_db - l->sqnr_per_tensor_db;
      if (l->per_tensor) {
        worst_chosen = std::max(worst_chosen, loss);
      } else {
        best_left = std::min(best_left, loss);
      }
    }
    EXPECT_LE(worst_chosen, best_left) << r->to_text();
    EXPECT_NE(r->to_text().find("linear inputs  " + std::to_string(per_tensor) + " of "), std::string::npos) << r->to_text();
  }
}

TEST(ConvertApi, ReportStructMatchesItsJson) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const auto model = import_tiny();
  ASSERT_TRUE(model);
  auto frames = model->synthetic_calibration_set(6, 3);
  ASSERT_TRUE(frames.ok());
  std::vector<ConversionProgress> progress;
  Int8Options o = quick_options();
  o.method = CalibrationMethod::kPercentile;
  o.progress = [&](const ConversionProgress& p) { progress.push_back(p); };
  const std::string dir = test::scratch_dir();
  const std::string blob = dir + "/p.actb";
  const auto r = model->write_int8(blob, *frames, o);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(files_in(dir), std::vector<std::string>{"p.actb"});
  EXPECT_EQ(r->int8_bytes, fs::file_size(blob));
  // The calibration pass counts its frames from 0 to all of them, in order.
  std::vector<size_t> counts;
  for (const auto& p : progress) {
    if (p.task == "calibrating (percentile)") {
      EXPECT_EQ(p.total, r->calibration_frames);
      EXPECT_STREQ(p.unit, "frames");
      counts.push_back(p.done);
    }
  }
  ASSERT_EQ(counts.size(), r->calibration_frames + 1);
  for (size_t i = 0; i < counts.size(); ++i) EXPECT_EQ(counts[i], i);
  // Fewer frames than calib_samples: the report says how many and why.
  const std::string fewer = "calibrated on " + std::to_string(r->calibration_frames) + " frames, fewer than the " +
                            std::to_string(o.calib_samples) + " asked: the calibration set holds 6 frames";
  EXPECT_NE(std::find_if(r->notes.begin(), r->notes.end(), [&](const std::string& n) { return n.find(fewer) == 0; }),
            r->notes.end()) << r->to_text();

  const nlohmann::json j = nlohmann::json::parse(r->to_json());
  EXPECT_EQ(j["mode"], "static");
  EXPECT_EQ(j["calibration"], "percentile");
  EXPECT_EQ(j["calibration_frames"], r->calibration_frames);
  EXPECT_EQ(j["holdout_frames"], 2);
  EXPECT_EQ(j["holdout_frames"], r->holdout_frames);
  EXPECT_EQ(j["fp32_bytes"], r->fp32_bytes);
  EXPECT_EQ(j["int8_bytes"], r->int8_bytes);
  EXPECT_EQ(j["notes"], r->notes);
  EXPECT_EQ(j["preprocessing"], r->preprocessing);
  EXPECT_EQ(j["action_keys"], r->action_keys);
  EXPECT_EQ(j["action_error"]["mse"].get<double>(), r->action_error.mse);
  EXPECT_EQ(j["action_error"]["max_abs_physical"].get<double>(), r->action_error.max_abs_physical);
  EXPECT_EQ(j["action_error"]["per_dim_mse"].get<std::vector<double>>(), r->action_error.per_dim_mse);
  EXPECT_EQ(j["action_error"]["per_dim_max_abs"].size(), static_cast<size_t>(r->action_keys));
  ASSERT_EQ(j["layers"].size(), r->layers.size());
  ASSERT_FALSE(r->layers.empty());
  for (size_t i = 0; i < r->layers.size(); ++i) {
    EXPECT_EQ(j["layers"][i]["value"], r->layers[i].value);
    EXPECT_EQ(j["layers"][i]["op"], r->layers[i].op);
    EXPECT_EQ(j["layers"][i]["sqnr_db"].get<double>(), r->layers[i].sqnr_db);
  }
  EXPECT_FALSE(j.contains("sensitivity"));  // no mixed search ran
  EXPECT_TRUE(std::isfinite(r->action_error.mse));
  EXPECT_NE(r->to_text().find("per-layer SQNR"), std::string::npos);

  // The blob runs unchanged through the public Engine.
  auto engine = Engine::open(blob, {.threads = 2});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  EXPECT_EQ((*engine)->model_info().precision, "int8 static");
}

TEST(ConvertApi, CalibrationMethodNames) {
  for (CalibrationMethod m : {CalibrationMethod::kMinMax, CalibrationMethod::kPercentile, CalibrationMethod::kMse}) {
    const auto parsed = parse_calibration_method(calibration_method_name(m));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(parsed.value(), m);
  }
  const auto unknown = parse_calibration_method("kl");
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unknown.status().message().find("kl"), std::string::npos);
}

TEST(ConvertApi, FramesWantedCoverCalibrationAndHoldout) {
  Int8Options o;
  o.calib_samples = 64;
  EXPECT_EQ(calibration_frames_wanted(o), 80u);  // a fifth held out, 16 at most
  o.holdout = 3;
  EXPECT_EQ(calibration_frames_wanted(o), 67u);
}

}  // namespace
}  // namespace act
