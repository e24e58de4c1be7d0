// What kind of file or folder a path is, from its first bytes (or a folder's telltale files), so that
// a tool given the wrong kind can say what it got and which command takes it.
#pragma once

#include <string>

namespace act {

enum class FileKind {
  kMissing, kLeRobotCheckpoint, kTrainingCheckpoint, kRecording, kLeRobotDataset, kFolder,
  kActb, kSafetensors, kPyTorchZip, kPyTorchLegacy, kPng, kJpeg, kVideo, kOther,
};

FileKind file_kind(const std::string& path);
/// "a LeRobot checkpoint folder", "a PNG image", ...
const char* file_kind_name(FileKind kind);
/// Which command takes a file of this kind, e.g. "convert it first with act_convert ckpt -o model.actb";
/// "" for kinds no tool takes (kMissing, kFolder, kOther).
std::string what_takes(FileKind kind, const std::string& path);
/// "'PATH' is KIND, not WANTED: WHAT_TAKES", for a tool given the wrong kind of file.
std::string wrong_kind_message(const std::string& path, FileKind kind, const std::string& wanted);
/// For a tool that wants an .actb blob: "" when `path` is one (or cannot be told), else what it is and
/// what to do, e.g. "'ckpt' is a LeRobot checkpoint folder, not an .actb blob: convert it first with
/// act_convert ckpt -o model.actb".
std::string not_a_blob_hint(const std::string& path);

}  // namespace act
