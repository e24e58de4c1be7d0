// act_eval on recorded episodes (apps/eval/): the episode readers, the metrics against values
// computed here, the gates' exit codes, the HTML reports' content (test/browser/run_report_pages.sh
// renders them in headless chromium).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "actengine/engine.h"
#include "actengine/vision.h"
#include "apps/eval/episode.h"
#include "apps/eval/metrics.h"
#include "engine/media/media_io.h"
#include "support/act_test_util.h"
#include "support/command.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

void write_text(const std::string& path, const std::string& text) { act::test::write_file(path, act::test::bytes_of(text)); }

nlohmann::json read_json(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

using act::test::fixture_image;

// %.9g: a float written so that it reads back exactly.
std::string exact(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", static_cast<double>(v));
  return buf;
}

// The act-tiny model (2 state values, 2 actions, chunk 10) as the tests need it.
std::string convert_tiny(const std::string& dir, const std::string& name, const std::string& flags = "") {
  const std::string blob = dir + "/" + name + ".actb";
  const CommandResult c = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                      q(blob) + " -q " + flags);
  EXPECT_EQ(c.exit_code, 0) << c.output;
  return blob;
}

std::string int8_flags() {
  return "--precision int8 --calib " + q(act::test::fixture_dir("act-tiny")) + " --calib-samples 3 --holdout 1";
}

// States of the four hand-made frames: exactly representable, so the CSV text reads back as these floats.
const std::vector<std::vector<float>> kStates = {{0.5f, -0.25f}, {0.25f, 0.0f}, {-0.5f, 0.75f}, {1.0f, -1.0f}};

// The model's chunks on the four fixture images with kStates, computed here through the public API.
std::vector<std::vector<float>> chunks_in_process(const std::string& blob) {
  auto engine = act::Engine::open(blob, {.threads = 1});
  EXPECT_TRUE(engine.ok());
  const act::ModelInfo& info = (*engine)->model_info();
  std::vector<std::vector<float>> out;
  for (int i = 0; i < 4; ++i) {
    std::vector<uint8_t> rgb;
    EXPECT_TRUE(act::frame_to_model_rgb(act::media::read_image(fixture_image(i)), info.cameras[0].height,
                                        info.cameras[0].width, rgb).ok());
    act::Observation obs;
    obs.images = {act::ImageView::rgb_u8(rgb.data(), info.cameras[0].height, info.cameras[0].width)};
    obs.state = kStates[static_cast<size_t>(i)];
    out.emplace_back(info.chunk_values());
    EXPECT_TRUE((*engine)->infer(obs, out.back()).ok());
  }
  return out;
}

// A folder of the four fixture images and a states CSV naming them by file (frames 0, 1) and by index (2, 3).
struct ImageEpisode {
  std::string frames, states;
  std::vector<std::string> keys;
};

ImageEpisode write_image_episode(const std::string& dir) {
  ImageEpisode e{dir + "/frames", dir + "/states.csv", {}};
  fs::create_directories(e.frames);
  for (int i = 0; i < 4; ++i) fs::copy_file(fixture_image(i), e.frames + "/" + fs::path(fixture_image(i)).filename().string());
  e.keys = {fs::path(fixture_image(0)).filename().string(), fs::path(fixture_image(1)).filename().string(), "2", "3"};
  std::string csv = "frame,state_a,state_b\n";
  for (size_t i = 0; i < 4; ++i) csv += e.keys[i] + "," + exact(kStates[i][0]) + "," + exact(kStates[i][1]) + "\n";
  write_text(e.states, csv);
  return e;
}

// fn() throws act::Error whose message holds every fragment.
template <typename F>
void expect_error(F fn, const std::vector<std::string>& fragments) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one naming " << fragments.front();
  } catch (const act::Error& e) {
    for (const auto& f : fragments) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << "'" << f << "' not in: " << e.what();
  }
}

act::ModelInfo tiny_info() {
  act::ModelInfo m;
  m.cameras.resize(1);
  m.cameras[0].height = 96;
  m.cameras[0].width = 128;
  m.state_dim = 2;
  m.action_dim = 2;
  m.chunk_size = 10;
  return m;
}

// ------------------------------------------------------------------------------------------ metrics

TEST(EvalMetrics, MatchHandComputedValues) {
  // Two dims; dim 0 spans -1..3 (half-range 2), dim 1 0..2 (half-range 1). Chunks of 2 steps.
  act::eval::EpisodeEvaluation e;
  e.action_names = {"steer", "throttle"};
  e.scale = {{-1.0f, 0.0f}, {3.0f, 2.0f}};
  e.models.emplace_back("a.actb", "fp32", 2);
  e.models.emplace_back("b.actb", "int8 static", 2);
  // Frame 0: demonstration of two steps; frame 1: of one step (the episode ends).
  e.add_frame("f0", std::vector<float>{1, 1, 2, 2}, {{1.5f, 1, 2, 1}, {1.5f, 1.5f, 2, 1}});
  e.add_frame("f1", std::vector<float>{0, 0}, {{-1, 1, 9, 9}, {-1, 1, 9, 9}});
  const auto& a = e.models[0].vs_demonstration;
  // First actions, model a: errors (0.5, 0) and (-1, 1).
  EXPECT_DOUBLE_EQ(a.first_raw.dim_mse(0), (0.25 + 1) / 2);
  EXPECT_DOUBLE_EQ(a.first_raw.dim_mse(1), (0 + 1) / 2.0);
  EXPECT_DOUBLE_EQ(a.first_raw.mse(), (0.25 + 0 + 1 + 1) / 4);
  EXPECT_DOUBLE_EQ(a.first_raw.max_abs(), 1);
  EXPECT_DOUBLE_EQ(a.first_normalised.dim_mse(0), (0.0625 + 0.25) / 2);
  EXPECT_DOUBLE_EQ(a.first_normalised.dim_mse(1), 0.5);
  // Whole chunk: frame 0 adds step 1's errors (0, -1); frame 1 has one step only.
  EXPECT_DOUBLE_EQ(a.chunk_raw.dim_mse(0), (0.25 + 0 + 1) / 3);
  EXPECT_DOUBLE_EQ(a.chunk_raw.dim_mse(1), (0 + 1 + 1) / 3.0);
  EXPECT_DOUBLE_EQ(a.chunk_raw.mse(), (0.25 + 0 + 1 + 0 + 1 + 1) / 6);
  // b against a: only frame 0's (0, 0.5) differs, over all 2 x 2 steps x dims per frame.
  const auto& ba = e.models[1].vs_reference;
  EXPECT_DOUBLE_EQ(ba.chunk_raw.mse(), 0.25 / 8);
  EXPECT_DOUBLE_EQ(ba.chunk_normalised.mse(), 0.25 / 8);  // dim 1's half-range is 1
  EXPECT_DOUBLE_EQ(ba.first_raw.max_abs(), 0.5);
  // Added error: b-vs-a chunk MSE over a's own, both normalised.
  const double own = (0.0625 + 0 + 0.25 + 0 + 1 + 1) / 6;
  EXPECT_DOUBLE_EQ(e.added_error(1), (0.25 / 8) / own);
  // Baselines: mean action (1, 1), the centre of the scale; the last action held (frame 0: the mean;
  // frame 1: frame 0's demonstrated (1, 1)); zero. Normalised errors over the steps compared:
  // mean and hold: frame 0 (0, 0), (-0.5, -1), frame 1 (0.5, 1); zero: (-0.5, -1), (-1, -2), (0, 0).
  ASSERT_EQ(e.baselines.size(), 3u);
  EXPECT_EQ(e.baselines[0].name, "hold last action");
  EXPECT_DOUBLE_EQ(e.baselines[0].vs_demonstration.chunk_normalised.mse(), 2.5 / 6);
  EXPECT_EQ(e.baselines[1].name, "mean action");
  EXPECT_DOUBLE_EQ(e.baselines[1].vs_demonstration.chunk_normalised.mse(), 2.5 / 6);
  EXPECT_EQ(e.baselines[2].name, "zero");
  EXPECT_DOUBLE_EQ(e.baselines[2].vs_demonstration.chunk_normalised.mse(), 6.25 / 6);
  EXPECT_DOUBLE_EQ(e.baselines[2].vs_demonstration.first_raw.mse(), (1 + 1 + 0 + 0) / 4.0);
  // Per-frame error of model a: normalised first-action MSE.
  ASSERT_EQ(e.models[0].frame_error.size(), 2u);
  EXPECT_DOUBLE_EQ(e.models[0].frame_error[0], 0.0625 / 2);
  EXPECT_DOUBLE_EQ(e.models[0].frame_error[1], (0.25 + 1) / 2);
  // The JSON names every dimension.
  const auto j = e.to_json();
  EXPECT_DOUBLE_EQ(j["models"][0]["vs_demonstration"]["first_action"]["raw"]["per_dimension"]["throttle"]["mse"].get<double>(), 0.5);
}

TEST(EvalMetrics, NonFiniteOutputMakesTheErrorNaN) {
  act::eval::EpisodeEvaluation e;
  e.action_names = {"a"};
  e.scale = {{-1.0f}, {1.0f}};
  e.models.emplace_back("a.actb", "fp32", 1);
  e.add_frame("f0", std::vector<float>{0}, {{std::nanf("")}});
  e.add_frame("f1", std::vector<float>{0}, {{5.0f}});
  EXPECT_EQ(e.models[0].non_finite_outputs, 1u);
  EXPECT_TRUE(std::isnan(e.models[0].vs_demonstration.first_raw.mse()));
  EXPECT_TRUE(std::isnan(e.models[0].vs_demonstration.chunk_raw.max_abs()));  // a maximum must not hide it
}

// ---------------------------------------------------------------------------------- episode inputs

TEST(EvalEpisode, KnownAnswerFromChunkColumns) {
  // The demonstration is the model's own chunk with 0.5 added to the first action dimension:
  // first-action and chunk MSE are then 0.25 on that dimension, 0 on the other.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = convert_tiny(dir, "fp32");
  const auto chunks = chunks_in_process(blob);
  const ImageEpisode ep = write_image_episode(dir);
  std::string csv = "frame";
  for (int s = 0; s < 10; ++s) csv += ",steer@" + std::to_string(s) + ",throttle@" + std::to_string(s);
  csv += "\n";
  std::vector<std::vector<float>> demo(4);
  for (size_t i = 0; i < 4; ++i) {
    csv += ep.keys[i];
    for (size_t v = 0; v < 20; ++v) {
      demo[i].push_back(v % 2 == 0 ? chunks[i][v] + 0.5f : chunks[i][v]);
      csv += ',';
      csv += exact(demo[i].back());
    }
    csv += "\n";
  }
  write_text(dir + "/actions.csv", csv);
  const CommandResult r = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                      q(dir + "/actions.csv") + " --states " + q(ep.states) + " -m " + q(blob) +
                                      " --json " + q(dir + "/eval.json") + " -t 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The expected values, from the floats the CSV holds.
  double sum0 = 0, sum0_first = 0;
  for (size_t i = 0; i < 4; ++i) {
    for (size_t s = 0; s < 10; ++s) {
      const double err = static_cast<double>(demo[i][2 * s]) - chunks[i][2 * s];
      sum0 += err * err;
      if (s == 0) sum0_first += err * err;
    }
  }
  act::ModelInfo info = (*act::Engine::open(blob))->model_info();
  const double half0 = (static_cast<double>(info.action_high[0]) - info.action_low[0]) / 2;
  const nlohmann::json j = read_json(dir + "/eval.json");
  const nlohmann::json& d = j["models"][0]["vs_demonstration"];
  EXPECT_EQ(j["action_names"], nlohmann::json({"steer", "throttle"}));
  EXPECT_EQ(j["frames"], 4);
  EXPECT_NEAR(d["first_action"]["raw"]["per_dimension"]["steer"]["mse"].get<double>(), sum0_first / 4, 1e-12);
  EXPECT_NEAR(d["first_action"]["raw"]["per_dimension"]["steer"]["mse"].get<double>(), 0.25, 1e-6);
  EXPECT_EQ(d["first_action"]["raw"]["per_dimension"]["throttle"]["mse"].get<double>(), 0.0);
  EXPECT_NEAR(d["chunk"]["raw"]["mse"].get<double>(), sum0 / 80, 1e-12);
  EXPECT_NEAR(d["chunk"]["raw"]["max_abs"].get<double>(), 0.5, 1e-6);
  EXPECT_NEAR(d["chunk"]["normalised"]["per_dimension"]["steer"]["mse"].get<double>(), sum0 / 40 / (half0 * half0), 1e-12);
  EXPECT_EQ(j["per_frame"]["source"][2], fs::path(fixture_image(2)).filename().string());  // index 2 of the sorted images
  EXPECT_NE(r.output.find("steer: first action MSE 0.25"), std::string::npos) << r.output;
}

TEST(EvalEpisode, OneActionPerRowBuildsChunksFromTheRowsThatFollow) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = convert_tiny(dir, "fp32");
  const auto chunks = chunks_in_process(blob);
  const ImageEpisode ep = write_image_episode(dir);
  // Each row: the model's own first action on that frame.
  std::string csv = "frame,steer,throttle\n";
  for (size_t i = 0; i < 4; ++i) csv += ep.keys[i] + "," + exact(chunks[i][0]) + "," + exact(chunks[i][1]) + "\n";
  write_text(dir + "/actions.csv", csv);
  const CommandResult r = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                      q(dir + "/actions.csv") + " --states " + q(ep.states) + " -m " + q(blob) +
                                      " --json " + q(dir + "/eval.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Frame i's chunk step s is compared with row i+s's action, while rows last.
  double sum = 0;
  size_t count = 0;
  for (size_t i = 0; i < 4; ++i) {
    for (size_t s = 0; i + s < 4; ++s) {
      for (size_t a = 0; a < 2; ++a) {
        const double err = static_cast<double>(chunks[i][2 * s + a]) - chunks[i + s][a];
        sum += err * err;
        ++count;
      }
    }
  }
  const nlohmann::json j = read_json(dir + "/eval.json");
  EXPECT_EQ(j["models"][0]["vs_demonstration"]["first_action"]["raw"]["mse"].get<double>(), 0.0);
  EXPECT_NEAR(j["models"][0]["vs_demonstration"]["chunk"]["raw"]["mse"].get<double>(), sum / static_cast<double>(count), 1e-12);
}

// The demonstrations as users have them, through act_eval: the long form (a chunk over rows, its
// padding left out) and one action per row without a frame column, in frame order.
TEST(ActEvalEpisodeCli, ReadsTheLongChunkFormAndCsvsWithoutAFrameColumn) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = convert_tiny(dir, "fp32");
  const auto chunks = chunks_in_process(blob);
  const ImageEpisode ep = write_image_episode(dir);
  // file,chunk_index,steering,throttle,is_pad: the model's own chunks, the last frame's steps 6..9
  // padded with values that would count if the padding were not respected.
  std::string csv = "file,chunk_index,steering,throttle,is_pad\n";
  for (size_t i = 0; i < 4; ++i) {
    for (size_t k = 0; k < 10; ++k) {
      const bool pad = i == 3 && k >= 6;
      csv += ep.keys[i] + "," + std::to_string(k) + "," + (pad ? "99" : exact(chunks[i][2 * k])) + "," +
             (pad ? "-99" : exact(chunks[i][2 * k + 1])) + "," + (pad ? "1" : "0") + "\n";
    }
  }
  write_text(dir + "/long.csv", csv);
  const std::string eval = std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -t 1 --episode " + q(ep.frames);
  CommandResult r = run_command(eval + " --actions " + q(dir + "/long.csv") + " --states " + q(ep.states) + " --json " +
                                q(dir + "/long.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json j = read_json(dir + "/long.json");
  EXPECT_EQ(j["action_names"], nlohmann::json({"steering", "throttle"}));
  EXPECT_EQ(j["frames"], 4);
  EXPECT_LT(j["models"][0]["vs_demonstration"]["chunk"]["raw"]["max_abs"].get<double>(), 1e-6) << r.output;
  // Steps out of order are an error naming the line.
  write_text(dir + "/bad_long.csv", "file,chunk_index,steering,throttle\n" + ep.keys[0] + ",1,0,0\n");
  r = run_command(eval + " --actions " + q(dir + "/bad_long.csv") + " --states " + q(ep.states));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("bad_long.csv line 2 column 'chunk_index': step 1 where 0 comes next"), std::string::npos) << r.output;

  // steering,throttle: no frame column, row i is frame i (the sorted images); states likewise.
  std::string per_frame = "steering,throttle\n", states = "a,b\n";
  for (size_t i = 0; i < 4; ++i) {
    per_frame += exact(chunks[i][0]) + "," + exact(chunks[i][1]) + "\n";
    states += exact(kStates[i][0]) + "," + exact(kStates[i][1]) + "\n";
  }
  write_text(dir + "/per_frame.csv", per_frame);
  write_text(dir + "/states_in_order.csv", states);
  r = run_command(eval + " --actions " + q(dir + "/per_frame.csv") + " --states " + q(dir + "/states_in_order.csv") +
                  " --json " + q(dir + "/per_frame.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("per_frame.csv has no frame column: its rows are the frames in order"), std::string::npos) << r.output;
  j = read_json(dir + "/per_frame.json");
  EXPECT_EQ(j["frames"], 4);
  EXPECT_EQ(j["models"][0]["vs_demonstration"]["first_action"]["raw"]["mse"].get<double>(), 0.0) << r.output;
}

// A CSV of another shape names every form act_eval reads, with an example.
TEST(ActEvalEpisodeCli, AMismatchNamesEveryAcceptedForm) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = convert_tiny(dir, "fp32");
  const ImageEpisode ep = write_image_episode(dir);
  write_text(dir + "/four.csv", "frame,a,b,c,d\n" + ep.keys[0] + ",1,2,3,4\n");
  const CommandResult r = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " --episode " + q(ep.frames) +
                                      " --actions " + q(dir + "/four.csv") + " --states " + q(ep.states));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  for (const char* form : {"4 action columns (a, b, c, d; one per dimension) after the frame column 'frame' but the model's "
                           "actions have 2 values",
                           "after a frame column (an image name or a 0-based frame index): frame,a0,a1",
                           "no frame column (row 1 is frame 0, in frame order): a0,a1",
                           "NAME@STEP columns: frame,a0@0,a1@0,", "file,chunk_index,a0,a1,is_pad"}) {
    EXPECT_NE(r.output.find(form), std::string::npos) << form << "\n" << r.output;
  }
}

// --state last-action|mean|zeros: a video or images with actions only, as act_drive feeds states.
TEST(ActEvalEpisodeCli, StatesFromTheActionsTheMeanOrZeros) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = convert_tiny(dir, "fp32");
  const ImageEpisode ep = write_image_episode(dir);
  write_text(dir + "/actions.csv", "frame,steer,throttle\n" + ep.keys[0] + ",0.1,0.2\n" + ep.keys[1] + ",0.3,0.4\n" +
                                       ep.keys[2] + ",0.5,0.6\n" + ep.keys[3] + ",0.7,0.8\n");
  const std::string eval = std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -t 1 --episode " + q(ep.frames) + " --actions " +
                           q(dir + "/actions.csv");
  CommandResult r = run_command(eval);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("give --states FILE.csv, or --state last-action|mean|zeros"), std::string::npos) << r.output;
  for (const std::string how : {"last-action", "mean", "zeros"}) {
    r = run_command(eval + " --state " + how);
    EXPECT_EQ(r.exit_code, 0) << how << "\n" << r.output;
    EXPECT_NE(r.output.find("--state " + how), std::string::npos) << r.output;  // the note says where the states came from
  }
  r = run_command(eval + " --state " + q(ep.states));  // a file, as --states
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // last-action: each frame's state is the action demonstrated at the frame before (the first, the training mean).
  act::ModelInfo info = tiny_info();
  info.state_low = {-1, 0};
  info.state_high = {1, 4};
  act::eval::EpisodeSources sources{ep.frames, dir + "/actions.csv", ""};
  sources.state = "last-action";
  const act::eval::Episode last = act::eval::read_episode(sources, info);
  ASSERT_EQ(last.frames.size(), 4u);
  EXPECT_EQ(last.frames[0].state, (std::vector<float>{0, 2}));
  EXPECT_EQ(last.frames[1].state, (std::vector<float>{0.1f, 0.2f}));
  EXPECT_EQ(last.frames[3].state, (std::vector<float>{0.5f, 0.6f}));
  sources.state = "zeros";
  EXPECT_EQ(act::eval::read_episode(sources, info).frames[2].state, (std::vector<float>{0, 0}));
}

TEST(EvalEpisode, ActDriveRecordingByColumnNames) {
  // Today's recorder columns plus ones it may add; a safe tick (no action) ends a chunk.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir() + "/rec";
  fs::create_directories(dir + "/frames");
  std::string log, ticks = "tick,time_s,jitter_ms,source,action.0,action.1,steering_us,throttle_us,sent,sent_by,sent_action.0\n";
  for (int i = 0; i < 4; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frames/%06d.png", i);
    fs::copy_file(fixture_image(i), dir + "/" + name);
    log += "{\"frame\":\"" + std::string(name) + "\",\"state\":[" + exact(kStates[static_cast<size_t>(i)][0]) + "," +
           exact(kStates[static_cast<size_t>(i)][1]) + "],\"tick\":" + std::to_string(3 * i) + ",\"time_s\":0}\n";
  }
  for (int t = 0; t < 12; ++t) {
    if (t == 5) {
      ticks += "5,0.1,0.0,safe:stale frame,,,1500,1500,1,policy,\n";
    } else {
      ticks += std::to_string(t) + ",0.1,0.0,chunk," + std::to_string(t) + "," + std::to_string(-t) + ",1500,1500,1,policy,0\n";
    }
  }
  // A killed run leaves its last lines cut short.
  write_text(dir + "/log.jsonl", log + "{\"frame\":\"frames/0000");
  write_text(dir + "/ticks.csv", ticks + "12,0.1,0.0,chu");
  const act::eval::Episode ep = act::eval::read_episode({dir, "", ""}, tiny_info());
  EXPECT_EQ(ep.kind, "act_drive recording");
  EXPECT_EQ(ep.action_names, (std::vector<std::string>{"action.0", "action.1"}));
  ASSERT_EQ(ep.frames.size(), 4u);
  // Frame 1 (tick 3): ticks 3 and 4, then the safe tick 5 ends it.
  EXPECT_EQ(ep.frames[1].demonstration, (std::vector<float>{3, -3, 4, -4}));
  // Frame 3 (tick 9): ticks 9..11, the end of the recording.
  EXPECT_EQ(ep.frames[3].demonstration, (std::vector<float>{9, -9, 10, -10, 11, -11}));
  EXPECT_EQ(ep.frames[2].state, kStates[2]);
  EXPECT_EQ(ep.frames[0].source, "frames/000000.png");
  ASSERT_EQ(ep.notes.size(), 1u);
  EXPECT_NE(ep.notes[0].find("cut short"), std::string::npos) << ep.notes[0];
}

TEST(EvalEpisode, PerTickRecordingDemonstratesWhatWasSent) {
  // act_drive's per-tick columns: the demonstration is the command sent (here by hand, where the
  // policy's action columns are empty), each new camera frame is evaluated once at its first tick with
  // that tick's state, and a tick held safe ends a chunk and is no demonstration.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir() + "/rec";
  fs::create_directories(dir + "/tick_frames");
  std::string ticks = "tick,time_s,jitter_ms,source,action.0,action.1,steering_us,throttle_us,sent,driver,frame,"
                      "state.0,state.1,command.0,command.1\n";
  for (int t = 0; t < 12; ++t) {
    const int shown = t / 3;  // a new camera frame every third tick
    char name[40];
    std::snprintf(name, sizeof name, "tick_frames/%08d.png", shown);
    if (t % 3 == 0) fs::copy_file(fixture_image(shown), dir + "/" + name);
    const std::string state = exact(kStates[static_cast<size_t>(shown)][0]) + "," + exact(kStates[static_cast<size_t>(shown)][1]);
    const bool safe = t == 5 || t == 6;
    ticks += std::to_string(t) + ",0.1,0.0," + (safe ? "safe:e-stop" : "manual") + ",,,1500,1500,1," +
             (safe ? "safe" : "manual") + "," + name + "," + state + "," + std::to_string(t) + "," + std::to_string(-t) + "\n";
  }
  write_text(dir + "/ticks.csv", ticks);
  write_text(dir + "/log.jsonl", "");  // the policy never ran
  const act::eval::Episode ep = act::eval::read_episode({dir, "", ""}, tiny_info());
  EXPECT_EQ(ep.action_names, (std::vector<std::string>{"command.0", "command.1"}));
  // Frames at ticks 0, 3 and 9; the one first seen at tick 6 was held safe.
  ASSERT_EQ(ep.frames.size(), 3u);
  EXPECT_EQ(ep.frames[0].source, "tick_frames/00000000.png");
  EXPECT_EQ(ep.frames[0].demonstration, (std::vector<float>{0, 0, 1, -1, 2, -2, 3, -3, 4, -4}));  // until tick 5
  EXPECT_EQ(ep.frames[1].demonstration, (std::vector<float>{3, -3, 4, -4}));
  EXPECT_EQ(ep.frames[2].source, "tick_frames/00000003.png");
  EXPECT_EQ(ep.frames[2].demonstration, (std::vector<float>{9, -9, 10, -10, 11, -11}));
  EXPECT_EQ(ep.frames[2].state, kStates[3]);
  ASSERT_EQ(ep.notes.size(), 1u);
  EXPECT_NE(ep.notes[0].find("1 frame(s) skipped"), std::string::npos) << ep.notes[0];
}

TEST(EvalEpisode, VideoFramesByIndex) {
  const std::string dir = act::test::scratch_dir();
  const std::string video = dir + "/clip.avi";
  {
    const std::unique_ptr<act::media::VideoWriter> writer = act::media::create_video(video, "MJPG", 10, cv::Size(128, 96));
    ASSERT_TRUE(writer);
    for (int i = 0; i < 6; ++i) writer->write(cv::Mat(96, 128, CV_8UC3, cv::Scalar(40 * i, 100, 200 - 30 * i)));
  }
  write_text(dir + "/states.csv", "frame_index,a,b\n1,0,0\n3,0.5,0.5\n5,1,1\n");
  write_text(dir + "/actions.csv", "frame_index,x,y\n1,1,2\n3,3,4\n5,5,6\n");
  const act::eval::Episode ep = act::eval::read_episode({video, dir + "/actions.csv", dir + "/states.csv"}, tiny_info());
  ASSERT_EQ(ep.frames.size(), 3u);
  EXPECT_EQ(ep.frames[1].source, "clip.avi frame 3");
  EXPECT_EQ(ep.frames[0].demonstration, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  act::eval::EpisodeImages images(ep);
  for (size_t f = 0; f < 3; ++f) {
    const cv::Mat image = images.image(f);
    ASSERT_FALSE(image.empty());
    // The frame's own colour (MJPG is lossy): blue channel 40 * index.
    EXPECT_NEAR(cv::mean(image)[0], 40.0 * static_cast<double>(ep.frames[f].video_index), 6.0);
  }
  // An index past the video's end names both.
  write_text(dir + "/long.csv", "frame_index,x,y\n1,1,2\n9,3,4\n");
  write_text(dir + "/long_states.csv", "frame_index,a,b\n1,0,0\n9,0,0\n");
  const act::eval::Episode past = act::eval::read_episode({video, dir + "/long.csv", dir + "/long_states.csv"}, tiny_info());
  act::eval::EpisodeImages past_images(past);
  past_images.image(0);
  expect_error([&] { past_images.image(1); }, {"clip.avi has only 6 frames", "frame 9"});
}

TEST(EvalEpisode, MalformedInputsNameFileLineAndColumn) {
  const std::string dir = act::test::scratch_dir();
  fs::create_directories(dir + "/frames");
  act::media::write_image(dir + "/frames/a.png", cv::Mat(96, 128, CV_8UC3, cv::Scalar(1, 2, 3)));
  act::media::write_image(dir + "/frames/b.png", cv::Mat(96, 128, CV_8UC3, cv::Scalar(1, 2, 3)));
  const std::string states = dir + "/states.csv", actions = dir + "/actions.csv";
  write_text(states, "frame,s0,s1\na.png,0,0\nb.png,0,0\n");
  const auto expect = [&](const std::string& actions_text, const std::vector<std::string>& fragments,
                          const std::string& states_text = "frame,s0,s1\na.png,0,0\nb.png,0,0\n") {
    write_text(actions, actions_text);
    write_text(states, states_text);
    expect_error([&] { act::eval::read_episode({dir + "/frames", actions, states}, tiny_info()); }, fragments);
  };
  expect("frame,x,y\na.png,1,oops\n", {actions, "line 2", "column 3 (y)", "'oops' is not a finite number"});
  expect("frame,x,y\na.png,1,nan\n", {"line 2", "'nan' is not a finite number"});
  expect("frame,x,y\na.png,1\n", {actions, "line 2", "2 columns where the header has 3"});
  expect("frame,x\na.png,1\n", {"1 action columns", "2 values"});
  expect("frame,x@0,y@0,x@1\na.png,1,2,3\n", {"'y' lacks the column y@1"});
  expect("frame,x@0,y@0,x@2,y@1\na.png,1,2,3,4\n", {"'x' lacks the column x@1"});
  expect("frame,x,y\nc.png,1,2\n", {"line 2 column 1", "'c.png' is neither an image", "2 images"});
  expect("frame,x,y\n7,1,2\n", {"'7' is neither an image"});
  expect("frame,x,y\nb.png,1,2\n", {"frame 'b.png' has no row in"}, "frame,s0,s1\na.png,0,0\n");
  expect("frame,x,y\na.png,1,2\n", {states, "line 2", "column 2 (s0)"}, "frame,s0,s1\na.png,x,0\n");
  expect("frame,x,y\na.png,1,2\n", {states, "3 state columns", "2 values"}, "frame,s0,s1,s2\na.png,0,0,0\n");
  expect("frame,x,y\n", {actions, "no rows"});
  expect("", {actions, "empty"});
  expect("frame,x,\"y\"\n", {"quoted fields"});
  // No actions CSV, no states CSV, nothing there.
  expect_error([&] { act::eval::read_episode({dir + "/frames", "", states}, tiny_info()); }, {"needs --actions"});
  expect_error([&] { act::eval::read_episode({dir + "/frames", actions, ""}, tiny_info()); }, {"--states"});
  expect_error([&] { act::eval::read_episode({dir + "/nope", actions, states}, tiny_info()); },
                          {"episode not found", dir + "/nope"});
  expect_error([&] { act::eval::read_episode({states, actions, states}, tiny_info()); }, {"nor a video"});
  // A recording with a broken log line, or without the model's action columns.
  fs::create_directories(dir + "/rec");
  write_text(dir + "/rec/ticks.csv", "tick,action.0,action.1\n0,1,2\n");
  write_text(dir + "/rec/log.jsonl", "{\"frame\":\"frames/000000.png\",\"state\":[0,0],\"tick\":0}\n{\"frame\": 3}\n");
  expect_error([&] { act::eval::read_episode({dir + "/rec", "", ""}, tiny_info()); },
                          {"log.jsonl line 2", "no \"frame\" file name"});
  write_text(dir + "/rec/log.jsonl", "{\"frame\":\"frames/000000.png\",\"state\":[0],\"tick\":0}\n");
  expect_error([&] { act::eval::read_episode({dir + "/rec", "", ""}, tiny_info()); },
                          {"log.jsonl line 1", "2 values"});
  write_text(dir + "/rec/ticks.csv", "tick,action.0\n0,1\n");
  expect_error([&] { act::eval::read_episode({dir + "/rec", "", ""}, tiny_info()); },
                          {"ticks.csv", "no 'action.1' column"});
  write_text(dir + "/rec/ticks.csv", "tick,action.0,action.1\n0,1,x\n");
  expect_error([&] { act::eval::read_episode({dir + "/rec", "", ""}, tiny_info()); },
                          {"ticks.csv line 2 column 3 (action.1)"});
  expect_error([&] { act::eval::read_episode({dir + "/rec", actions, ""}, tiny_info()); },
                          {"drop --states and --actions"});
}

// ---------------------------------------------------------------------------------- the command line

TEST(ActEvalEpisodeCli, GatesExitCodes) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string fp32 = convert_tiny(dir, "fp32"), int8 = convert_tiny(dir, "int8", int8_flags());
  const ImageEpisode ep = write_image_episode(dir);
  write_text(dir + "/actions.csv", "frame,steer,throttle\n" + ep.keys[0] + ",0.1,0.2\n" + ep.keys[1] + ",0.2,0.1\n" +
                                       ep.keys[2] + ",0.3,0\n" + ep.keys[3] + ",0.4,-0.1\n");
  const std::string base = std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " + q(dir + "/actions.csv") +
                           " --states " + q(ep.states) + " -m " + q(fp32) + " -m " + q(int8) + " --json " + q(dir + "/e.json");
  const CommandResult pass = run_command(base);
  ASSERT_EQ(pass.exit_code, 0) << pass.output;
  const nlohmann::json j = read_json(dir + "/e.json");
  const double own = j["models"][0]["vs_demonstration"]["chunk"]["normalised"]["mse"].get<double>();
  const double added = j["models"][1]["added_error_fraction"].get<double>();
  EXPECT_GT(added, 0.0);
  EXPECT_NEAR(added, j["models"][1]["vs_reference"]["chunk"]["normalised"]["mse"].get<double>() / own, 1e-12 * added);
  EXPECT_NE(pass.output.find("added error"), std::string::npos) << pass.output;
  // The added error as a percentage, a verdict line, and the baselines beside the policy's error.
  EXPECT_NEAR(j["models"][1]["added_error_percent"].get<double>(), 100 * added, 1e-9 * added);
  EXPECT_NE(pass.output.find("% of model 1's own error"), std::string::npos) << pass.output;
  EXPECT_NE(pass.output.find("verdict      model 2 adds "), std::string::npos) << pass.output;
  EXPECT_NE(pass.output.find("baselines    chunk MSE against the demonstration (normalised), no policy: hold last action "),
            std::string::npos) << pass.output;
  ASSERT_EQ(j["baselines"].size(), 3u);
  EXPECT_EQ(j["baselines"][1]["name"], "mean action");
  EXPECT_TRUE(j["baselines"][2]["vs_demonstration"]["chunk"]["normalised"]["mse"].is_number());
  const CommandResult within = run_command(base + " --max-added-error " + std::to_string(added * 2));
  EXPECT_NE(within.output.find(": within --max-added-error"), std::string::npos) << within.output;
  EXPECT_NE(within.output.find("PASS"), std::string::npos) << within.output;

  EXPECT_EQ(run_command(base + " --max-mse " + std::to_string(own * 2) + " --max-added-error " + std::to_string(added * 2)).exit_code, 0);
  const CommandResult mse = run_command(base + " --max-mse " + std::to_string(own / 2));
  EXPECT_EQ(mse.exit_code, 2) << mse.output;
  EXPECT_NE(mse.output.find("above --max-mse"), std::string::npos) << mse.output;
  const CommandResult add = run_command(base + " --max-added-error " + std::to_string(added / 2));
  EXPECT_EQ(add.exit_code, 2) << add.output;
  EXPECT_NE(add.output.find("above --max-added-error"), std::string::npos) << add.output;
  // Bad input is exit 1, naming the file; --help documents the codes.
  const CommandResult bad = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                        q(ep.states + ".missing") + " --states " + q(ep.states) + " -m " + q(fp32));
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find(ep.states + ".missing"), std::string::npos) << bad.output;
  const CommandResult help = run_command(std::string(ACT_EVAL_BIN) + " --help");
  EXPECT_NE(help.output.find("3 a model gave NaN"), std::string::npos) << help.output;
}

TEST(ActEvalEpisodeCli, NonFiniteOutputFails) {
  // The import refuses non-finite and huge weights, but not a huge (finite) action spread: with the
  // action head's bias at 1e6 and the action std at 3e38 every un-normalised action overflows.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string src = act::test::fixture_dir("act-tiny"), ckpt = dir + "/overflow-ckpt";
  const std::string model = "model.safetensors", stats = "policy_postprocessor_step_0_unnormalizer_processor.safetensors";
  fs::create_directories(ckpt);
  for (const auto& entry : fs::directory_iterator(src)) {
    const std::string name = entry.path().filename().string();
    if (name != model && name != stats) fs::create_symlink(entry.path(), ckpt + "/" + name);
  }
  act::test::write_with_values_replaced(src + "/" + model, ckpt + "/" + model, "model.action_head.bias", 0, 1e6f);
  act::test::write_with_values_replaced(src + "/" + stats, ckpt + "/" + stats, "action.std", 0, 3e38f);
  const std::string blob = dir + "/overflow.actb";
  const CommandResult c = run_command(std::string(ACT_CONVERT_BIN) + " " + q(ckpt) + " -o " + q(blob) + " -q");
  ASSERT_EQ(c.exit_code, 0) << c.output;
  const ImageEpisode ep = write_image_episode(dir);
  write_text(dir + "/actions.csv", "frame,steer,throttle\n" + ep.keys[0] + ",0.1,0.2\n");
  const CommandResult r = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                      q(dir + "/actions.csv") + " --states " + q(ep.states) + " -m " + q(blob) +
                                      " --max-mse 1e9 --json " + q(dir + "/e.json"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("output values are NaN or infinite"), std::string::npos) << r.output;
  EXPECT_TRUE(read_json(dir + "/e.json")["models"][0]["vs_demonstration"]["chunk"]["raw"]["mse"].is_null());
}

TEST(ActEvalEpisodeCli, HtmlReportHoldsTheEpisode) {
  // (test/browser/run_report_pages.sh renders it in chromium.)
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string fp32 = convert_tiny(dir, "fp32");
  const ImageEpisode ep = write_image_episode(dir);
  write_text(dir + "/actions.csv", "frame,steer,throttle\n" + ep.keys[0] + ",0.1,0.2\n" + ep.keys[1] + ",0.2,0.1\n");
  const std::string html = dir + "/report.html";
  const CommandResult r = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                      q(dir + "/actions.csv") + " --states " + q(ep.states) + " -m " + q(fp32) +
                                      " --report " + q(html));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<uint8_t> bytes = act::test::read_file(html);
  const std::string text(bytes.begin(), bytes.end());
  for (const char* part : {"<h3>steer</h3>", "<h3>throttle</h3>", "Error histogram", ep.keys[0].c_str(), "class='chart actions'",
                           "Baselines (no policy), beside the first model", "<td>hold last action (",
                           "<td>mean action (", "<td>zero ("}) {
    EXPECT_NE(text.find(part), std::string::npos) << part;
  }
  EXPECT_EQ(text.find("http"), std::string::npos);
  // With FP32 then INT8, the actions chart draws INT8 first, wider, and FP32 over it, so both show.
  const std::string int8 = convert_tiny(dir, "int8", int8_flags());
  const CommandResult two = run_command(std::string(ACT_EVAL_BIN) + " --episode " + q(ep.frames) + " --actions " +
                                        q(dir + "/actions.csv") + " --states " + q(ep.states) + " -m " + q(fp32) + " -m " +
                                        q(int8) + " --report " + q(html));
  ASSERT_EQ(two.exit_code, 0) << two.output;
  const std::vector<uint8_t> page_bytes = act::test::read_file(html);
  const std::string page(page_bytes.begin(), page_bytes.end());
  const size_t chart = page.find("class='chart actions'");
  ASSERT_NE(chart, std::string::npos);
  const size_t fp32_line = page.find("stroke='#1f77b4'", chart), int8_line = page.find("stroke='#d62728'", chart);
  ASSERT_NE(fp32_line, std::string::npos);
  ASSERT_NE(int8_line, std::string::npos);
  EXPECT_LT(int8_line, fp32_line) << "INT8 is drawn over FP32";
  EXPECT_NE(page.find("stroke-width='5.5' stroke-opacity='0.70' stroke='#d62728'", chart), std::string::npos);
  EXPECT_NE(page.find("stroke-width='3.5' stroke-opacity='0.70' stroke='#1f77b4'", chart), std::string::npos);
}

TEST(ActConvertCli, KeepFloatAndHtmlReportUseOneLayerNaming) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string kept = "backbone.conv1.weight,decoder.layers.0.linear1.weight";
  convert_tiny(dir, "int8", int8_flags() + " --keep-float " + kept + " --report " + q(dir + "/r.json"));
  const nlohmann::json j = read_json(dir + "/r.json");
  EXPECT_EQ(j["float_layers"], nlohmann::json({"backbone.conv1.weight", "decoder.layers.0.linear1.weight"}));
  // The SQNR list names layers as float_layers does, the kept ones marked.
  size_t marked = 0;
  for (const auto& l : j["layers"]) {
    const std::string name = l["layer"];
    const bool in_float_list = name == "backbone.conv1.weight" || name == "decoder.layers.0.linear1.weight";
    EXPECT_EQ(l["kept_float"].get<bool>(), in_float_list) << name;
    marked += in_float_list;
  }
  EXPECT_EQ(marked, 2u);
  // Each calibrated activation: scale = int8 range / 255, zero point in int8.
  ASSERT_FALSE(j["activations"].empty());
  for (const auto& a : j["activations"]) {
    const double lo = a["quantized_range"][0], hi = a["quantized_range"][1];
    EXPECT_NEAR((hi - lo) / 255.0, a["scale"].get<double>(), 1e-6 * a["scale"].get<double>()) << a["value"];
    EXPECT_LE(a["observed_range"][0].get<double>(), a["observed_range"][1].get<double>());
  }
  // A name that is no layer fails, naming it and how layers are named; nothing is written.
  const CommandResult bad = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                        q(dir + "/bad.actb") + " -q " + int8_flags() + " --keep-float cam0.backbone.stem");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("\"cam0.backbone.stem\" is not a quantizable layer"), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("backbone.conv1.weight"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(dir + "/bad.actb"));

  const std::string html = dir + "/r.html";
  convert_tiny(dir, "int8_html", int8_flags() + " --keep-float " + kept + " --report " + q(html));
  const std::vector<uint8_t> bytes = act::test::read_file(html);
  const std::string text(bytes.begin(), bytes.end());
  EXPECT_NE(text.find("backbone.conv1.weight (float)"), std::string::npos);
  EXPECT_NE(text.find("Calibrated activations"), std::string::npos);
  EXPECT_EQ(text.find("http"), std::string::npos);
}

}  // namespace
