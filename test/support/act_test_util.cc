#include "support/act_test_util.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/test_paths.h"
#include "weights/import/lerobot_import.h"

namespace fs = std::filesystem;

namespace act::test {

Int8Options quick_int8_options(Int8Mode mode) {
  Int8Options options;
  options.mode = mode;
  options.calib_samples = 8;
  options.holdout = 3;
  options.threads = 2;
  options.layer_report = false;
  return options;
}

namespace {

std::string hex_hash(const std::string& text) {
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016zx", std::hash<std::string>{}(text));
  return hex;
}

// What a conversion of `checkpoint_dir` by `exe` depends on: the names, sizes and modification
// times of the checkpoint's files and of the binary (a rebuild may convert differently).
std::string conversion_key(const fs::path& checkpoint_dir, const fs::path& exe) {
  std::vector<fs::path> files{exe};
  for (const auto& entry : fs::recursive_directory_iterator(checkpoint_dir)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  std::sort(files.begin() + 1, files.end());
  std::ostringstream id;
  for (const fs::path& f : files) {
    id << f.string() << ' ' << fs::file_size(f) << ' ' << fs::last_write_time(f).time_since_epoch().count() << '\n';
  }
  return hex_hash(id.str());
}

}  // namespace

std::string convert_checkpoint(const std::string& checkpoint_dir, const std::string& scratch, const std::string& stem) {
  const std::string path = (fs::path(scratch) / (stem + ".actb")).string();
  const auto convert_to = [&](const std::string& blob) { write_fp32_blob(import_lerobot_checkpoint(checkpoint_dir), blob); };
  // Many tests convert the same checkpoint (a second each under ASan, more for the full-size
  // ones): the first conversion by this test binary is kept beside it, one per checkpoint, and the
  // later ones, in any process, copy it.
  std::error_code ec;
  const fs::path exe = this_executable();
  const fs::path cache_dir = exe.parent_path() / "converted_checkpoints";
  if (!exe.empty()) fs::create_directories(cache_dir, ec);
  if (exe.empty() || ec || !fs::is_directory(checkpoint_dir)) {
    convert_to(path);
    return path;
  }
  const std::string prefix = exe.filename().string() + "." + hex_hash(fs::canonical(checkpoint_dir).string()) + ".";
  const fs::path cached = cache_dir / (prefix + conversion_key(checkpoint_dir, exe) + ".actb");
  if (!fs::exists(cached)) {
    // An older conversion of the same checkpoint goes (not a blob being written: "<name>.actb.tmp.<pid>").
    for (const auto& entry : fs::directory_iterator(cache_dir)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind(prefix, 0) == 0 && name.find(".actb.") == std::string::npos) fs::remove(entry.path(), ec);
    }
    convert_to(cached.string());  // the blob writer's file gets its name only once complete
  }
  if (!fs::copy_file(cached, path, fs::copy_options::overwrite_existing, ec)) {
    convert_to(path);  // evicted meanwhile by a rebuilt binary
  }
  return path;
}

std::vector<float> nchw_to_hwc(const float* src, int channels, int height, int width) {
  std::vector<float> out(static_cast<size_t>(channels) * height * width);
  const size_t plane = static_cast<size_t>(height) * width;
  for (int c = 0; c < channels; ++c) {
    for (size_t i = 0; i < plane; ++i) out[i * channels + c] = src[c * plane + i];
  }
  return out;
}

::testing::AssertionResult all_close(const std::string& what, const float* ours, const float* ref, size_t n, double tol) {
  if (n == 0) return ::testing::AssertionFailure() << what << ": nothing to compare";
  double worst = -1.0;
  size_t worst_i = 0;
  for (size_t i = 0; i < n; ++i) {
    const double diff = std::fabs(static_cast<double>(ours[i]) - ref[i]);
    const double ratio = std::isnan(diff) ? INFINITY : diff / (1.0 + std::fabs(static_cast<double>(ref[i])));
    if (ratio > worst) {
      worst = ratio;
      worst_i = i;
    }
  }
  if (worst <= tol) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << what << ": element " << worst_i << " is " << ours[worst_i] << ", reference "
                                       << ref[worst_i] << " (|diff|/(1+|ref|) = " << worst << " > " << tol << ")";
}

void patch_checkpoint(const std::string& src, const std::string& dst, const std::string& config_patch_json) {
  fs::create_directories(dst);
  for (const auto& entry : fs::directory_iterator(src)) {
    const fs::path target = fs::path(dst) / entry.path().filename();
    if (entry.path().filename() == "config.json") continue;
    fs::create_symlink(fs::absolute(entry.path()), target);
  }
  std::ifstream in(fs::path(src) / "config.json");
  nlohmann::ordered_json config = nlohmann::ordered_json::parse(in);
  const nlohmann::ordered_json patch = nlohmann::ordered_json::parse(config_patch_json);
  for (const auto& [key, value] : patch.items()) config[key] = value;
  std::ofstream(fs::path(dst) / "config.json") << config.dump(4);
}

void write_with_values_replaced(const std::string& src, const std::string& dst, const std::string& name, size_t first,
                                float value) {
  const SafetensorsFile in = SafetensorsFile::open(src);
  std::vector<std::vector<uint8_t>> copies;
  std::vector<SafetensorsWriteTensor> out;
  copies.reserve(in.names().size());
  for (const std::string& n : in.names()) {
    const SafetensorsTensor& t = in.get(n);
    copies.emplace_back(t.data, t.data + t.nbytes);
    if (n == name) {
      auto* values = reinterpret_cast<float*>(copies.back().data());
      for (size_t i = first; i < t.elements(); ++i) values[i] = value;
    }
    out.push_back({n, t.dtype, t.shape, copies.back().data(), t.nbytes});
  }
  write_safetensors(dst, out);
}

}  // namespace act::test
