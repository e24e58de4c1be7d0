// act_drive's camera: every kind of source opens through its backend, each way of failing says
// what it was given, a stalled network stream is reopened, and stopping never waits for a backend
// that blocks.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <functional>
#include <string>
#include <thread>


#include "actengine/status.h"
#include "apps/drive/camera.h"
#include "engine/media/media_io.h"
#include "drive/drive_test_util.h"
#include "drive/stalling_stream.h"
#include "support/test_paths.h"

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

TEST(Camera, AVideoFilePlaysFromTheStartOfPlayback) {
  const std::string dir = act::test::scratch_dir();
  Camera camera(CameraOptions{write_test_video(dir + "/v.avi", 10, 30, 80, 60), 0, 0, 0});
  const Clock::time_point opened = camera.latest()->captured;
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // six frame intervals
  EXPECT_EQ(camera.latest()->index, 0u) << "the file played before start_playback()";
  camera.start_playback();
  EXPECT_GE(camera.latest()->captured - opened, std::chrono::milliseconds(200));  // its first frame is delivered now
  ASSERT_TRUE(eventually([&] { return camera.state() == FrameSource::State::kEnded; }));
  EXPECT_EQ(camera.latest()->index, 9u);
}

TEST(Camera, OpensAnImageSequenceLikeACamera) {
  const std::string dir = act::test::scratch_dir();
  for (int i = 0; i < 3; ++i) {
    act::media::write_image(dir + "/frame_00" + std::to_string(i) + ".png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(10 * i, 20, 30)));
  }
  Camera camera(CameraOptions{dir + "/frame_%03d.png", 0, 0, 0});
  EXPECT_FALSE(camera.is_file());
  EXPECT_TRUE(camera.is_replay());  // played at its rate, like a video file
  EXPECT_EQ(camera.latest()->interval, std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / 30)));
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

// A FIFO given as the camera, or as an image sequence's first frame (which OpenCV opened and waited
// on forever), is refused at once, naming it.
TEST(Camera, RefusesAFifoAtOnce) {
  const std::string dir = act::test::scratch_dir();
  const std::string fifo = dir + "/camera.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  ASSERT_EQ(::mkfifo((dir + "/frame_000.png").c_str(), 0644), 0);
  act::media::write_image(dir + "/frame_001.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)));
  // A reader stuck on a FIFO is released after 3 s (an end of file), so a failure does not hang the suite.
  std::atomic<bool> done{false};
  std::thread release([&] {
    const auto start = Clock::now();
    while (!done.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (Clock::now() - start < std::chrono::seconds(3)) continue;
      for (const std::string& path : {fifo, dir + "/frame_000.png"}) {
        const int writer = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);  // fails at once while nobody reads
        if (writer >= 0) ::close(writer);
      }
    }
  });
  const std::string as_camera = open_error(fifo);
  const std::string as_frame = open_error(dir + "/frame_%03d.png");
  done.store(true);
  release.join();
  EXPECT_NE(as_camera.find("camera '" + fifo + "': is not a regular file (a FIFO)"), std::string::npos) << as_camera;
  EXPECT_NE(as_frame.find("camera '" + dir + "/frame_%03d.png': '" + dir + "/frame_000.png' is not a regular file (a FIFO)"),
            std::string::npos) << as_frame;
}

TEST(Camera, ReopensANetworkStreamThatStalls) {
  const std::string dir = act::test::scratch_dir();
  StallingStreamServer server(write_test_video(dir + "/v.avi", 30, 30), std::chrono::milliseconds(0));
  CameraOptions options{server.url(), 0, 0, 0};
  options.read_timeout = std::chrono::milliseconds(300);
  Camera camera(options);
  EXPECT_FALSE(camera.is_file());
  ASSERT_TRUE(eventually([&] { return server.connections() >= 2; })) << "the stall was never detected: " << camera.problem();
  EXPECT_EQ(camera.state(), FrameSource::State::kReconnecting);
  const std::string problem = camera.problem();
  EXPECT_NE(problem.find("camera '" + server.url() + "' stopped delivering frames (stalled: no frame for "), std::string::npos)
      << problem;
}

TEST(Camera, StopLeavesBehindACaptureThreadBlockedInItsBackend) {
  const std::string dir = act::test::scratch_dir();
  StallingStreamServer server(write_test_video(dir + "/v.avi", 30, 30), std::chrono::milliseconds(0));
  CameraOptions options{server.url(), 0, 0, 0};
  options.read_timeout = std::chrono::minutes(1);  // FFmpeg's read blocks for a minute once the frames run out
  Camera camera(options);
  ASSERT_TRUE(eventually([&] { return Clock::now() - camera.latest()->captured > std::chrono::milliseconds(300); }));
  const auto start = Clock::now();
  EXPECT_FALSE(camera.stop(std::chrono::milliseconds(200)));
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(5));
  EXPECT_TRUE(Camera::left_a_thread_behind());
  EXPECT_FALSE(camera.stop());  // the same answer again, at once
  ASSERT_NE(camera.latest(), nullptr);  // what it captured stays readable
}

TEST(Camera, StopEndsAHealthyCaptureThreadWithoutWaitingForItsNextFrame) {
  const std::string dir = act::test::scratch_dir();
  // A file played at one frame every 20 s: the capture thread sleeps until then unless told to stop.
  Camera camera(CameraOptions{write_test_video(dir + "/v.avi", 10, 30), 0, 0, 0.05});
  EXPECT_TRUE(camera.stop(std::chrono::seconds(5)));
  EXPECT_TRUE(camera.stop());
}

}  // namespace
}  // namespace act::drive::test
