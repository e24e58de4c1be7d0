// Progress on stderr (apps/progress.h): one line rewritten in place on a terminal, a few plain lines
// elsewhere; and act_convert's calibration messages on a real pseudo-terminal (`script`) and off it.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>


#include "engine/media/media_io.h"
#include "apps/progress.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

// What a ProgressLine writes for `run`, captured through an in-memory FILE.
template <typename Run>
std::string rendered(bool terminal, Run run) {
  char* buffer = nullptr;
  size_t size = 0;
  std::FILE* out = open_memstream(&buffer, &size);
  {
    act::ProgressLine progress(out, "tool", terminal);
    run(progress);
  }
  std::fclose(out);
  std::string text(buffer, size);
  std::free(buffer);
  return text;
}

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

void eight_frames_then_a_message(act::ProgressLine& p) {
  for (size_t i = 0; i <= 8; ++i) p.update("calibrating", i, 8, "frames");
  p.message("done");
}

TEST(ProgressLine, OnATerminalOneLineIsRewrittenInPlace) {
  const std::string text = rendered(true, eight_frames_then_a_message);
  EXPECT_EQ(count(text, "\r"), 9u) << text;
  EXPECT_EQ(count(text, "\n"), 2u) << text;  // the progress line's end, then the message
  EXPECT_NE(text.find("\rtool: calibrating: 0/8 frames\033[K"), std::string::npos) << text;
  EXPECT_NE(text.find("\rtool: calibrating: 3/8 frames, "), std::string::npos) << text;
  EXPECT_NE(text.find(" left\033[K"), std::string::npos) << text;  // the time left, while some are
  EXPECT_NE(text.find("8/8 frames, "), std::string::npos) << text;
  EXPECT_NE(text.find("\ntool: done\n"), std::string::npos) << text;
}

TEST(ProgressLine, ElsewhereAPlainLineAtTheStartAndEachQuarter) {
  const std::string text = rendered(false, eight_frames_then_a_message);
  EXPECT_EQ(count(text, "\r"), 0u) << text;
  EXPECT_EQ(count(text, "\033"), 0u) << text;
  EXPECT_EQ(count(text, "tool: calibrating: "), 5u) << text;  // 0, 2, 4, 6, 8 of 8
  for (const char* n : {"0/8", "2/8", "4/8", "6/8", "8/8"}) EXPECT_NE(text.find(std::string(": ") + n + " frames"), std::string::npos) << n;
  EXPECT_EQ(text.find("1/8"), std::string::npos) << text;
  // 1000 items: still five lines.
  const std::string many = rendered(false, [](act::ProgressLine& p) {
    for (size_t i = 0; i <= 1000; ++i) p.update("runs", i, 1000, "runs");
  });
  EXPECT_EQ(count(many, "\n"), 5u) << many;
}

// act-tiny converted to INT8 on its four sample frames plus, given, frames of another shape.
class CalibrationMessages : public ::testing::Test {
 protected:
  void SetUp() override {
    fixture_ = act::test::fixture_dir("act-tiny");
    ACT_REQUIRE_PATH(fixture_);
    dir_ = act::test::scratch_dir();
    fs::create_directories(dir_ + "/frames");
    for (int i = 0; i < 4; ++i) {
      const std::string name = "/sample" + std::to_string(i) + ".observation.images.front.png";
      fs::copy_file(fixture_ + name, dir_ + "/frames" + name);
    }
  }
  std::string convert(const std::string& calib, const std::string& extra = "") const {
    return std::string(ACT_CONVERT_BIN) + " " + q(fixture_) + " -o " + q(dir_ + "/m.actb") + " --precision int8 --calib " +
           q(calib) + " --threads 1 " + extra;
  }
  std::string fixture_, dir_;
};

TEST_F(CalibrationMessages, ProgressOnAPseudoTerminalAndOffIt) {
  // `script` runs act_convert on a pseudo-terminal (stderr a tty) and copies what it shows.
  const CommandResult tty = run_command("script -qec " + q(convert(dir_ + "/frames")) + " /dev/null");
  ASSERT_EQ(tty.exit_code, 0) << tty.output;
  EXPECT_NE(tty.output.find("\ract_convert: calibrating (mse): 0/"), std::string::npos) << tty.output;
  EXPECT_NE(tty.output.find("\033[K"), std::string::npos) << tty.output;

  const CommandResult plain = run_command(convert(dir_ + "/frames"));
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  EXPECT_EQ(plain.output.find('\r'), std::string::npos) << plain.output;
  EXPECT_NE(plain.output.find("act_convert: calibrating (mse): 3/3 frames"), std::string::npos) << plain.output;
  EXPECT_LE(count(plain.output, "calibrating (mse)"), 5u) << plain.output;  // at most five lines (one pass)
}

TEST_F(CalibrationMessages, FewerFramesThanAskedSaysHowManyAndWhy) {
  const CommandResult r = run_command(convert(dir_ + "/frames", "--calib-samples 400"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // 400 + 16 held out wanted; the folder holds 4 images.
  EXPECT_NE(r.output.find("read 4 calibration frames of the 416 wanted (calibration samples + held-out): " + dir_ +
                          "/frames gave only 4 (its share: 416)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("calibrated on 3 frames, fewer than the 400 asked: the calibration set holds 4 frames and 1 of "
                          "them are held out"), std::string::npos) << r.output;
}

TEST_F(CalibrationMessages, FramesOfAnotherAspectRatioAreAWarning) {
  // 360x640 (16:9) frames for the model's 96x128 (4:3) camera (height x width).
  fs::create_directories(dir_ + "/wide");
  act::media::write_image(dir_ + "/wide/f0.png", cv::Mat(360, 640, CV_8UC3, cv::Scalar(40, 90, 160)));
  act::media::write_image(dir_ + "/wide/f1.png", cv::Mat(360, 640, CV_8UC3, cv::Scalar(200, 30, 60)));
  const CommandResult r = run_command(convert(dir_ + "/wide"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string warning = "warning: calibration frames of 360x640 are stretched to the model's 96x128 (height x width";
  EXPECT_NE(r.output.find("act_convert: " + warning), std::string::npos) << r.output;  // as the frames are read
  EXPECT_NE(r.output.find("\n" + warning), std::string::npos) << r.output;             // and in the report
  // Frames of the model's own shape get no warning.
  const CommandResult same = run_command(convert(dir_ + "/frames"));
  EXPECT_EQ(same.output.find("stretched"), std::string::npos) << same.output;
}

// "128 frames given, 64 used for calibration, 16 held out, 48 left out": the frames not used are
// said, in the printed report and in the report file.
TEST_F(CalibrationMessages, SaysHowManyFramesWereUsedHeldOutAndLeftOut) {
  fs::create_directories(dir_ + "/ten");
  for (int i = 0; i < 10; ++i) {
    fs::copy_file(fixture_ + "/sample" + std::to_string(i % 4) + ".observation.images.front.png",
                  dir_ + "/ten/f" + std::to_string(i) + ".png");
  }
  const CommandResult r = run_command(convert(dir_ + "/ten", "--calib-samples 4 --holdout 2 --report " + q(dir_ + "/r.json")));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string note = "10 frames given, 4 used for calibration, 2 held out, 4 left out (--calib-samples 4 sets how many "
                           "are used)";
  EXPECT_NE(r.output.find("note: " + note), std::string::npos) << r.output;
  std::ifstream in(dir_ + "/r.json");
  const std::string report((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(report.find(note), std::string::npos) << report;
  // All of them used: nothing left out.
  const CommandResult all = run_command(convert(dir_ + "/ten", "--calib-samples 8 --holdout 2"));
  ASSERT_EQ(all.exit_code, 0) << all.output;
  EXPECT_NE(all.output.find("note: 10 frames given, 8 used for calibration, 2 held out\n"), std::string::npos) << all.output;
}

TEST_F(CalibrationMessages, UpscaledFramesAreAWarningNamingBothSizes) {
  // 48x64 frames for the model's 96x128 camera: blown up 2x, the same aspect ratio.
  fs::create_directories(dir_ + "/small");
  act::media::write_image(dir_ + "/small/f0.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(40, 90, 160)));
  act::media::write_image(dir_ + "/small/f1.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(200, 30, 60)));
  const CommandResult r = run_command(convert(dir_ + "/small"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string warning = "warning: calibration frames of 48x64 are upscaled 2x to the model's 96x128 (height x width";
  EXPECT_NE(r.output.find("act_convert: " + warning), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\n" + warning), std::string::npos) << r.output;  // in the report
  EXPECT_EQ(r.output.find("stretched"), std::string::npos) << r.output;
  const CommandResult same = run_command(convert(dir_ + "/frames"));
  EXPECT_EQ(same.output.find("upscaled"), std::string::npos) << same.output;
}

}  // namespace
