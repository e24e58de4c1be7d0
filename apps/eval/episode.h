// A recorded episode for act_eval: frames, the robot state of each, and the demonstrated actions.
//
// Sources (read_episode):
//   - an act_drive --record folder: frames and states from log.jsonl, the actions executed from
//     ticks.csv's "action.<i>" columns (looked up by name; other columns are ignored), matched by tick;
//   - a folder of images or a video, with an actions CSV and (when the model has a state) a states CSV:
//       first column: a frame (an image's path in the folder, or a 0-based index of the folder's images,
//       subfolders included, sorted by path, or of the video's frames), then one named column per value. An actions row holds either one
//       action ("steer,throttle") or a chunk of future actions, its columns named NAME@K with K the
//       steps ahead of the frame ("steer@0,throttle@0,steer@1,throttle@1,...");
//       without a frame column (the first column's name is not a frame's, e.g. "frame" or "file", and
//       every column is a value) the rows are the frames in order;
//       or the long form, a chunk over rows: "file,chunk_index,steer,throttle,is_pad" (is_pad
//       optional; padded steps are left out of the demonstration).
// With one action per row, a frame's demonstrated chunk is the actions of the rows that follow it.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "actengine/engine.h"
#include "engine/media/media_io.h"

namespace act::eval {

struct EpisodeFrame {
  std::string source;        ///< where the image is, for people: "frames/000012.png" or "video.mp4 frame 12"
  std::string image_path;    ///< the image file; empty when the frame comes from the episode's video
  std::string where;         ///< the file and line that name the frame ("ticks.csv:12"), for errors
  size_t video_index = 0;    ///< the frame's index in the video
  std::vector<float> state;  ///< raw robot state; empty when the model has none
  /// The demonstration from this frame on: steps x action_dim raw actions, row-major, at least one step.
  std::vector<float> demonstration;
};

struct Episode {
  std::string path;
  std::string kind;                       ///< e.g. "act_drive recording", "video + CSV"
  std::string video;                      ///< the video the frames come from; empty for image files
  std::vector<std::string> action_names;  ///< one per action dimension
  std::vector<EpisodeFrame> frames;       ///< in time order
  std::vector<std::string> notes;         ///< what a user should know about how it was read
};

/// What a user names: the episode (recording folder, image folder or video) and, for the latter two, the CSVs.
struct EpisodeSources {
  std::string episode, actions_csv, states_csv;
  /// Instead of states_csv: "last-action" (the action demonstrated at the frame before), "mean"
  /// (the training mean) or "zeros"; empty: from states_csv.
  std::string state = {};
};

/// Reads and checks everything against the model (action and state sizes). Throws act::Error
/// naming the file, line and column of anything malformed.
Episode read_episode(const EpisodeSources& sources, const ModelInfo& model);

/// Decodes an episode's images in order (a video is read once, front to back).
class EpisodeImages {
 public:
  explicit EpisodeImages(const Episode& episode);
  /// The image of frame i as decoded (BGR); i must not decrease between calls. Throws act::Error.
  cv::Mat image(size_t i);

 private:
  const Episode& episode_;
  std::unique_ptr<media::VideoReader> video_;  // null without a video
  size_t next_video_index_ = 0;
};

}  // namespace act::eval
