#include "weights/blob/file_kind.h"

#include <fcntl.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>

namespace act {

namespace fs = std::filesystem;

namespace {

FileKind folder_kind(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_regular_file(dir / "config.json", ec)) return FileKind::kLeRobotCheckpoint;
  if (fs::is_regular_file(dir / "pretrained_model" / "config.json", ec)) return FileKind::kTrainingCheckpoint;
  if (fs::is_regular_file(dir / "log.jsonl", ec)) return FileKind::kRecording;
  if (fs::is_regular_file(dir / "meta" / "info.json", ec)) return FileKind::kLeRobotDataset;
  return FileKind::kFolder;
}

FileKind bytes_kind(const unsigned char* b, size_t n) {
  const auto starts = [&](const char* magic, size_t len) { return n >= len && std::memcmp(b, magic, len) == 0; };
  if (starts("ACTBLOB", 8)) return FileKind::kActb;  // with its NUL
  if (starts("\x89PNG", 4)) return FileKind::kPng;
  if (starts("\xFF\xD8\xFF", 3)) return FileKind::kJpeg;
  if (starts("PK\x03\x04", 4)) return FileKind::kPyTorchZip;
  if (starts("\x80\x02\x8a", 3)) return FileKind::kPyTorchLegacy;  // protocol 2, then the magic long
  if ((n >= 8 && std::memcmp(b + 4, "ftyp", 4) == 0) || starts("RIFF", 4) || starts("\x1A\x45\xDF\xA3", 4)) {
    return FileKind::kVideo;  // MP4/MOV, AVI, Matroska/WebM
  }
  if (n >= 9 && b[8] == '{') return FileKind::kSafetensors;  // 8-byte header length, then the JSON header
  return FileKind::kOther;
}

}  // namespace

FileKind file_kind(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return FileKind::kMissing;
  if (fs::is_directory(path, ec)) return folder_kind(path);
  if (!fs::is_regular_file(path, ec)) return FileKind::kOther;
  unsigned char head[16] = {};
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return FileKind::kOther;
  const ssize_t n = ::read(fd, head, sizeof head);
  ::close(fd);
  return n > 0 ? bytes_kind(head, static_cast<size_t>(n)) : FileKind::kOther;
}

const char* file_kind_name(FileKind kind) {
  switch (kind) {
    case FileKind::kMissing: return "missing";
    case FileKind::kLeRobotCheckpoint: return "a LeRobot checkpoint folder";
    case FileKind::kTrainingCheckpoint: return "a LeRobot training checkpoint (the policy is in pretrained_model/)";
    case FileKind::kRecording: return "an act_drive recording";
    case FileKind::kLeRobotDataset: return "a LeRobot dataset";
    case FileKind::kFolder: return "a folder";
    case FileKind::kActb: return "an .actb blob";
    case FileKind::kSafetensors: return "a safetensors file";
    case FileKind::kPyTorchZip: return "a PyTorch checkpoint (torch.save zip)";
    case FileKind::kPyTorchLegacy: return "a PyTorch checkpoint (legacy format)";
    case FileKind::kPng: return "a PNG image";
    case FileKind::kJpeg: return "a JPEG image";
    case FileKind::kVideo: return "a video";
    case FileKind::kOther: return "not a known kind of file";
  }
  return "not a known kind of file";
}

std::string what_takes(FileKind kind, const std::string& path) {
  switch (kind) {
    case FileKind::kLeRobotCheckpoint:
    case FileKind::kTrainingCheckpoint:
    case FileKind::kPyTorchZip:
    case FileKind::kPyTorchLegacy: return "convert it first with act_convert " + path + " -o model.actb";
    case FileKind::kActb:
      return "it is already converted: run it with act_bench -m " + path + ", act_eval -m " + path +
             " -i OBS.safetensors or act_drive -m " + path;
    case FileKind::kSafetensors:
      return "observations go to act_eval -i or act_bench --input; a checkpoint's model.safetensors is converted "
             "with its folder: act_convert FOLDER -o model.actb";
    case FileKind::kRecording:
    case FileKind::kLeRobotDataset:
    case FileKind::kPng:
    case FileKind::kJpeg:
    case FileKind::kVideo:
      return "frames are calibration input: act_convert CHECKPOINT -o model.actb --precision int8 --calib " + path;
    case FileKind::kMissing:
    case FileKind::kFolder:
    case FileKind::kOther: return "";
  }
  return "";
}

std::string wrong_kind_message(const std::string& path, FileKind kind, const std::string& wanted) {
  std::string message = "'" + path + "' is " + file_kind_name(kind) + ", not " + wanted;
  if (const std::string next = what_takes(kind, path); !next.empty()) message += ": " + next;
  return message;
}

std::string not_a_blob_hint(const std::string& path) {
  const FileKind kind = file_kind(path);
  if (kind == FileKind::kActb || kind == FileKind::kMissing || kind == FileKind::kOther) return "";
  return wrong_kind_message(path, kind, "an .actb blob");
}

}  // namespace act
