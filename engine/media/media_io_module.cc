// libact_media_io.so: OpenCV's imgcodecs and videoio behind act::media::MediaIo (media_io.h says why
// they live in a module loaded on first use).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "engine/media/media_io.h"

namespace act::media {
namespace {

class OpenCvVideoReader final : public VideoReader {
 public:
  bool read(cv::Mat& frame) override { return capture.read(frame); }
  double get(int property) const override { return capture.get(property); }
  bool set(int property, double value) override { return capture.set(property, value); }

  cv::VideoCapture capture;
};

class OpenCvVideoWriter final : public VideoWriter {
 public:
  void write(const cv::Mat& bgr) override { writer.write(bgr); }

  cv::VideoWriter writer;
};

std::unique_ptr<VideoReader> opened_or_null(std::unique_ptr<OpenCvVideoReader> reader) {
  if (!reader->capture.isOpened()) return nullptr;
  return reader;
}

class OpenCvMediaIo final : public MediaIo {
 public:
  cv::Mat decode_image(const uint8_t* data, size_t size, int flags) const override {
    if (size == 0) return {};
    return cv::imdecode(cv::Mat(1, static_cast<int>(size), CV_8UC1, const_cast<uint8_t*>(data)), flags);
  }
  bool write_image(const std::string& path, const cv::Mat& image) const override { return cv::imwrite(path, image); }
  bool encode_image(const std::string& extension, const cv::Mat& image, std::vector<uchar>& encoded) const override {
    return cv::imencode(extension, image, encoded);
  }
  std::unique_ptr<VideoReader> open_video(const std::string& source, int backend,
                                          const std::vector<int>& parameters) const override {
    auto reader = std::make_unique<OpenCvVideoReader>();
    reader->capture.open(source, backend, parameters);
    return opened_or_null(std::move(reader));
  }
  std::unique_ptr<VideoReader> open_camera(int index, int backend) const override {
    auto reader = std::make_unique<OpenCvVideoReader>();
    reader->capture.open(index, backend);
    return opened_or_null(std::move(reader));
  }
  std::unique_ptr<VideoWriter> create_video(const std::string& path, const std::string& fourcc, double fps,
                                            cv::Size size) const override {
    if (fourcc.size() != 4) return nullptr;
    auto writer = std::make_unique<OpenCvVideoWriter>();
    writer->writer.open(path, cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps, size);
    if (!writer->writer.isOpened()) return nullptr;
    return writer;
  }
};

}  // namespace
}  // namespace act::media

extern "C" __attribute__((visibility("default"))) const act::media::MediaIo& act_media_io() {
  static const act::media::OpenCvMediaIo media_io;
  return media_io;
}
