// act_eval's observation reader: every tensor of the wrong size, layout or type, and a missing one,
// is an error that names the tensor and what was expected.
#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "actengine/status.h"
#include "engine/src/convert/observation_file.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"
#include "weights/import/safetensors.h"

namespace act {
namespace {

class ObservationFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    model_.cameras = {{"observation.images.front", 4, 6}};
    model_.state_dim = 2;
    model_.action_dim = 2;
    model_.chunk_size = 3;
    path_ = test::scratch_dir() + "/obs.safetensors";
  }
  // Writes float tensors of the given shapes (values 0.5) and returns the reader's error (kOk if none).
  std::optional<Error> read_error(const std::vector<std::pair<std::string, std::vector<int64_t>>>& tensors,
                   ImageSource source = ImageSource::kAuto) {
    std::vector<std::vector<float>> values;
    std::vector<SafetensorsWriteTensor> out;
    for (const auto& [name, shape] : tensors) {
      values.emplace_back(shape_elements(shape), 0.5f);
      out.push_back({name, DType::kF32, shape, values.back().data(), values.back().size() * sizeof(float)});
    }
    write_safetensors(path_, out);
    return test::error_thrown_by([&] { ObservationBatch::read(path_, model_, source); });
  }
  void expect_error(const std::optional<Error>& e, StatusCode code, const std::string& needle) {
    ASSERT_TRUE(e.has_value()) << "read without an error; expected: " << needle;
    EXPECT_EQ(e->code(), code) << e->what();
    EXPECT_NE(std::string(e->what()).find(needle), std::string::npos) << "message: " << e->what() << "\nexpected: " << needle;
  }
  ModelInfo model_;
  std::string path_;
};

TEST_F(ObservationFileTest, ReadsAWellFormedFile) {
  EXPECT_FALSE(read_error({{"input.observation.images.front", {2, 3, 4, 6}}, {"input.observation.state", {2, 2}},
                           {"output.action", {2, 3, 2}}}).has_value());
  const ObservationBatch batch = ObservationBatch::read(path_, model_);
  EXPECT_EQ(batch.size(), 2u);
  EXPECT_TRUE(batch.has_expected_actions());
}

TEST_F(ObservationFileTest, ImageInTheWrongLayoutOrSize) {
  // NHWC floats where NCHW is expected: the shapes differ, and both are named.
  expect_error(read_error({{"input.observation.images.front", {2, 4, 6, 3}}, {"input.observation.state", {2, 2}}}),
               StatusCode::kInvalidArgument, "has shape [2, 4, 6, 3], expected [2, 3, 4, 6]");
  // Another camera size.
  expect_error(read_error({{"input.observation.images.front", {2, 3, 8, 6}}, {"input.observation.state", {2, 2}}}),
               StatusCode::kInvalidArgument, "expected [2, 3, 4, 6]");
  // A u8 image stored as float.
  expect_error(read_error({{"input.observation.images.front.u8_nhwc", {2, 4, 6, 3}}, {"input.observation.state", {2, 2}}}),
               StatusCode::kInvalidArgument, "must be U8");
}

TEST_F(ObservationFileTest, StateOrActionsOfTheWrongSizeOrMissing) {
  expect_error(read_error({{"input.observation.images.front", {2, 3, 4, 6}}, {"input.observation.state", {2, 3}}}),
               StatusCode::kInvalidArgument, "\"input.observation.state\" has shape [2, 3], expected [2, 2]");
  // The batch size comes from the state; an image batch that disagrees is named.
  expect_error(read_error({{"input.observation.images.front", {3, 3, 4, 6}}, {"input.observation.state", {2, 2}}}),
               StatusCode::kInvalidArgument, "expected [2, 3, 4, 6]");
  expect_error(read_error({{"input.observation.images.front", {2, 3, 4, 6}}, {"input.observation.state", {2, 2}},
                           {"output.action", {2, 4, 2}}}),
               StatusCode::kInvalidArgument, "\"output.action\" has shape [2, 4, 2], expected [2, 3, 2]");
  expect_error(read_error({{"input.observation.state", {2, 2}}}), StatusCode::kNotFound,
               "missing \"input.observation.images.front\"");
  expect_error(read_error({{"input.observation.state", {0, 2}}}), StatusCode::kInvalidArgument, "no batch axis");
}

}  // namespace
}  // namespace act
