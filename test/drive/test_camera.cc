// act_drive's camera: every kind of source opens through its backend, and each way of failing says
// what it was given.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "apps/drive/camera.h"
#include "drive/drive_test_util.h"
#include "support/test_paths.h"
#include "weights/blob/error.h"

namespace act::drive::test {
namespace {

// What opening `source` throws ("" when it opens).
std::string open_error(const std::string& source) {
  try {
    Camera camera(CameraOptions{source, 0, 0, 0});
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Camera, OpensAVideoFileAtItsSize) {
  const std::string dir = act::test::scratch_dir();
  Camera camera(CameraOptions{write_test_video(dir + "/v.avi", 10, 30, 80, 60), 0, 0, 0});
  EXPECT_TRUE(camera.is_file());
  EXPECT_EQ(camera.width(), 80);
  EXPECT_EQ(camera.height(), 60);
  ASSERT_NE(camera.latest(), nullptr);
  EXPECT_EQ(camera.latest()->bgr.cols, 80);
}

TEST(Camera, OpensAnImageSequenceLikeACamera) {
  const std::string dir = act::test::scratch_dir();
  for (int i = 0; i < 3; ++i) {
    cv::imwrite(dir + "/frame_00" + std::to_string(i) + ".png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(10 * i, 20, 30)));
  }
  Camera camera(CameraOptions{dir + "/frame_%03d.png", 0, 0, 0});
  EXPECT_FALSE(camera.is_file());
  EXPECT_EQ(camera.width(), 64);
  EXPECT_EQ(camera.height(), 48);
}

TEST(Camera, EachFailureNamesTheSource) {
  const std::string dir = act::test::scratch_dir();
  const std::string missing = dir + "/no-such-video.avi";
  std::string error = open_error(missing);
  EXPECT_NE(error.find("cannot open camera '" + missing + "': no such file"), std::string::npos) << error;

  const std::string bogus = dir + "/clip.mp4";
  std::ofstream(bogus) << "not a video";
  error = open_error(bogus);
  EXPECT_NE(error.find("cannot open camera '" + bogus + "'"), std::string::npos) << error;
  EXPECT_EQ(error.find("no such file"), std::string::npos) << error;

  error = open_error(dir + "/empty_%03d.png");  // a pattern that matches nothing
  EXPECT_NE(error.find("cannot open camera"), std::string::npos) << error;
}

}  // namespace
}  // namespace act::drive::test
