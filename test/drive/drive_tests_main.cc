// act_drive_tests' main: gtest's, ending the process as act_drive does when a Camera left its
// capture thread behind (Camera::left_a_thread_behind): std::_Exit, so no static destructor runs
// while that thread may still be inside OpenCV (a camera test that stops a camera blocked in its
// backend otherwise aborts at exit, after it passed, with glibc's "corrupted double-linked list").
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>

#include "apps/drive/camera.h"

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  const int result = RUN_ALL_TESTS();
  if (act::drive::Camera::left_a_thread_behind()) {
    std::fflush(nullptr);
    std::_Exit(result);
  }
  return result;
}
