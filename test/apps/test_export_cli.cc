// act_convert's exports as a user runs them: --export-calib's NumPy file (checked against the images
// decoded here) and --export-onnx from a checkpoint and from a blob, with its bad inputs; and
// bench/tools/ort_bench.js timing a QDQ export of act_bench's built-in model in ONNX Runtime.
#include <gtest/gtest.h>


#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <nlohmann/json.hpp>

#include "engine/media/media_io.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

const std::string kConvert = ACT_CONVERT_BIN;

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

size_t count_files(const std::string& dir, const std::string& extension) {
  size_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.path().extension() == extension;
  return n;
}

TEST(ActConvertExportCli, ExportCalibWritesTheFramesAsNumpyNhwc) {
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  const std::string npy = dir + "/calib.npy";
  const CommandResult r = run_command(kConvert + " " + q(src) + " --export-calib " + q(npy) + " --calib " + q(src) +
                                      " --calib-samples 4");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/model.actb"));  // nothing but the calibration set was asked for
  const std::string bytes = read_file(npy);
  // NumPy format 1.0: magic, version, little-endian header length, a dict padded to 64 bytes, data.
  ASSERT_GT(bytes.size(), 10u);
  ASSERT_EQ(bytes.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
  const size_t header_len = static_cast<uint8_t>(bytes[8]) | static_cast<size_t>(static_cast<uint8_t>(bytes[9])) << 8;
  EXPECT_EQ((10 + header_len) % 64, 0u);
  const std::string header = bytes.substr(10, header_len);
  EXPECT_EQ(header.rfind("{'descr': '<f4', 'fortran_order': False, 'shape': (4, 96, 128, 3), }", 0), 0u) << header;
  EXPECT_EQ(header.back(), '\n');
  ASSERT_EQ(bytes.size(), 10 + header_len + 4u * 96 * 128 * 3 * sizeof(float));
  // Frame i is sample i's PNG (the folder's images in path order), RGB / 255.
  for (int i = 0; i < 4; ++i) {
    const cv::Mat bgr = act::media::read_image(src + "/sample" + std::to_string(i) + ".observation.images.front.png");
    ASSERT_EQ(bgr.rows, 96);
    ASSERT_EQ(bgr.cols, 128);
    const char* frame = bytes.data() + 10 + header_len + static_cast<size_t>(i) * 96 * 128 * 3 * sizeof(float);
    for (int y = 0; y < 96; y += 7) {
      for (int x = 0; x < 128; x += 5) {
        for (int c = 0; c < 3; ++c) {
          float v;
          std::memcpy(&v, frame + ((static_cast<size_t>(y) * 128 + x) * 3 + c) * sizeof(float), sizeof v);
          ASSERT_EQ(v, static_cast<float>(bgr.at<cv::Vec3b>(y, x)[2 - c]) / 255.0f) << "frame " << i << " y " << y << " x " << x;
        }
      }
    }
  }
  // Without frames' sources, or for the out-normalised model, it refuses and writes nothing.
  const CommandResult no_calib = run_command(kConvert + " " + q(src) + " --export-calib " + q(dir + "/x.npy"));
  EXPECT_EQ(no_calib.exit_code, 1);
  EXPECT_NE(no_calib.output.find("--calib"), std::string::npos) << no_calib.output;
  EXPECT_FALSE(fs::exists(dir + "/x.npy"));
}

TEST(ActConvertExportCli, ExportsOnnxFromACheckpointAndFromABlob) {
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  const CommandResult direct = run_command(kConvert + " " + q(src) + " --export-onnx " + q(dir + "/direct.onnx"));
  ASSERT_EQ(direct.exit_code, 0) << direct.output;
  EXPECT_NE(direct.output.find("observation.images.front [1, 3, 96, 128]"), std::string::npos) << direct.output;
  EXPECT_NE(direct.output.find("action [1, 10, 2]"), std::string::npos) << direct.output;
  EXPECT_EQ(count_files(dir, ".actb"), 0u) << "the blob converted on the way is removed";

  ASSERT_EQ(run_command(kConvert + " " + q(src) + " -o " + q(dir + "/m.actb") + " -q").exit_code, 0);
  const CommandResult backbone = run_command(kConvert + " " + q(dir + "/m.actb") + " --export-onnx " +
                                             q(dir + "/backbone.onnx") + " --onnx-part backbone --onnx-normalization out");
  ASSERT_EQ(backbone.exit_code, 0) << backbone.output;
  EXPECT_NE(backbone.output.find("observation.images.front.features [1, 64, 3, 4]"), std::string::npos) << backbone.output;
  // The same model, exported twice, is the same file.
  ASSERT_EQ(run_command(kConvert + " " + q(dir + "/m.actb") + " --export-onnx " + q(dir + "/again.onnx") + " -q").exit_code, 0);
  EXPECT_EQ(read_file(dir + "/again.onnx"), read_file(dir + "/direct.onnx"));
}

TEST(ActConvertExportCli, BadOnnxExportsFailAndWriteNothing) {
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  ASSERT_EQ(run_command(kConvert + " " + q(src) + " -o " + q(dir + "/m.actb") + " -q").exit_code, 0);
  std::ofstream(dir + "/junk.actb") << "not a blob";
  const auto expect_error = [&](const std::string& args, const std::string& words) {
    const CommandResult r = run_command(kConvert + " " + args);
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_NE(r.output.find(words), std::string::npos) << args << "\n" << r.output;
    EXPECT_EQ(count_files(dir, ".onnx") + count_files(dir, ".npy"), 0u) << args;
    EXPECT_EQ(count_files(dir, ".actb"), 2u) << args << ": only the blob and the junk are there";
  };
  expect_error(q(dir + "/absent.actb") + " --export-onnx " + q(dir + "/a.onnx"), "absent.actb");
  expect_error(q(dir + "/junk.actb") + " --export-onnx " + q(dir + "/a.onnx"), "junk.actb");
  expect_error(q(dir + "/m.actb") + " --export-onnx " + q(dir + "/no-such-folder/a.onnx"), "no-such-folder");
  expect_error(q(src) + " --export-onnx " + q(dir + "/no-such-folder/a.onnx"), "no-such-folder");
  expect_error(q(dir + "/m.actb") + " --export-onnx " + q(dir + "/a.onnx") + " --onnx-part encoder", "encoder");
  expect_error(q(src) + " -o " + q(dir + "/n.actb") + " --onnx-part backbone", "--export-onnx");
  expect_error(q(dir + "/m.actb") + " -o " + q(dir + "/n.actb") + " --export-onnx " + q(dir + "/a.onnx"), "already converted");
  expect_error(q(dir + "/m.actb") + " --export-calib " + q(dir + "/c.npy") + " --calib " + q(src) + " --export-onnx " +
                   q(dir + "/a.onnx") + " --onnx-normalization out",
               "--onnx-normalization in");
}

// The tool compare_ort.sh runs: a small built-in INT8 model saved by act_bench, exported as QDQ,
// timed by ort_bench.js for 2 runs and profiled. Its JSON and its printed line hold positive
// latencies (no timing limits) and the op types ONNX Runtime ran. "Onnx" in the name: the Release stage's Node tests (scripts/run_tests.sh).
TEST(OnnxOrtBench, TimesAQdqExportOfTheBuiltInModel) {
  ACT_REQUIRE_PATH(std::string(ACT_ONNX_DIR) + "/node_modules/onnxruntime-node/package.json");
  ASSERT_EQ(run_command("node --version").exit_code, 0) << "node is not installed (scripts/install_deps.sh)";
  const std::string dir = act::test::scratch_dir();
  const CommandResult saved = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 --precision int8 -t 1 --save-model " +
                                          q(dir + "/m.actb"));
  ASSERT_EQ(saved.exit_code, 0) << saved.output;
  const CommandResult exported = run_command(kConvert + " " + q(dir + "/m.actb") + " --export-onnx " + q(dir + "/m.onnx") + " -q");
  ASSERT_EQ(exported.exit_code, 0) << exported.output;
  const CommandResult r = run_command("node " + q(ACT_ORT_BENCH_JS) + " " + q(dir + "/m.onnx") +
                                      " --threads 1 --warmup 1 --runs 2 --profile --json " + q(dir + "/ort.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("intra-op threads 1\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" ms (2 runs after 1 warm-up)"), std::string::npos) << r.output;
  const nlohmann::json j = nlohmann::json::parse(read_file(dir + "/ort.json"));
  EXPECT_EQ(j.at("runtime"), "onnxruntime-node");
  EXPECT_EQ(j.at("threads"), 1);
  const nlohmann::json& latency = j.at("latency_ms");
  EXPECT_EQ(latency.at("count"), 2);
  EXPECT_GT(latency.at("p50").get<double>(), 0.0);
  EXPECT_LE(latency.at("min").get<double>(), latency.at("p50").get<double>());
  EXPECT_LE(latency.at("p50").get<double>(), latency.at("p99").get<double>());
  EXPECT_LE(latency.at("p99").get<double>(), latency.at("max").get<double>());
  ASSERT_EQ(j.at("runs_ms").size(), 2u);
  EXPECT_FALSE(j.at("inputs").empty());
  // --profile: ONNX Runtime's time by op type; a QDQ model quantizes its activations somewhere.
  const nlohmann::json& op_types = j.at("op_types_ms");
  ASSERT_FALSE(op_types.empty());
  for (const auto& [type, ms] : op_types.items()) EXPECT_GE(ms.get<double>(), 0.0) << type;
  EXPECT_TRUE(op_types.contains("QuantizeLinear")) << op_types.dump();
  EXPECT_NE(r.output.find("op types     ms per run"), std::string::npos) << r.output;
  // Bad arguments are clear errors.
  const CommandResult bad = run_command("node " + q(ACT_ORT_BENCH_JS) + " " + q(dir + "/absent.onnx"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("no file " + dir + "/absent.onnx"), std::string::npos) << bad.output;
}

}  // namespace
