#include "actengine/calibration_files.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <memory>
#include <set>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "actengine/status.h"
#include "actengine/vision.h"
#include "engine/media/media_io.h"
#include "engine/src/convert/observation_file.h"
#include "weights/blob/file_kind.h"
#include "weights/blob/file_util.h"

namespace act {

namespace fs = std::filesystem;

namespace {

const std::set<std::string> kImageExtensions = {".png", ".jpg", ".jpeg", ".bmp"};
const std::set<std::string> kVideoExtensions = {".mp4", ".avi", ".mkv", ".mov", ".webm"};

std::string lower_extension(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e;
}

// `count` indices spread evenly over [0, n).
std::vector<size_t> spread(size_t n, size_t count) {
  std::vector<size_t> idx;
  if (n == 0 || count == 0) return idx;
  count = std::min(count, n);
  for (size_t i = 0; i < count; ++i) idx.push_back(i * n / count);
  return idx;
}

class Loader {
 public:
  explicit Loader(const ModelInfo& model) : model_(model) {}

  CalibrationSet take() { return std::move(set_); }
  size_t frames() const { return set_.frames.size(); }
  /// The frames the sources hold, read or not.
  size_t given() const { return given_; }

  void add_source(const std::string& source, size_t max_frames) {
    const fs::path p(source);
    if (!fs::exists(p)) fail(StatusCode::kNotFound, "calibration source not found: " + source);
    // A model given as frames says what it is (a checkpoint folder holding images is still a folder of images).
    switch (const FileKind kind = file_kind(source)) {
      case FileKind::kLeRobotCheckpoint:
      case FileKind::kTrainingCheckpoint:
        if (!files_in(p, is_image_file).empty()) break;
        [[fallthrough]];
      case FileKind::kActb:
      case FileKind::kPyTorchZip:
      case FileKind::kPyTorchLegacy:
        fail(StatusCode::kInvalidArgument, wrong_kind_message(source, kind, "calibration frames"));
      default: break;
    }
    if (fs::is_directory(p)) {
      if (fs::exists(p / "meta" / "info.json") && fs::is_directory(p / "videos")) return add_lerobot_dataset(p, max_frames);
      if (fs::exists(p / "log.jsonl")) return add_recording(p, max_frames);
      return add_image_folder(p, max_frames);
    }
    if (lower_extension(p) == ".safetensors") return add_observation_file(p, max_frames);
    if (is_video_file(p)) return add_video(p, max_frames);
    if (is_image_file(p)) return add_images({p}, max_frames, p.string());
    fail(StatusCode::kInvalidArgument, "calibration source " + source +
         " is not a folder, a video (mp4, avi, mkv, mov, webm), an image or an observation .safetensors file");
  }

 private:
  void note(const std::string& n) {
    if (std::find(set_.notes.begin(), set_.notes.end(), n) == set_.notes.end()) set_.notes.push_back(n);
  }

  void to_model_rgb(const cv::Mat& image, const CameraInfo& cam, std::vector<uint8_t>& rgb) {
    // A frame of another shape is stretched to the model's input, as act_drive's camera would be; the
    // model saw training frames of its own aspect ratio, so calibration on stretched ones misleads.
    const double frame_aspect = static_cast<double>(image.cols) / image.rows;
    const double model_aspect = static_cast<double>(cam.width) / cam.height;
    if (std::abs(frame_aspect - model_aspect) > 0.01 * model_aspect) {
      note("warning: calibration frames of " + std::to_string(image.rows) + "x" + std::to_string(image.cols) +
           " are stretched to the model's " + std::to_string(cam.height) + "x" + std::to_string(cam.width) + " (height x width, " +
           cam.key + "): another aspect ratio than training's; use frames from the robot's camera at its training setting");
    }
    // Frames much smaller than the model's input are blown up: less detail than the camera the model
    // was trained on gave it, which the calibration then measures.
    const double upscale = std::max(static_cast<double>(cam.height) / image.rows, static_cast<double>(cam.width) / image.cols);
    if (upscale >= 2.0) {
      char factor[32];
      std::snprintf(factor, sizeof factor, "%.3g", upscale);
      note("warning: calibration frames of " + std::to_string(image.rows) + "x" + std::to_string(image.cols) +
           " are upscaled " + factor + "x to the model's " + std::to_string(cam.height) + "x" + std::to_string(cam.width) +
           " (height x width, " + cam.key + "): they hold less detail than the model's input; use frames from the "
           "robot's camera at its training size");
    }
    const Status converted = frame_to_model_rgb(image, cam.height, cam.width, rgb);
    if (!converted.ok()) throw Error(converted);
  }

  // A frame whose cameras all see `image`. The states the source lacks (or has with the wrong
  // length) stay empty: the conversion samples them.
  // `state`: the robot state logged with the frame (a recording), or null for a source without any.
  void add_frame_all_cameras(const cv::Mat& image, const std::vector<float>* state = nullptr) {
    CalibrationFrame f;
    for (const auto& cam : model_.cameras) {
      f.images.emplace_back();
      to_model_rgb(image, cam, f.images.back());
    }
    if (model_.cameras.size() > 1) note("single-view source: every camera was given the same frame");
    if (state && model_.state_dim > 0) f.state = *state;
    set_.frames.push_back(std::move(f));
  }

  void add_images(const std::vector<fs::path>& files, size_t max_frames, const std::string& source) {
    if (files.empty()) fail(StatusCode::kNotFound, "calibration folder " + source + " has no images (png, jpg, jpeg, bmp)");
    given_ += files.size();
    for (size_t i : spread(files.size(), max_frames)) {
      std::string why;
      const cv::Mat image = media::read_image(files[i].string(), cv::IMREAD_COLOR, &why);
      if (image.empty()) fail(StatusCode::kDataLoss, "calibration image: " + why);
      add_frame_all_cameras(image);
    }
  }

  void add_image_folder(const fs::path& dir, size_t max_frames) {
    add_images(files_in(dir, is_image_file), max_frames, dir.string());
  }

  // Opens a video; throws naming it when OpenCV cannot.
  static std::unique_ptr<media::VideoReader> open_video(const fs::path& p) {
    // FFmpeg only, as act_drive reads video files: the same decoder gives the same frames.
    std::unique_ptr<media::VideoReader> video = media::open_video(p.string(), cv::CAP_FFMPEG);
    if (!video) fail(StatusCode::kDataLoss, "cannot open video " + p.string() + " (OpenCV/FFmpeg)");
    return video;
  }

  // Decodes frames at the given indices (ascending) of one video.
  static std::vector<cv::Mat> video_frames(const fs::path& p, const std::vector<size_t>& wanted) {
    const std::unique_ptr<media::VideoReader> video = open_video(p);
    std::vector<cv::Mat> out;
    size_t index = 0, next = 0;
    cv::Mat frame;
    while (next < wanted.size() && video->read(frame)) {
      if (index == wanted[next]) {
        out.push_back(frame.clone());
        ++next;
      }
      ++index;
    }
    return out;
  }

  static size_t video_length(const fs::path& p) {
    const std::unique_ptr<media::VideoReader> video = open_video(p);
    const double n = video->get(cv::CAP_PROP_FRAME_COUNT);
    if (n >= 1) return static_cast<size_t>(n);
    size_t count = 0;  // the container does not say: count by decoding
    cv::Mat frame;
    while (video->read(frame)) ++count;
    return count;
  }

  void add_video(const fs::path& p, size_t max_frames) {
    const size_t n = video_length(p);
    if (n == 0) fail(StatusCode::kDataLoss, "video " + p.string() + " has no frames");
    given_ += n;
    const std::vector<size_t> wanted = spread(n, max_frames);
    const std::vector<cv::Mat> frames = video_frames(p, wanted);
    if (frames.empty()) fail(StatusCode::kDataLoss, "could not decode any frame of " + p.string());
    for (const cv::Mat& frame : frames) add_frame_all_cameras(frame);
  }

  // LeRobot dataset: videos/**/<camera key>/**.mp4, one file per episode (or chunk file) per camera.
  void add_lerobot_dataset(const fs::path& dir, size_t max_frames) {
    std::vector<std::vector<fs::path>> per_camera;
    for (const auto& cam : model_.cameras) {
      std::vector<fs::path> files;
      for (const auto& f : files_in(dir / "videos", is_video_file)) {
        for (const auto& part : f) {
          if (part.string() == cam.key) {
            files.push_back(f);
            break;
          }
        }
      }
      if (files.empty()) {
        fail(StatusCode::kNotFound,
             "LeRobot dataset " + dir.string() + " has no videos for camera \"" + cam.key + "\"");
      }
      if (!per_camera.empty() && files.size() != per_camera[0].size()) {
        fail(StatusCode::kDataLoss, "LeRobot dataset " + dir.string() + ": cameras have different numbers of video files");
      }
      per_camera.push_back(std::move(files));
    }
    const size_t n_files = per_camera[0].size();
    const size_t per_file = std::max<size_t>(1, (max_frames + n_files - 1) / n_files);
    std::vector<size_t> lengths;
    for (const fs::path& file : per_camera[0]) lengths.push_back(video_length(file));
    for (size_t length : lengths) given_ += length;
    size_t added = 0;
    for (size_t f = 0; f < n_files && added < max_frames; ++f) {
      const std::vector<size_t> wanted = spread(lengths[f], per_file);
      std::vector<std::vector<cv::Mat>> frames;
      for (const auto& files : per_camera) frames.push_back(video_frames(files[f], wanted));
      for (size_t i = 0; i < wanted.size(); ++i) {
        CalibrationFrame frame;
        bool complete = true;
        for (size_t c = 0; c < model_.cameras.size(); ++c) {
          if (i >= frames[c].size()) {
            complete = false;
            break;
          }
          frame.images.emplace_back();
          to_model_rgb(frames[c][i], model_.cameras[c], frame.images.back());
        }
        if (!complete) break;
        set_.frames.push_back(std::move(frame));
        ++added;
      }
    }
    note("LeRobot dataset: frames decoded from its videos; states are not read from its parquet files");
  }

  // act_drive --record folder: log.jsonl lines {"frame": "<path relative to the folder>", "state": [...]}.
  void add_recording(const fs::path& dir, size_t max_frames) {
    const std::string log_path = (dir / "log.jsonl").string();
    std::istringstream in(detail::read_regular_file(log_path));  // a FIFO is refused, never waited on
    std::vector<std::pair<fs::path, std::vector<float>>> entries;
    std::string line;
    size_t line_no = 0;
    while (std::getline(in, line)) {
      ++line_no;
      if (line.empty()) continue;
      const std::string where = log_path + ":" + std::to_string(line_no);
      std::vector<float> state;
      std::string frame;
      try {
        const auto j = detail::parse_untrusted_json<nlohmann::json>(where, line.data(), line.size(), "not valid JSON");
        if (!j.contains("frame")) continue;
        if (j.contains("state") && j["state"].is_array()) state = j["state"].get<std::vector<float>>();
        frame = j["frame"].get<std::string>();
      } catch (const std::exception& e) {
        // A recording cut off by a crash may end in a partial line (no newline): skip it, say so. Any
        // other bad line (a duplicate key included) is an error, not a frame quietly left out.
        if (!in.eof()) fail(StatusCode::kDataLoss, e.what());
        note(log_path + ": skipped unreadable line " + std::to_string(line_no) + " (cut short)");
        continue;
      }
      // States of another length belong to another model: calibrating on sampled states instead would
      // hide that (and once did, with a note saying the source had none).
      if (model_.state_dim > 0 && state.size() != static_cast<size_t>(model_.state_dim)) {
        fail(StatusCode::kInvalidArgument, where + ": the recording's state has " + std::to_string(state.size()) +
             " values, the model's has " + std::to_string(model_.state_dim) + " (recorded with another model?)");
      }
      entries.emplace_back(dir / frame, std::move(state));
    }
    // Not the folder's images instead: they would calibrate without the states the recording holds.
    if (entries.empty()) fail(StatusCode::kDataLoss, log_path + " names no frame: nothing to calibrate on in this recording");
    given_ += entries.size();
    for (size_t i : spread(entries.size(), max_frames)) {
      std::string why;
      const cv::Mat image = media::read_image(entries[i].first.string(), cv::IMREAD_COLOR, &why);
      if (image.empty()) fail(StatusCode::kDataLoss, "recorded frame: " + why);
      add_frame_all_cameras(image, &entries[i].second);
    }
  }

  void add_observation_file(const fs::path& p, size_t max_frames) {
    const ObservationBatch batch = ObservationBatch::read(p.string(), model_);
    given_ += batch.size();
    for (size_t i : spread(batch.size(), max_frames)) {
      const Observation obs = batch.at(i);
      CalibrationFrame f;
      for (size_t c = 0; c < obs.images.size(); ++c) {
        const ImageView& v = obs.images[c];
        std::vector<uint8_t> rgb(static_cast<size_t>(v.height) * v.width * 3);
        if (v.format == ImageView::Format::kRgbU8Hwc) {
          const auto* src = static_cast<const uint8_t*>(v.data);
          const size_t stride = v.row_stride ? v.row_stride : static_cast<size_t>(v.width) * 3;
          for (int y = 0; y < v.height; ++y) std::copy_n(src + y * stride, v.width * 3, rgb.data() + static_cast<size_t>(y) * v.width * 3);
        } else {
          const auto* src = static_cast<const float*>(v.data);
          const size_t plane = static_cast<size_t>(v.height) * v.width;
          for (size_t px = 0; px < plane; ++px) {
            for (size_t ch = 0; ch < 3; ++ch) {
              rgb[px * 3 + ch] = static_cast<uint8_t>(std::clamp(std::nearbyint(src[ch * plane + px] * 255.0f), 0.0f, 255.0f));
            }
          }
        }
        f.images.push_back(std::move(rgb));
      }
      f.state.assign(obs.state.begin(), obs.state.end());
      f.env_state.assign(obs.env_state.begin(), obs.env_state.end());
      set_.frames.push_back(std::move(f));
    }
  }

 private:
  const ModelInfo& model_;
  CalibrationSet set_;
  size_t given_ = 0;
};

}  // namespace

bool is_image_file(const fs::path& p) { return kImageExtensions.count(lower_extension(p)) > 0; }
bool is_video_file(const fs::path& p) { return kVideoExtensions.count(lower_extension(p)) > 0; }

std::vector<fs::path> files_in(const fs::path& dir, bool (*pick)(const fs::path&)) {
  std::vector<fs::path> out;
  for (const auto& entry : fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied)) {
    if (entry.is_regular_file() && pick(entry.path())) out.push_back(entry.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

namespace {

CalibrationSet read_calibration_frames(const std::vector<std::string>& sources, const ModelInfo& model, size_t max_frames,
                                       size_t* given) {
  if (sources.empty()) fail(StatusCode::kInvalidArgument, "no calibration sources given");
  Loader loader(model);
  // Every source contributes its share of the frames.
  const size_t share = std::max<size_t>(1, (max_frames + sources.size() - 1) / sources.size());
  std::vector<std::string> short_sources;
  for (const auto& s : sources) {
    const size_t before = loader.frames();
    loader.add_source(s, share);
    if (loader.frames() - before < share) {
      short_sources.push_back(s + " gave only " + std::to_string(loader.frames() - before) + " (its share: " + std::to_string(share) + ")");
    }
  }
  if (given) *given = loader.given();
  CalibrationSet set = loader.take();
  if (set.frames.size() > max_frames) set.frames.resize(max_frames);
  if (set.frames.size() < max_frames) {
    std::string why;
    for (const auto& s : short_sources) why += (why.empty() ? "" : "; ") + s;
    set.notes.push_back("read " + std::to_string(set.frames.size()) + " calibration frames of the " + std::to_string(max_frames) +
                        " wanted (calibration samples + held-out): " + why);
  }
  if (!model.cameras.empty()) {
    set.preprocessing = model_preprocessing_description(model.cameras[0].height, model.cameras[0].width);
  }
  return set;
}

}  // namespace

StatusOr<CalibrationSet> load_calibration_frames(const std::vector<std::string>& sources, const ModelInfo& model,
                                                 size_t max_frames, size_t* given) {
  try {
    return read_calibration_frames(sources, model, max_frames, given);
  } catch (const Error& e) {
    return e.status();
  } catch (const std::exception& e) {  // std::filesystem's, on a folder that cannot be listed
    return Status(StatusCode::kIoError, "calibration sources: " + std::string(e.what()));
  }
}

}  // namespace act
