#include "weights/blob/actb.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "actengine/status.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"
#include "weights/blob/blob_tensors.h"
#include "weights/blob/file_util.h"
#include "weights/blob/quant_config.h"
#include "weights/import/safetensors.h"

namespace act {
namespace {

namespace fs = std::filesystem;
using test::list_dir;
using test::throws_error;

// ---------------------------------------------------------------------------------------------- helpers

uint64_t get_le(const std::vector<uint8_t>& b, size_t pos, int n) {
  uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | b[pos + static_cast<size_t>(i)];
  return v;
}

void put_le(std::vector<uint8_t>& b, size_t pos, uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b[pos + static_cast<size_t>(i)] = static_cast<uint8_t>(v >> (8 * i));
}

uint32_t crc_from_64(const std::vector<uint8_t>& b) {
  uLong crc = ::crc32(0L, Z_NULL, 0);
  if (b.size() > 64) crc = ::crc32(crc, b.data() + 64, static_cast<uInt>(b.size() - 64));
  return static_cast<uint32_t>(crc);
}

void fix_checksum(std::vector<uint8_t>& b) { put_le(b, 40, crc_from_64(b), 8); }

uint64_t align64(uint64_t v) { return (v + 63) / 64 * 64; }

// An .actb file built by hand from a header text and a data area, with a correct checksum. By default the
// data area starts at the next 64-byte boundary after the header.
std::vector<uint8_t> raw_actb(const std::string& json, const std::vector<uint8_t>& data,
                              std::optional<uint64_t> data_offset = std::nullopt) {
  const uint64_t off = data_offset.value_or(align64(64 + json.size()));
  std::vector<uint8_t> b(std::max<size_t>(off, 64 + json.size()) + data.size(), 0);
  std::memcpy(b.data(), "ACTBLOB\0", 8);
  put_le(b, 8, kActbFormatVersion, 4);
  put_le(b, 16, json.size(), 8);
  put_le(b, 24, off, 8);
  put_le(b, 32, data.size(), 8);
  std::copy(json.begin(), json.end(), b.begin() + 64);
  // A data_offset inside the JSON (a corruption test) overwrites its tail, as a real bad file would.
  b.resize(off + data.size());
  std::copy(data.begin(), data.end(), b.begin() + static_cast<long>(off));
  fix_checksum(b);
  return b;
}

// A header with the given tensor entries (a comma-separated list of JSON objects).
std::string header_with(const std::string& entries) {
  return R"({"producer":"test","config":{},"tensors":[)" + entries + "]}";
}

std::string entry(const std::string& name, const std::string& dtype, const std::string& shape, uint64_t offset,
                  uint64_t nbytes, const std::string& extra = "") {
  return R"({"name":")" + name + R"(","dtype":")" + dtype + R"(","shape":)" + shape +
         R"(,"offset":)" + std::to_string(offset) + R"(,"nbytes":)" + std::to_string(nbytes) + extra + "}";
}

// True if `p` lies in a read-only mapping of the file `path` in this process.
bool points_into_mapping_of(const void* p, const std::string& path) {
  const std::string want = fs::canonical(path).string();
  const auto addr = reinterpret_cast<uintptr_t>(p);
  std::ifstream maps("/proc/self/maps");
  std::string line;
  while (std::getline(maps, line)) {
    std::istringstream in(line);
    std::string range, perms, offset, dev, inode, file;
    in >> range >> perms >> offset >> dev >> inode;
    std::getline(in >> std::ws, file);
    const size_t dash = range.find('-');
    const uintptr_t begin = std::stoull(range.substr(0, dash), nullptr, 16);
    const uintptr_t end = std::stoull(range.substr(dash + 1), nullptr, 16);
    if (addr >= begin && addr < end) return file == want && perms.size() >= 2 && perms[0] == 'r' && perms[1] == '-';
  }
  return false;
}

template <typename T>
std::vector<uint8_t> as_bytes(const std::vector<T>& v) {
  std::vector<uint8_t> out(v.size() * sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), v.data(), out.size());
  return out;
}

// A small valid blob used by the corruption tests.
ActbWriter small_writer() {
  ActbWriter w;
  w.set_producer("unit test");
  w.set_config({{"dim_model", 8}, {"name", "tiny"}});
  w.add_f32("a", {2, 3}, {1, 2, 3, 4, 5, 6});
  const std::vector<int8_t> q = {-1, 2, -3, 4};
  w.add_tensor("q", DType::kI8, {4}, q.data(), q.size(), QuantParams{{0.5f}, {0}, 0});
  w.add_f32("b", {3}, {7, 8, 9});
  return w;
}

class ActbBad : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = test::scratch_dir() + "/bad.actb";
    small_writer().write(path_);
    good_ = test::read_file(path_);
    data_offset_ = get_le(good_, 24, 8);
    header_size_ = get_le(good_, 16, 8);
  }

  ::testing::AssertionResult rejects(const std::vector<uint8_t>& bytes, StatusCode code,
                                     std::vector<std::string> needles, bool verify = true) {
    test::write_file(path_, bytes);
    needles.push_back(path_);
    return throws_error([&] { ActbFile::open(path_, verify); }, code, needles);
  }
  ::testing::AssertionResult corrupt(const std::vector<uint8_t>& bytes, std::vector<std::string> needles,
                                     bool verify = true) {
    return rejects(bytes, StatusCode::kDataLoss, std::move(needles), verify);
  }
  // A hand-built blob with these tensor entries over `data_size` bytes of data must be rejected.
  ::testing::AssertionResult rejects_entries(const std::string& entries, size_t data_size,
                                             std::vector<std::string> needles) {
    return corrupt(raw_actb(header_with(entries), std::vector<uint8_t>(data_size, 0x5A)), std::move(needles));
  }

  std::string path_;
  std::vector<uint8_t> good_;
  uint64_t data_offset_ = 0;
  uint64_t header_size_ = 0;
};

// ---------------------------------------------------------------------------------------------- round trips

TEST(Actb, RoundTripEveryDtypeAndQuant) {
  const std::string path = test::scratch_dir() + "/model.actb";
  const std::vector<float> f32 = {1.5f, -2.25f, 0.0f, 3.0e-8f, 1e30f, -7.0f};
  const std::vector<uint16_t> f16 = {0x3C00, 0xC000, 0x0001, 0x7BFF};
  const std::vector<uint16_t> bf16 = {0x3F80, 0xC000, 0x4049};
  const std::vector<int8_t> i8 = {-128, -1, 0, 1, 127};
  const std::vector<uint8_t> u8 = {0, 128, 255, 1, 2, 3};
  const std::vector<int32_t> i32 = {std::numeric_limits<int32_t>::min(), 42, -7, 0};
  const std::vector<double> f64 = {3.141592653589793};
  const std::vector<int64_t> i64 = {std::numeric_limits<int64_t>::max()};
  const QuantParams per_tensor{{0.0123f}, {-3}, 0};
  const QuantParams per_channel{{0.1f, 0.2f, 1e-7f}, {0, 128, 255}, 1};

  ActbWriter w;
  w.set_producer("act_convert test");
  const nlohmann::json config = {{"dim_model", 512}, {"backbone", "resnet18"}, {"blocks", {2, 2, 2, 2}}};
  w.set_config(config);
  w.add_f32("f32", {2, 3}, f32);
  w.add_tensor("f16", DType::kF16, {2, 2}, f16.data(), 8);
  w.add_tensor("bf16", DType::kBF16, {3}, bf16.data(), 6);
  w.add_tensor("i8", DType::kI8, {5}, i8.data(), 5, per_tensor);
  w.add_tensor("u8", DType::kU8, {2, 3}, u8.data(), 6, per_channel);
  w.add_tensor("i32", DType::kI32, {4}, i32.data(), 16);
  w.add_tensor("f64", DType::kF64, {1}, f64.data(), 8);
  w.add_tensor("i64", DType::kI64, {}, i64.data(), 8);
  w.add_f32("scalar", {}, {2.5f});
  w.add_f32("empty", {0, 4}, {});
  w.add_tensor("empty.i8", DType::kI8, {3, 0}, nullptr, 0);
  const size_t written = w.write(path);

  const ActbFile f = ActbFile::open(path);
  EXPECT_EQ(f.path(), path);
  EXPECT_EQ(f.file_size(), written);
  EXPECT_EQ(fs::file_size(path), written);
  EXPECT_EQ(f.format_version(), kActbFormatVersion);
  EXPECT_EQ(f.producer(), "act_convert test");
  EXPECT_EQ(f.config(), config);

  std::vector<std::string> names;
  for (const ActbTensor& t : f.tensors()) names.push_back(t.name);
  EXPECT_EQ(names, (std::vector<std::string>{"f32", "f16", "bf16", "i8", "u8", "i32", "f64", "i64", "scalar",
                                             "empty", "empty.i8"}));

  auto check = [&](const std::string& name, DType dtype, std::vector<int64_t> shape, const std::vector<uint8_t>& bytes,
                   const QuantParams& quant = {}) {
    SCOPED_TRACE(name);
    const ActbTensor& t = f.get(name);
    EXPECT_EQ(&t, f.find(name));
    EXPECT_EQ(t.dtype, dtype);
    EXPECT_EQ(t.shape, shape);
    EXPECT_EQ(t.elements(), shape_elements(shape));
    ASSERT_EQ(t.nbytes, bytes.size());
    if (!bytes.empty()) {
      EXPECT_EQ(std::memcmp(t.data, bytes.data(), bytes.size()), 0);
    }
    EXPECT_EQ(t.quant.scales, quant.scales);
    EXPECT_EQ(t.quant.zero_points, quant.zero_points);
    EXPECT_EQ(t.quant.empty(), quant.empty());
    if (!quant.empty()) {
      EXPECT_EQ(t.quant.axis, quant.axis);
    }
  };
  check("f32", DType::kF32, {2, 3}, as_bytes(f32));
  check("f16", DType::kF16, {2, 2}, as_bytes(f16));
  check("bf16", DType::kBF16, {3}, as_bytes(bf16));
  check("i8", DType::kI8, {5}, as_bytes(i8), per_tensor);
  check("u8", DType::kU8, {2, 3}, as_bytes(u8), per_channel);
  check("i32", DType::kI32, {4}, as_bytes(i32));
  check("f64", DType::kF64, {1}, as_bytes(f64));
  check("i64", DType::kI64, {}, as_bytes(i64));
  check("scalar", DType::kF32, {}, as_bytes(std::vector<float>{2.5f}));
  check("empty", DType::kF32, {0, 4}, {});
  check("empty.i8", DType::kI8, {3, 0}, {});

  EXPECT_EQ(std::vector<float>(f.get("f32").f32(), f.get("f32").f32() + 6), f32);
  EXPECT_EQ(*f.get("scalar").f32(), 2.5f);
}

TEST(Actb, TensorDataIsAlignedAndPointsIntoTheMapping) {
  const std::string path = test::scratch_dir() + "/aligned.actb";
  ActbWriter w;
  // Odd sizes, so an unpadded layout would misalign the next tensor.
  w.add_tensor("u8", DType::kU8, {3}, "\x01\x02\x03", 3);
  w.add_f32("f", {5}, {1, 2, 3, 4, 5});
  w.add_tensor("i8", DType::kI8, {1}, "\x07", 1);
  w.add_f32("big", {1000}, std::vector<float>(1000, 0.5f));
  w.write(path);

  const ActbFile f = ActbFile::open(path);
  const std::vector<uint8_t> bytes = test::read_file(path);
  const uint64_t data_offset = get_le(bytes, 24, 8);
  const uint8_t* base = f.get("u8").data - data_offset;  // where the mapping must start
  EXPECT_EQ(reinterpret_cast<uintptr_t>(base) % static_cast<uintptr_t>(sysconf(_SC_PAGESIZE)), 0u);
  for (const ActbTensor& t : f.tensors()) {
    SCOPED_TRACE(t.name);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(t.data) % kActbAlignment, 0u);
    // No copy: the pointer is inside a read-only mapping of this very file, at the matching offset.
    EXPECT_TRUE(points_into_mapping_of(t.data, path));
    EXPECT_TRUE(points_into_mapping_of(t.data + t.nbytes - 1, path));
    const auto file_pos = static_cast<size_t>(t.data - base);
    EXPECT_EQ(std::memcmp(t.data, bytes.data() + file_pos, t.nbytes), 0);
  }
  EXPECT_EQ(f.get("big").f32()[999], 0.5f);
}

TEST(Actb, MovedFileKeepsTensorsValid) {
  const std::string path = test::scratch_dir() + "/move.actb";
  small_writer().write(path);
  ActbFile f = ActbFile::open(path);
  const float* a = f.get("a").f32();
  ActbFile g = std::move(f);
  EXPECT_EQ(g.get("a").f32(), a);
  EXPECT_EQ(a[5], 6.0f);
  EXPECT_EQ(g.path(), path);
}

TEST(Actb, FileLayoutMatchesTheSpec) {
  const std::string path = test::scratch_dir() + "/layout.actb";
  const size_t written = small_writer().write(path);
  const std::vector<uint8_t> b = test::read_file(path);
  ASSERT_EQ(b.size(), written);
  EXPECT_EQ(std::memcmp(b.data(), "ACTBLOB\0", 8), 0);
  EXPECT_EQ(get_le(b, 8, 4), kActbFormatVersion);
  EXPECT_EQ(get_le(b, 12, 4), 0u);
  const uint64_t header_size = get_le(b, 16, 8);
  const uint64_t data_offset = get_le(b, 24, 8);
  const uint64_t data_size = get_le(b, 32, 8);
  EXPECT_EQ(data_offset % 64, 0u);
  EXPECT_GE(data_offset, 64 + header_size);
  EXPECT_LT(data_offset, 64 + header_size + 64);  // no wasted space beyond alignment
  EXPECT_EQ(data_offset + data_size, b.size());
  EXPECT_EQ(get_le(b, 40, 8), crc_from_64(b));
  for (size_t i = 48; i < 64; ++i) EXPECT_EQ(b[i], 0) << i;

  const auto header = nlohmann::json::parse(b.begin() + 64, b.begin() + 64 + static_cast<long>(header_size));
  EXPECT_EQ(header["producer"], "unit test");
  EXPECT_EQ(header["config"]["dim_model"], 8);
  ASSERT_EQ(header["tensors"].size(), 3u);
  EXPECT_EQ(header["tensors"][0]["name"], "a");
  EXPECT_EQ(header["tensors"][0]["offset"], 0);
  EXPECT_EQ(header["tensors"][0]["nbytes"], 24);
  EXPECT_EQ(header["tensors"][1]["offset"], 64);
  EXPECT_EQ(header["tensors"][1]["quant"]["scales"], nlohmann::json::array({0.5}));
  EXPECT_EQ(header["tensors"][1]["quant"]["zero_points"], nlohmann::json::array({0}));
  EXPECT_EQ(header["tensors"][1]["quant"]["axis"], 0);
  EXPECT_FALSE(header["tensors"][0].contains("quant"));
  EXPECT_EQ(header["tensors"][2]["offset"], 128);
}

TEST(Actb, HandBuiltFileIsRead) {
  // Written independently of ActbWriter, straight from the layout in actb.h.
  const std::string path = test::scratch_dir() + "/hand.actb";
  std::vector<uint8_t> data(192, 0);
  const float v[2] = {1.25f, -4.0f};
  std::memcpy(data.data() + 128, v, sizeof v);
  data[0] = 9;
  const std::string json = R"({"producer":"hand","config":{"k":[1,2]},"tensors":[)" +
                           entry("late", "F32", "[2]", 128, 8) + "," +
                           entry("early", "U8", "[1]", 0, 1, R"(,"quant":{"scales":[2],"zero_points":[3],"axis":0})") +
                           "," + entry("none", "F32", "[0]", 192, 0) + "]}";
  test::write_file(path, raw_actb(json, data));
  const ActbFile f = ActbFile::open(path);
  EXPECT_EQ(f.producer(), "hand");
  EXPECT_EQ(f.config()["k"][1], 2);
  EXPECT_EQ(f.get("late").f32()[1], -4.0f);
  EXPECT_EQ(f.get("early").data[0], 9);
  EXPECT_EQ(f.get("early").quant.scales, std::vector<float>{2.0f});
  EXPECT_EQ(f.get("early").quant.zero_points, std::vector<int32_t>{3});
  EXPECT_EQ(f.get("none").nbytes, 0u);
}

TEST(Actb, EmptyBlob) {
  const std::string path = test::scratch_dir() + "/empty.actb";
  ActbWriter w;
  const size_t n = w.write(path);
  EXPECT_EQ(n % 64, 0u);
  const ActbFile f = ActbFile::open(path);
  EXPECT_TRUE(f.tensors().empty());
  EXPECT_EQ(f.producer(), "actengine");
  EXPECT_TRUE(f.config().is_object());
}

TEST(Actb, GetMissingTensorIsNotFound) {
  const std::string path = test::scratch_dir() + "/get.actb";
  small_writer().write(path);
  const ActbFile f = ActbFile::open(path);
  EXPECT_EQ(f.find("nope"), nullptr);
  EXPECT_TRUE(throws_error([&] { f.get("nope"); }, StatusCode::kNotFound, {"'nope'", path}));
}

TEST(Actb, F32AccessorChecksDtype) {
  const std::string path = test::scratch_dir() + "/f32.actb";
  small_writer().write(path);
  const ActbFile f = ActbFile::open(path);
  EXPECT_TRUE(throws_error([&] { f.get("q").f32(); }, StatusCode::kInvalidArgument, {"'q'", "I8", "F32"}));
}

TEST(Actb, OpenMissingOrDirectory) {
  const std::string dir = test::scratch_dir();
  EXPECT_TRUE(throws_error([&] { ActbFile::open(dir + "/missing.actb"); }, StatusCode::kNotFound,
                           {dir + "/missing.actb"}));
  // A folder says what it is (a LeRobot checkpoint folder would also say to convert it first).
  EXPECT_TRUE(throws_error([&] { ActbFile::open(dir); }, StatusCode::kInvalidArgument, {dir, "is a folder, not an .actb blob"}));
}

// ------------------------------------------------------------------------- config against tensors

// A small int8 model config as a blob states it (the tensors of the tests below are not its network).
nlohmann::json small_int8_config() {
  ModelConfig c;
  c.backbone_blocks = {2, 2, 2, 2};
  c.cameras = {{"observation.images.front", 64, 64}};
  c.state_dim = 2;
  c.action_dim = 2;
  c.dim_model = 16;
  c.n_heads = 2;
  c.dim_feedforward = 32;
  c.chunk_size = c.n_action_steps = 4;
  c.input_norm = {{"observation.state", NormMode::kMeanStd}, {"observation.images.front", NormMode::kIdentity}};
  c.precision = Precision::kInt8;
  nlohmann::json j = c.to_json();
  j["quantization"] = QuantConfig{}.to_json();
  return j;
}

// The attention precision: written and read back, absent in older blobs (float), anything else
// refused by name.
TEST(QuantConfigJson, AttentionPrecisionRoundTripsAndDefaultsToFloat) {
  QuantConfig q;
  q.int8_attention = true;
  EXPECT_TRUE(QuantConfig::from_json(q.to_json()).int8_attention);
  q.int8_attention = false;
  EXPECT_FALSE(QuantConfig::from_json(q.to_json()).int8_attention);
  nlohmann::json older = QuantConfig{}.to_json();
  older.erase("attention");
  EXPECT_FALSE(QuantConfig::from_json(older).int8_attention);
  nlohmann::json bad = QuantConfig{}.to_json();
  bad["attention"] = "int4";
  EXPECT_TRUE(throws_error([&] { QuantConfig::from_json(bad); }, StatusCode::kDataLoss, {"attention", "\"int4\""}));
}

TEST(ActbSemantics, ConfigAndTensorsMustAgree) {
  const std::string dir = test::scratch_dir();
  const std::vector<int8_t> q = {1, -2, 3, -4, 5, -6};
  const auto blob = [&](const std::string& name, nlohmann::json config, std::vector<int32_t> zero_points) {
    ActbWriter w;
    w.set_config(std::move(config));
    w.add_tensor("w", DType::kI8, {2, 3}, q.data(), q.size(), {{0.5f, 0.25f}, std::move(zero_points), 0});
    w.write(dir + "/" + name);
    return ActbFile::open(dir + "/" + name);
  };
  EXPECT_EQ(blob_model_config(blob("ok.actb", small_int8_config(), {0, 0})).precision, Precision::kInt8);
  EXPECT_TRUE(throws_error([&] { blob_model_config(blob("zp.actb", small_int8_config(), {0, 7})); },
                           StatusCode::kDataLoss, {dir + "/zp.actb", "\"w\"", "zero point 7", "symmetric"}));
  nlohmann::json fp32 = small_int8_config();
  fp32["precision"] = "fp32";
  EXPECT_TRUE(throws_error([&] { blob_model_config(blob("fp32.actb", fp32, {0, 0})); }, StatusCode::kDataLoss,
                           {dir + "/fp32.actb", "\"w\"", "precision is not int8"}));
  nlohmann::json null_norm = small_int8_config();
  null_norm["input_norm"] = nullptr;
  EXPECT_TRUE(throws_error([&] { blob_model_config(blob("null.actb", null_norm, {0, 0})); }, StatusCode::kDataLoss,
                           {dir + "/null.actb", "input_norm"}));
  nlohmann::json backbone = small_int8_config();
  backbone["backbone"] = "vgg16";
  EXPECT_TRUE(throws_error([&] { blob_model_config(blob("vgg.actb", backbone, {0, 0})); }, StatusCode::kDataLoss,
                           {dir + "/vgg.actb", "\"vgg16\"", "resnet18, resnet34, resnet50, resnet101, resnet152"}));
}

// The stored numbers are checked before the config is parsed, so fuzz_actb's inputs reach the checks
// with any config, and a blob with both problems names the number.
TEST(ActbSemantics, StoredNumbersAreCheckedWhateverTheConfig) {
  const std::string dir = test::scratch_dir();
  const auto blob = [&](const std::string& name, const std::function<void(ActbWriter&)>& add) {
    ActbWriter w;
    w.set_config(nlohmann::json::object());  // no model config at all
    add(w);
    w.write(dir + "/" + name);
    return ActbFile::open(dir + "/" + name);
  };
  const ActbFile huge = blob("huge.actb", [](ActbWriter& w) { w.add_f32("proj.state.weight", {2}, {0.5f, -1e30f}); });
  EXPECT_TRUE(throws_error([&] { blob_model_config(huge); }, StatusCode::kDataLoss,
                           {dir + "/huge.actb", "\"proj.state.weight\"", "-1e+30 at index 1"}));
  const std::vector<int8_t> q = {1, -2, 3, -4, 5, -6};
  const ActbFile scaled = blob("scale.actb", [&](ActbWriter& w) {
    w.add_tensor("w", DType::kI8, {2, 3}, q.data(), q.size(), {{0.5f, 1.8e19f}, {0, 0}, 0});
  });
  EXPECT_TRUE(throws_error([&] { blob_model_config(scaled); }, StatusCode::kDataLoss,
                           {dir + "/scale.actb", "\"w\"", "int8 scale 1.8e+19 for channel 1"}));
  // Statistics may be large (a state in microseconds), never infinite.
  const ActbFile stats = blob("stats.actb", [](ActbWriter& w) { w.add_f32("norm.observation.state.sub", {1}, {3e9f}); });
  EXPECT_TRUE(throws_error([&] { blob_model_config(stats); }, StatusCode::kDataLoss, {"malformed model config"}));
}

TEST(ActbSemantics, TensorsNobodyReadAreNamed) {
  const std::string path = test::scratch_dir() + "/reads.actb";
  small_writer().write(path);
  ActbFile f = ActbFile::open(path);
  BlobTensors tensors(f);
  for (const ActbTensor& t : f.tensors()) {
    if (t.name != "q") tensors.find(t.name);
  }
  EXPECT_TRUE(throws_error([&] { tensors.check_all_read(); }, StatusCode::kDataLoss, {path, "\"q\"", "does not use"}));
  tensors.find("q");
  EXPECT_NO_THROW(tensors.check_all_read());
  EXPECT_TRUE(throws_error([&] { tensors.f32("q", f.get("q").shape); }, StatusCode::kDataLoss, {path, "\"q\"", "I8"}));
  EXPECT_TRUE(throws_error([&] { tensors.get("q", {99}); }, StatusCode::kDataLoss, {path, "\"q\"", "[99]"}));
}

TEST(ActbSemantics, ReleasedTensorsAreNotReadAgain) {
  const std::string path = test::scratch_dir() + "/retire.actb";
  small_writer().write(path);
  ActbFile f = ActbFile::open(path);
  BlobTensors tensors(f);
  tensors.release("a");
  EXPECT_TRUE(throws_error([&] { tensors.f32("a", {2, 3}); }, StatusCode::kInternal, {path, "\"a\"", "released"}));
  EXPECT_TRUE(throws_error([&] { tensors.release("q"); }, StatusCode::kInternal, {path, "\"q\"", "no float tensor"}));
  EXPECT_EQ(tensors.f32("b", {3})[2], 9.0f);  // the others stay readable
}

// ---------------------------------------------------------------------------------------------- writer

TEST(ActbWrite, RejectsBadTensors) {
  ActbWriter w;
  w.add_f32("a", {2}, {1, 2});
  const std::vector<int8_t> q(6, 1);
  EXPECT_TRUE(throws_error([&] { w.add_f32("a", {1}, {3}); }, StatusCode::kInvalidArgument, {"'a'", "duplicate"}));
  EXPECT_TRUE(throws_error([&] { w.add_f32("b", {3}, {1, 2}); }, StatusCode::kInvalidArgument,
                           {"'b'", "[3]", "8 bytes"}));
  EXPECT_TRUE(throws_error([&] { w.add_tensor("c", DType::kF16, {3}, q.data(), 5); }, StatusCode::kInvalidArgument,
                           {"'c'", "F16"}));
  EXPECT_TRUE(throws_error([&] { w.add_f32("d", {-2}, {}); }, StatusCode::kInvalidArgument,
                           {"'d'", "negative dimension"}));
  EXPECT_TRUE(throws_error([&] { w.add_tensor("e", DType::kI8, {4}, nullptr, 4); }, StatusCode::kInvalidArgument,
                           {"'e'", "null"}));
  EXPECT_TRUE(throws_error([&] { w.add_f32("", {1}, {1}); }, StatusCode::kInvalidArgument, {"empty name"}));
}

TEST(ActbWrite, RejectsBadQuantParams) {
  ActbWriter w;
  const std::vector<int8_t> q(6, 1);
  auto add = [&](QuantParams p) { return [&w, &q, p] { w.add_tensor("q", DType::kI8, {2, 3}, q.data(), 6, p); }; };
  EXPECT_TRUE(throws_error(add({{0.1f, 0.2f}, {0}, 0}), StatusCode::kInvalidArgument,
                           {"'q'", "2 scales but 1 zero_points"}));
  EXPECT_TRUE(throws_error(add({{}, {0}, 0}), StatusCode::kInvalidArgument, {"zero_points but no scales"}));
  EXPECT_TRUE(throws_error(add({{0.0f}, {0}, 0}), StatusCode::kInvalidArgument, {"positive finite"}));
  EXPECT_TRUE(throws_error(add({{-1.0f}, {0}, 0}), StatusCode::kInvalidArgument, {"positive finite"}));
  EXPECT_TRUE(throws_error(add({{std::numeric_limits<float>::quiet_NaN()}, {0}, 0}), StatusCode::kInvalidArgument,
                           {"positive finite"}));
  EXPECT_TRUE(throws_error(add({{std::numeric_limits<float>::infinity()}, {0}, 0}), StatusCode::kInvalidArgument,
                           {"positive finite"}));
  EXPECT_TRUE(throws_error(add({{1, 1, 1}, {0, 0, 0}, 2}), StatusCode::kInvalidArgument,
                           {"axis 2 is out of range", "[2, 3]"}));
  EXPECT_TRUE(throws_error(add({{1, 1, 1}, {0, 0, 0}, -1}), StatusCode::kInvalidArgument, {"axis -1"}));
  EXPECT_TRUE(throws_error(add({{1, 1, 1}, {0, 0, 0}, 0}), StatusCode::kInvalidArgument,
                           {"3 scales", "2 channels on axis 0"}));
  // Valid: per-channel along axis 1, and per-tensor (axis ignored).
  w.add_tensor("ok1", DType::kI8, {2, 3}, q.data(), 6, {{1, 2, 3}, {0, 0, 0}, 1});
  w.add_tensor("ok2", DType::kI8, {2, 3}, q.data(), 6, {{1}, {0}, 7});
}

TEST(ActbWrite, RejectsInvalidUtf8) {
  const std::string dir = test::scratch_dir();
  ActbWriter w;
  w.add_f32("bad\xfe", {1}, {1});
  EXPECT_TRUE(throws_error([&] { w.write(dir + "/x.actb"); }, StatusCode::kInvalidArgument, {"JSON"}));
  ActbWriter p;
  p.set_producer("\xc3");
  EXPECT_TRUE(throws_error([&] { p.write(dir + "/x.actb"); }, StatusCode::kInvalidArgument, {"JSON"}));
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(ActbWrite, RejectsNonObjectConfig) {
  const std::string dir = test::scratch_dir();
  ActbWriter w;
  w.set_config(nlohmann::json::array({1, 2}));
  EXPECT_TRUE(throws_error([&] { w.write(dir + "/x.actb"); }, StatusCode::kInvalidArgument,
                           {"config must be a JSON object", "array"}));
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(ActbWrite, ReplacesExistingFileAndLeavesNoTemp) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/m.actb";
  small_writer().write(path);
  ActbWriter w;
  w.add_f32("only", {1}, {42});
  w.write(path);
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"m.actb"});
  const ActbFile f = ActbFile::open(path);
  ASSERT_EQ(f.tensors().size(), 1u);
  EXPECT_EQ(*f.get("only").f32(), 42.0f);
}

// add_f32 copies the values when called; add_f32_ref reads them when the blob is written. Both write
// the same bytes, side by side with int8 tensors of their own.
TEST(ActbWrite, ReferencedTensorsAreWrittenAsCopiedOnesAre) {
  const std::string dir = test::scratch_dir();
  std::vector<float> a(1000), b(77);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> dist(-2.0f, 2.0f);
  for (float& v : a) v = dist(rng);
  for (float& v : b) v = dist(rng);
  const std::vector<int8_t> codes = {1, -2, 3, -4, 5, -6};
  const auto build = [&](bool refer, const std::vector<float>& first, const std::vector<float>& second) {
    ActbWriter w;
    w.set_config({{"k", 1}});
    if (refer) {
      w.add_f32_ref("a", {10, 100}, first);
    } else {
      w.add_f32("a", {10, 100}, first);
    }
    w.add_tensor("q", DType::kI8, {2, 3}, codes.data(), codes.size(), {{0.5f, 0.25f}, {0, 0}, 0});
    if (refer) {
      w.add_f32_ref("b", {77}, second);
    } else {
      w.add_f32("b", {77}, second);
    }
    return w;
  };
  build(false, a, b).write(dir + "/copied.actb");
  const ActbWriter referring = build(true, a, b);
  referring.write(dir + "/referenced.actb");
  EXPECT_EQ(test::read_file(dir + "/copied.actb"), test::read_file(dir + "/referenced.actb"));
  // A copy of a writer holds copies of its own: it writes the same blob once the original is gone.
  std::optional<ActbWriter> original(build(false, a, b));
  const ActbWriter duplicate = *original;
  original.reset();
  duplicate.write(dir + "/duplicate.actb");
  EXPECT_EQ(test::read_file(dir + "/duplicate.actb"), test::read_file(dir + "/copied.actb"));

  // A reference is read at each write; a copy keeps the values of its call.
  std::vector<float> changing = a;
  ActbWriter copied = build(false, changing, b);
  const ActbWriter referenced = build(true, changing, b);
  changing[5] = 123.0f;
  copied.write(dir + "/copied.actb");
  referenced.write(dir + "/referenced.actb");
  EXPECT_EQ(ActbFile::open(dir + "/copied.actb").get("a").f32()[5], a[5]);
  EXPECT_EQ(ActbFile::open(dir + "/referenced.actb").get("a").f32()[5], 123.0f);
  const ActbFile f = ActbFile::open(dir + "/referenced.actb");
  EXPECT_EQ(std::memcmp(f.get("b").f32(), b.data(), b.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(f.get("q").data, codes.data(), codes.size()), 0);
}

// A blob written with its checksum left for later fails verification until it is sealed, and is then
// byte for byte the blob written with its checksum at once.
TEST(ActbWrite, ChecksumLeftForLaterIsSealedBeforeCommit) {
  const std::string dir = test::scratch_dir();
  const ActbWriter w = small_writer();
  w.write(dir + "/now.actb");
  {
    detail::AtomicFileWriter file(dir + "/later.actb");
    w.write_to(file, ActbWriter::Checksum::kLater);
    EXPECT_TRUE(throws_error([&] { ActbFile::open(file.readable_path()); }, StatusCode::kDataLoss, {"checksum mismatch"}));
    EXPECT_NO_THROW(ActbFile::open(file.readable_path(), /*verify_checksum=*/false));
    seal_actb_checksum(file);
    file.commit();
  }
  EXPECT_EQ(test::read_file(dir + "/later.actb"), test::read_file(dir + "/now.actb"));
  EXPECT_NO_THROW(ActbFile::open(dir + "/later.actb"));

  // Nothing written: nothing to seal, and no file appears.
  {
    detail::AtomicFileWriter empty(dir + "/empty.actb");
    EXPECT_TRUE(throws_error([&] { seal_actb_checksum(empty); }, StatusCode::kInvalidArgument, {"no .actb blob"}));
  }
  EXPECT_FALSE(fs::exists(dir + "/empty.actb"));
}

TEST(ActbWrite, MissingFolderFailsCleanly) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/no/such/dir/m.actb";
  EXPECT_TRUE(throws_error([&] { small_writer().write(path); }, StatusCode::kIoError,
                           {path, "No such file or directory"}));
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(ActbWrite, ReadOnlyFolderFailsCleanly) {
  if (::geteuid() == 0) GTEST_SKIP() << "root ignores directory permissions";
  const std::string dir = test::scratch_dir() + "/ro";
  fs::create_directories(dir);
  ASSERT_EQ(::chmod(dir.c_str(), 0555), 0);
  const std::string path = dir + "/m.actb";
  EXPECT_TRUE(throws_error([&] { small_writer().write(path); }, StatusCode::kIoError, {path, "Permission denied"}));
  ::chmod(dir.c_str(), 0755);
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(ActbWrite, FailedRenameRemovesTempFile) {
  // The temp file is fully written; the final rename onto a non-empty folder fails; the temp must go.
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/m.actb";
  fs::create_directories(path + "/keep");
  EXPECT_TRUE(throws_error([&] { small_writer().write(path); }, StatusCode::kIoError, {path, "rename"}));
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"m.actb"});
  EXPECT_TRUE(fs::is_directory(path + "/keep"));
}

TEST(ActbWrite, WriteErrorMidwayRemovesTempFile) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/big.actb";
  ActbWriter w;
  w.add_f32("big", {50000}, std::vector<float>(50000, 1.0f));
  {
    test::FileSizeLimit limit(4096);  // the 200 KB write fails part way with EFBIG
    EXPECT_TRUE(throws_error([&] { w.write(path); }, StatusCode::kIoError, {path, "File too large"}));
  }
  EXPECT_TRUE(list_dir(dir).empty());
  w.write(path);  // and works again once the limit is gone
  EXPECT_EQ(ActbFile::open(path).get("big").f32()[49999], 1.0f);
}

TEST(ActbWrite, StaleTempFileIsOverwritten) {
  // A temp file left by a crashed run with the same pid must not block or corrupt the next write.
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/m.actb";
  test::write_file(path + ".tmp." + std::to_string(::getpid()), std::vector<uint8_t>(100000, 0xEE));
  small_writer().write(path);
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"m.actb"});
  EXPECT_EQ(ActbFile::open(path).get("b").f32()[2], 9.0f);
}

// ---------------------------------------------------------------------------------------------- bad files

TEST_F(ActbBad, BadMagic) {
  std::vector<uint8_t> b = good_;
  b[6] = 'X';
  EXPECT_TRUE(corrupt(b, {"not an .actb file (bad magic)"}));
  b = good_;
  b[7] = 1;  // the terminating NUL is part of the magic
  EXPECT_TRUE(corrupt(b, {"not an .actb file (bad magic)"}));
  EXPECT_TRUE(corrupt(test::bytes_of("this is a text file, certainly not a blob of weights at all.........."),
                      {"not an .actb file (bad magic)"}));
}

TEST_F(ActbBad, SafetensorsFileIsNotAnActb) {
  const std::vector<float> v = {1, 2};
  write_safetensors(path_, {{"a", DType::kF32, {2}, v.data(), 8}});
  EXPECT_TRUE(throws_error([&] { ActbFile::open(path_); }, StatusCode::kInvalidArgument,
                           {path_, "is a safetensors file, not an .actb blob"}));
}

TEST_F(ActbBad, WrongVersion) {
  for (uint32_t version : {0u, 2u, 7u, 0xFFFFFFFFu}) {
    std::vector<uint8_t> b = good_;
    put_le(b, 8, version, 4);
    EXPECT_TRUE(rejects(b, StatusCode::kUnimplemented,
                        {"format version " + std::to_string(version) + ", this build reads 1"}))
        << version;
  }
}

TEST_F(ActbBad, EmptyAndTinyFiles) {
  EXPECT_TRUE(corrupt({}, {"file has 0 bytes", "too short"}));
  EXPECT_TRUE(corrupt({'A', 'C', 'T'}, {"file has 3 bytes", "too short"}));
}

TEST_F(ActbBad, TruncatedAtSeveralPoints) {
  const size_t size = good_.size();
  const std::vector<size_t> cuts = {
      0,   5,   8, 12, 16, 40, 63,  // inside the fixed header
      64,  65,  static_cast<size_t>(64 + header_size_ / 2), static_cast<size_t>(64 + header_size_ - 1),  // JSON
      static_cast<size_t>(data_offset_ - 1), static_cast<size_t>(data_offset_),                    // padding
      static_cast<size_t>(data_offset_ + 10), size - 1};                                            // data
  for (size_t n : cuts) {
    SCOPED_TRACE("cut at " + std::to_string(n));
    const std::vector<uint8_t> b(good_.begin(), good_.begin() + static_cast<long>(n));
    if (n < 8) {
      EXPECT_TRUE(corrupt(b, {"file has " + std::to_string(n) + " bytes", "too short"}));
    } else if (n < 64) {
      EXPECT_TRUE(corrupt(b, {"truncated: file has " + std::to_string(n) + " bytes", "fixed header needs 64"}));
    } else {
      EXPECT_TRUE(corrupt(b, {"truncated: file has " + std::to_string(n) + " bytes, header says " +
                              std::to_string(size)}));
    }
  }
}

TEST_F(ActbBad, EveryTruncationIsRejected) {
  for (size_t n = 0; n < good_.size(); ++n) {
    const std::vector<uint8_t> b(good_.begin(), good_.begin() + static_cast<long>(n));
    EXPECT_TRUE(corrupt(b, {}, /*verify=*/false)) << "cut at " << n;
  }
}

TEST_F(ActbBad, TrailingBytes) {
  std::vector<uint8_t> b = good_;
  b.push_back(0);
  EXPECT_TRUE(corrupt(b, {"file has " + std::to_string(good_.size() + 1) + " bytes, header says " +
                          std::to_string(good_.size()),
                          "trailing"}));
}

TEST_F(ActbBad, FlippedDataByteFailsChecksum) {
  std::vector<uint8_t> b = good_;
  b[data_offset_ + 4] ^= 0x01;  // inside tensor "a"
  EXPECT_TRUE(corrupt(b, {"checksum mismatch"}));
  // Without verification the (corrupt) file opens and the flip is visible.
  test::write_file(path_, b);
  const ActbFile f = ActbFile::open(path_, /*verify_checksum=*/false);
  EXPECT_NE(f.get("a").f32()[1], 2.0f);
}

TEST_F(ActbBad, FlippedPaddingByteFailsChecksum) {
  std::vector<uint8_t> b = good_;
  b[data_offset_ + 30] ^= 0x80;  // padding between tensors "a" (24 bytes) and "q" (at 64)
  EXPECT_TRUE(corrupt(b, {"checksum mismatch"}));
}

TEST_F(ActbBad, FlippedHeaderByteFailsChecksum) {
  std::vector<uint8_t> b = good_;
  b[64] ^= 0x20;  // the opening '{' of the JSON
  EXPECT_TRUE(corrupt(b, {"checksum mismatch"}));
  EXPECT_TRUE(corrupt(b, {"malformed JSON"}, /*verify=*/false));
}

TEST_F(ActbBad, EverySingleByteFlipAfterFixedHeaderFailsChecksum) {
  // CRC-32 detects every single-byte error; check that the whole covered range really is covered.
  for (size_t pos = 64; pos < good_.size(); ++pos) {
    std::vector<uint8_t> b = good_;
    b[pos] ^= 0xFF;
    EXPECT_TRUE(corrupt(b, {"checksum mismatch"})) << "byte " << pos;
  }
}

TEST_F(ActbBad, FlippedChecksumField) {
  std::vector<uint8_t> b = good_;
  b[40] ^= 0x01;
  EXPECT_TRUE(corrupt(b, {"checksum mismatch"}));
  test::write_file(path_, b);
  EXPECT_NO_THROW(ActbFile::open(path_, /*verify_checksum=*/false));
  b = good_;
  b[44] = 1;  // a CRC-32 is zero-extended to 64 bits
  EXPECT_TRUE(corrupt(b, {"zero-extended CRC-32"}));
}

TEST_F(ActbBad, ReservedBytesMustBeZero) {
  for (size_t pos : {12, 15, 48, 63}) {
    std::vector<uint8_t> b = good_;
    b[pos] = 1;
    EXPECT_TRUE(corrupt(b, {"reserved"})) << pos;
  }
}

TEST_F(ActbBad, InconsistentSizeFields) {
  std::vector<uint8_t> b = good_;
  put_le(b, 32, get_le(b, 32, 8) + 64, 8);  // data_size too large
  EXPECT_TRUE(corrupt(b, {"truncated", "header says " + std::to_string(good_.size() + 64)}));
  b = good_;
  put_le(b, 32, std::numeric_limits<uint64_t>::max(), 8);
  EXPECT_TRUE(corrupt(b, {"overflows"}));
  b = good_;
  put_le(b, 16, data_offset_, 8);  // the JSON would run into the data
  EXPECT_TRUE(corrupt(b, {"overruns data_offset"}));
  b = good_;
  put_le(b, 16, uint64_t{1} << 62, 8);
  EXPECT_TRUE(corrupt(b, {"header_size 4611686018427387904", "limit"}));
  b = good_;
  put_le(b, 16, header_size_ - 1, 8);  // header cut one byte short: the JSON no longer parses
  EXPECT_TRUE(corrupt(b, {"malformed JSON"}));
}

TEST_F(ActbBad, MisalignedDataOffset) {
  const std::string json = header_with(entry("a", "U8", "[4]", 0, 4));
  EXPECT_TRUE(corrupt(raw_actb(json, {1, 2, 3, 4}, 64 + json.size() + 1),
                      {"data_offset " + std::to_string(64 + json.size() + 1) + " is not 64-byte aligned"}));
  // Aligned but below the end of the JSON header.
  EXPECT_TRUE(corrupt(raw_actb(json, {1, 2, 3, 4}, 64), {"overruns data_offset 64"}));
}

TEST_F(ActbBad, MisalignedTensorOffsets) {
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[2]", 8, 8), 64, {"tensor 'a'", "offset 8 is not 64-byte aligned"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[1]", 0, 1) + "," + entry("b", "U8", "[1]", 1, 1), 64,
                              {"tensor 'b'", "offset 1 is not 64-byte aligned"}));
}

TEST_F(ActbBad, InvalidJson) {
  for (const std::string json : {"{", "not json", R"({"producer":"x",})", R"({"a":1} {"b":2})"}) {
    EXPECT_TRUE(corrupt(raw_actb(json, {}), {"malformed JSON"})) << json;
  }
  EXPECT_TRUE(corrupt(raw_actb(std::string(R"({"producer":"x","config":{},"tensors":[]})") + '\0' + "junk", {}),
                      {"NUL byte"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":"x","producer":"y","config":{},"tensors":[]})", {}),
                      {"duplicate key 'producer'"}));
}

TEST_F(ActbBad, HeaderStructure) {
  EXPECT_TRUE(corrupt(raw_actb("[]", {}), {"must be an object", "array"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"config":{},"tensors":[]})", {}), {"'producer' string"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":1,"config":{},"tensors":[]})", {}), {"'producer' string"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":"x","tensors":[]})", {}), {"'config' object"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":"x","config":[],"tensors":[]})", {}), {"'config' object"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":"x","config":{}})", {}), {"'tensors' array"}));
  EXPECT_TRUE(corrupt(raw_actb(R"({"producer":"x","config":{},"tensors":{}})", {}), {"'tensors' array"}));
}

TEST_F(ActbBad, TensorEntryFields) {
  EXPECT_TRUE(rejects_entries("5", 0, {"tensors[0]: must be an object", "number"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[1]", 0, 1) + R"(,{"dtype":"U8"})", 64,
                              {"tensors[1]: needs a non-empty 'name' string"}));
  EXPECT_TRUE(rejects_entries(R"({"name":5,"dtype":"U8","shape":[0],"offset":0,"nbytes":0})", 0, {"'name'"}));
  EXPECT_TRUE(rejects_entries(entry("", "U8", "[0]", 0, 0), 0, {"non-empty 'name'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","shape":[0],"offset":0,"nbytes":0})", 0, {"tensor 'a'", "'dtype'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","offset":0,"nbytes":0})", 0,
                              {"tensor 'a'", "missing 'shape'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","shape":[0],"nbytes":0})", 0, {"tensor 'a'", "'offset'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","shape":[0],"offset":0})", 0, {"tensor 'a'", "'nbytes'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","shape":[1],"offset":-64,"nbytes":1})", 64,
                              {"non-negative integer 'offset'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","shape":[1],"offset":"0","nbytes":1})", 64,
                              {"non-negative integer 'offset'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":"U8","shape":[1],"offset":0,"nbytes":1.0})", 64,
                              {"non-negative integer 'nbytes'"}));
}

TEST_F(ActbBad, UnknownDtype) {
  EXPECT_TRUE(rejects_entries(entry("a", "Q4_0", "[2]", 0, 1), 64, {"tensor 'a'", "unknown dtype 'Q4_0'"}));
  EXPECT_TRUE(rejects_entries(R"({"name":"a","dtype":4,"shape":[1],"offset":0,"nbytes":1})", 64,
                              {"tensor 'a'", "'dtype' must be a string", "number"}));
}

TEST_F(ActbBad, BadShapes) {
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[-2]", 0, 0), 64, {"tensor 'a'", "negative dimension -2"}));
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "2", 0, 8), 64, {"tensor 'a'", "shape must be an array"}));
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[2.5]", 0, 8), 64, {"tensor 'a'", "non-integer"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[4294967296,4294967296]", 0, 0), 64, {"tensor 'a'", "overflows"}));
}

TEST_F(ActbBad, NbytesMismatch) {
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[4]", 0, 12), 64,
                              {"tensor 'a'", "nbytes 12 does not match shape [4] with dtype F32"}));
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[]", 0, 0), 64, {"nbytes 0 does not match shape []"}));
  // The element count fits in 64 bits, the byte count does not.
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[4611686018427387904]", 0, 0), 64, {"tensor 'a'", "too large"}));
}

TEST_F(ActbBad, OffsetsOutOfBounds) {
  EXPECT_TRUE(rejects_entries(entry("a", "F32", "[4]", 64, 16), 64,
                              {"tensor 'a'", "out of bounds of the data area of 64 bytes"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[65]", 0, 65), 64, {"out of bounds"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[64]", 18446744073709551552ull, 64), 64, {"out of bounds"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[0]", 128, 0), 64, {"out of bounds"}));
}

TEST_F(ActbBad, OverlappingTensors) {
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[128]", 0, 128) + "," + entry("b", "U8", "[64]", 64, 64), 128,
                              {"tensors 'a' and 'b' overlap"}));
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[8]", 64, 8) + "," + entry("b", "U8", "[8]", 64, 8), 128,
                              {"overlap"}));
  // Listed out of order, with a third tensor in between.
  EXPECT_TRUE(rejects_entries(entry("c", "U8", "[1]", 128, 1) + "," + entry("a", "U8", "[256]", 0, 256) + "," +
                                  entry("b", "U8", "[1]", 192, 1),
                              256, {"tensors 'a' and", "overlap"}));
}

TEST_F(ActbBad, EmptyTensorsMayShareOffsets) {
  const std::string json = header_with(entry("a", "U8", "[64]", 0, 64) + "," + entry("e", "F32", "[0]", 0, 0) +
                                       "," + entry("z", "I8", "[0, 9]", 64, 0));
  test::write_file(path_, raw_actb(json, std::vector<uint8_t>(64)));
  const ActbFile f = ActbFile::open(path_);
  EXPECT_EQ(f.tensors().size(), 3u);
}

TEST_F(ActbBad, DuplicateNames) {
  EXPECT_TRUE(rejects_entries(entry("a", "U8", "[1]", 0, 1) + "," + entry("a", "U8", "[1]", 64, 1), 128,
                              {"tensor 'a'", "duplicate tensor name"}));
}

TEST_F(ActbBad, BadQuantParams) {
  auto with_quant = [](const std::string& quant) {
    return entry("q", "I8", "[2, 3]", 0, 6, R"(,"quant":)" + quant);
  };
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"[1]", "'quant' must be an object"},
      {R"({"zero_points":[0],"axis":0})", "'scales' array"},
      {R"({"scales":[1],"axis":0})", "'zero_points' array"},
      {R"({"scales":[1],"zero_points":[0]})", "'axis'"},
      {R"({"scales":["1"],"zero_points":[0],"axis":0})", "scales must be numbers"},
      {R"({"scales":[1e300],"zero_points":[0],"axis":0})", "out of float range"},
      {R"({"scales":[0],"zero_points":[0],"axis":0})", "positive finite"},
      {R"({"scales":[-0.5],"zero_points":[0],"axis":0})", "positive finite"},
      {R"({"scales":[1],"zero_points":[1099511627776],"axis":0})", "32-bit"},
      {R"({"scales":[1],"zero_points":[0.5],"axis":0})", "32-bit"},
      {R"({"scales":[1],"zero_points":[0],"axis":"0"})", "32-bit"},
      {R"({"scales":[1,2],"zero_points":[0],"axis":0})", "2 scales but 1 zero_points"},
      {R"({"scales":[],"zero_points":[0],"axis":0})", "zero_points but no scales"},
      {R"({"scales":[1,2,3],"zero_points":[0,0,0],"axis":5})", "axis 5 is out of range"},
      {R"({"scales":[1,2,3],"zero_points":[0,0,0],"axis":0})", "2 channels on axis 0"},
  };
  for (const auto& [quant, needle] : cases) {
    EXPECT_TRUE(rejects_entries(with_quant(quant), 64, {"tensor 'q'", needle})) << quant;
  }
}

TEST_F(ActbBad, DeeplyNestedJsonIsRejected) {
  auto with_config_depth = [](size_t depth) {
    return R"({"producer":"x","config":{"deep":)" + std::string(depth, '[') + std::string(depth, ']') +
           R"(},"tensors":[]})";
  };
  EXPECT_TRUE(corrupt(raw_actb(with_config_depth(200000), {}), {"nested deeper than 256 levels"}));
  EXPECT_TRUE(corrupt(raw_actb(std::string(200000, '['), {}), {"malformed JSON"}));
  // Moderate nesting in the config is fine.
  test::write_file(path_, raw_actb(with_config_depth(50), {}));
  const ActbFile f = ActbFile::open(path_);
  EXPECT_TRUE(f.config()["deep"].is_array());
}

TEST_F(ActbBad, RandomCorruptionNeverCrashes) {
  std::mt19937 rng(4242);
  int opened = 0;
  int rejected = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    std::vector<uint8_t> b = good_;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int k = 0; k < flips; ++k) {
      // Mostly hit the fixed header and the JSON, where the parsing logic lives.
      const size_t limit = iter % 3 == 0 ? b.size() : static_cast<size_t>(64 + header_size_);
      b[rng() % limit] = static_cast<uint8_t>(rng());
    }
    if (iter % 5 == 0) b.resize(rng() % (b.size() + 1));
    test::write_file(path_, b);
    try {
      const ActbFile f = ActbFile::open(path_, /*verify_checksum=*/false);
      for (const ActbTensor& t : f.tensors()) {
        ASSERT_EQ(reinterpret_cast<uintptr_t>(t.data) % kActbAlignment, 0u);
        volatile uint8_t sink = 0;
        for (size_t i = 0; i < t.nbytes; ++i) sink = static_cast<uint8_t>(sink + t.data[i]);  // must be mapped
      }
      ++opened;
    } catch (const Error& e) {
      ASSERT_TRUE(e.code() == StatusCode::kDataLoss || e.code() == StatusCode::kUnimplemented) << e.what();
      ASSERT_NE(std::string(e.what()).find(path_), std::string::npos) << e.what();
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 0);
  EXPECT_EQ(opened + rejected, 3000);
}

}  // namespace
}  // namespace act
