// The INT8 converter's trial engines share its FP32 engine's packed float weights (Engine::Impl's
// packed_weights_from, graph::ActNetwork): the same actions, bit for bit, as packing them again,
// and nothing shared where the panels are another gemm_f32 variant's.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/src/engine_impl.h"
#include "support/test_paths.h"
#include "weights/import/lerobot_import.h"
#include "weights/quantize/quantize_model.h"

namespace act {
namespace {

class SharedPackedWeights : public ::testing::Test {
 protected:
  // An FP32 blob and a dynamic INT8 one written from one imported model, as the converter writes
  // its scratch blobs, the INT8 one with its first quantizable conv1 kept in float beside the
  // layers that always are (the state projection, the action head).
  void SetUp() override {
    const std::string fixture = test::fixture_dir("act-tiny");
    ACT_REQUIRE_PATH(fixture);
    const std::string scratch = test::scratch_dir();
    const ImportedModel model = import_lerobot_checkpoint(fixture);
    for (const std::string& layer : quantizable_layers(model)) {
      if (kept_float_.empty() && layer.find("conv1.weight") != std::string::npos) kept_float_ = layer;
    }
    ASSERT_FALSE(kept_float_.empty()) << "act-tiny has no conv1 to keep in float";
    fp32_blob_ = scratch + "/fp32.actb";
    int8_blob_ = scratch + "/dynamic.actb";
    write_fp32_blob(model, fp32_blob_);
    QuantConfig quant;
    quant.mode = QuantMode::kDynamic;
    quant.float_layers = {kept_float_};
    write_int8_blob(model, quant, int8_blob_);
    fp32_ = std::make_unique<Engine::Impl>(fp32_blob_, options_);

    const CameraInfo& cam = fp32_->info().cameras[0];
    image_.resize(static_cast<size_t>(cam.height) * cam.width * 3);
    for (size_t i = 0; i < image_.size(); ++i) image_[i] = static_cast<uint8_t>((i * 37) % 251);
    state_.assign(static_cast<size_t>(fp32_->info().state_dim), 0.25f);
  }

  std::vector<float> actions(Engine::Impl& engine) {
    const CameraInfo& cam = engine.info().cameras[0];
    Observation obs;
    obs.images = {ImageView::rgb_u8(image_.data(), cam.height, cam.width)};
    obs.state = state_;
    std::vector<float> out(engine.info().chunk_values());
    engine.run(obs, out);
    return out;
  }

  EngineOptions options_{.threads = 2};
  std::string fp32_blob_, int8_blob_, kept_float_;
  std::unique_ptr<Engine::Impl> fp32_;
  std::vector<uint8_t> image_;
  std::vector<float> state_;
};

TEST_F(SharedPackedWeights, Int8EngineTakesTheFp32EnginesPanelsAndRunsAsIfItPackedThem) {
  Engine::Impl shared(int8_blob_, options_, fp32_.get());
  Engine::Impl own(int8_blob_, options_);
  const auto& theirs = fp32_->network().packed_weights();
  const auto& packed = shared.network().packed_weights();
  ASSERT_TRUE(packed.count(kept_float_)) << kept_float_ << " was not packed as a float layer";
  EXPECT_GT(theirs.size(), packed.size()) << "the int8 engine should pack fewer float layers than the FP32 one";
  for (const auto& [name, panels] : packed) {
    ASSERT_TRUE(theirs.count(name)) << name;
    EXPECT_EQ(panels.get(), theirs.at(name).get()) << name << " was packed again";
    EXPECT_NE(own.network().packed_weights().at(name).get(), panels.get()) << name;
  }
  EXPECT_EQ(actions(shared), actions(own));
}

TEST_F(SharedPackedWeights, PanelsOfAnotherGemmVariantAreNotShared) {
  // The reference gemm_f32's panels are 8 columns wide; every SIMD variant's are wider.
  EngineOptions ref = options_;
  ref.isa = "ref";
  Engine::Impl ref_fp32(fp32_blob_, ref);
  Engine::Impl engine(int8_blob_, options_, &ref_fp32);
  Engine::Impl own(int8_blob_, options_);
  if (engine.info().isa == "ref") GTEST_SKIP() << "this CPU runs only the reference kernels";
  for (const auto& [name, panels] : engine.network().packed_weights()) {
    EXPECT_NE(panels.get(), ref_fp32.network().packed_weights().at(name).get()) << name;
  }
  EXPECT_EQ(actions(engine), actions(own));
}

}  // namespace
}  // namespace act
