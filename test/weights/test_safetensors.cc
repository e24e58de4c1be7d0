#include "weights/import/safetensors.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "actengine/status.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"

namespace act {
namespace {

namespace fs = std::filesystem;
using test::list_dir;
using test::throws_error;

// A safetensors file built by hand: 8-byte LE header length, the header text, then the data.
std::vector<uint8_t> raw_file(const std::string& header, const std::vector<uint8_t>& data,
                              std::optional<uint64_t> length_field = std::nullopt) {
  const uint64_t n = length_field.value_or(header.size());
  std::vector<uint8_t> out(8 + header.size() + data.size());
  for (int i = 0; i < 8; ++i) out[static_cast<size_t>(i)] = static_cast<uint8_t>(n >> (8 * i));
  std::copy(header.begin(), header.end(), out.begin() + 8);
  std::copy(data.begin(), data.end(), out.begin() + 8 + static_cast<long>(header.size()));
  return out;
}

template <typename T>
std::vector<uint8_t> as_bytes(const std::vector<T>& v) {
  std::vector<uint8_t> out(v.size() * sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), v.data(), out.size());
  return out;
}

template <typename T>
SafetensorsWriteTensor wt(const std::string& name, DType dtype, std::vector<int64_t> shape, const std::vector<T>& v) {
  return {name, dtype, std::move(shape), v.data(), v.size() * sizeof(T)};
}

class SafetensorsBad : public ::testing::Test {
 protected:
  void SetUp() override { path_ = test::scratch_dir() + "/bad.safetensors"; }

  // Writes `bytes` and expects open() to fail with kDataLoss naming the file and every needle.
  ::testing::AssertionResult rejects(const std::vector<uint8_t>& bytes, std::vector<std::string> needles) {
    test::write_file(path_, bytes);
    needles.push_back(path_);
    return throws_error([&] { SafetensorsFile::open(path_); }, StatusCode::kDataLoss, needles);
  }
  ::testing::AssertionResult rejects_header(const std::string& header, size_t data_size,
                                            std::vector<std::string> needles) {
    return rejects(raw_file(header, std::vector<uint8_t>(data_size, 0xAB)), std::move(needles));
  }

  std::string path_;
};

// ------------------------------------------------------------------------------------ round trips

TEST(Safetensors, RoundTripEveryDtype) {
  const std::string path = test::scratch_dir() + "/all.safetensors";
  const std::vector<float> f32 = {1.5f, -2.25f, 0.0f, 3.0e-8f, 1e30f, -7.0f};
  const std::vector<uint16_t> f16 = {0x3C00, 0xC000, 0x0001, 0x7BFF};   // 1, -2, 2^-24, 65504
  const std::vector<uint16_t> bf16 = {0x3F80, 0xC000, 0x4049, 0x0000};  // 1, -2, 3.140625, 0
  const std::vector<int8_t> i8 = {-128, -1, 0, 1, 127};
  const std::vector<uint8_t> u8 = {0, 128, 255};
  const std::vector<int32_t> i32 = {std::numeric_limits<int32_t>::min(), 42};
  const std::vector<double> f64 = {3.141592653589793};
  const std::vector<int64_t> i64 = {std::numeric_limits<int64_t>::max()};
  const std::vector<float> scalar = {2.5f};
  const std::vector<float> empty_f32;
  const std::vector<int8_t> empty_i8;
  write_safetensors(path, {
                              wt("w.f32", DType::kF32, {2, 3}, f32),
                              wt("w.f16", DType::kF16, {4}, f16),
                              wt("w.bf16", DType::kBF16, {2, 2}, bf16),
                              wt("w.i8", DType::kI8, {5}, i8),
                              wt("w.u8", DType::kU8, {3, 1}, u8),
                              wt("w.i32", DType::kI32, {2}, i32),
                              wt("w.f64", DType::kF64, {1}, f64),
                              wt("w.i64", DType::kI64, {1, 1}, i64),
                              wt("scalar", DType::kF32, {}, scalar),
                              wt("empty.f32", DType::kF32, {0, 3}, empty_f32),
                              wt("empty.i8", DType::kI8, {0}, empty_i8),
                          });
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_EQ(f.path(), path);
  EXPECT_EQ(f.names(), (std::vector<std::string>{"empty.f32", "empty.i8", "scalar", "w.bf16", "w.f16", "w.f32",
                                                 "w.f64", "w.i32", "w.i64", "w.i8", "w.u8"}));
  EXPECT_TRUE(f.metadata().empty());

  auto check = [&](const std::string& name, DType dtype, std::vector<int64_t> shape, const std::vector<uint8_t>& bytes) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(f.contains(name));
    const SafetensorsTensor& t = f.get(name);
    EXPECT_EQ(t.name, name);
    EXPECT_EQ(t.dtype, dtype);
    EXPECT_EQ(t.shape, shape);
    EXPECT_EQ(t.elements(), shape_elements(shape));
    ASSERT_EQ(t.nbytes, bytes.size());
    if (!bytes.empty()) {
      EXPECT_EQ(std::memcmp(t.data, bytes.data(), bytes.size()), 0);
    }
  };
  check("w.f32", DType::kF32, {2, 3}, as_bytes(f32));
  check("w.f16", DType::kF16, {4}, as_bytes(f16));
  check("w.bf16", DType::kBF16, {2, 2}, as_bytes(bf16));
  check("w.i8", DType::kI8, {5}, as_bytes(i8));
  check("w.u8", DType::kU8, {3, 1}, as_bytes(u8));
  check("w.i32", DType::kI32, {2}, as_bytes(i32));
  check("w.f64", DType::kF64, {1}, as_bytes(f64));
  check("w.i64", DType::kI64, {1, 1}, as_bytes(i64));
  check("scalar", DType::kF32, {}, as_bytes(scalar));
  check("empty.f32", DType::kF32, {0, 3}, {});
  check("empty.i8", DType::kI8, {0}, {});

  EXPECT_EQ(f.get("w.f32").to_f32(), f32);
  EXPECT_EQ(f.get("w.f16").to_f32(), (std::vector<float>{1.0f, -2.0f, 5.9604644775390625e-08f, 65504.0f}));
  EXPECT_EQ(f.get("w.bf16").to_f32(), (std::vector<float>{1.0f, -2.0f, 3.140625f, 0.0f}));
  EXPECT_EQ(f.get("scalar").to_f32(), std::vector<float>{2.5f});
  EXPECT_TRUE(f.get("empty.f32").to_f32().empty());
}

TEST(Safetensors, HeaderIsSpacePaddedToEightBytes) {
  const std::string dir = test::scratch_dir();
  // Vary the name length so the unpadded header length hits every residue mod 8.
  for (int len = 1; len <= 8; ++len) {
    const std::string path = dir + "/p" + std::to_string(len) + ".safetensors";
    const std::vector<uint8_t> v = {1, 2, 3};
    write_safetensors(path, {wt(std::string(static_cast<size_t>(len), 'x'), DType::kU8, {3}, v)});
    const std::vector<uint8_t> bytes = test::read_file(path);
    uint64_t n = 0;
    for (int i = 7; i >= 0; --i) n = (n << 8) | bytes[static_cast<size_t>(i)];
    EXPECT_EQ(n % 8, 0u) << len;
    EXPECT_EQ(bytes.size(), 8 + n + 3);
    EXPECT_EQ(bytes[8], '{');
    const std::string header(bytes.begin() + 8, bytes.begin() + 8 + static_cast<long>(n));
    EXPECT_EQ(header.find_last_not_of(' '), header.rfind('}'));
    EXPECT_EQ(SafetensorsFile::open(path).get(std::string(static_cast<size_t>(len), 'x')).data[2], 3);
  }
}

TEST(Safetensors, MetadataRoundTrip) {
  const std::string path = test::scratch_dir() + "/meta.safetensors";
  const std::vector<float> v = {1.0f};
  const std::map<std::string, std::string> meta = {{"format", "pt"}, {"note", "quotes \" and \\ and ünïcode"}, {"", ""}};
  write_safetensors(path, {wt("a", DType::kF32, {1}, v)}, meta);
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_EQ(f.metadata(), meta);
  EXPECT_EQ(f.names(), std::vector<std::string>{"a"});  // __metadata__ is not a tensor
  EXPECT_FALSE(f.contains("__metadata__"));
}

TEST(Safetensors, NoTensorsAtAll) {
  const std::string path = test::scratch_dir() + "/none.safetensors";
  write_safetensors(path, {}, {{"k", "v"}});
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_TRUE(f.names().empty());
  EXPECT_EQ(f.metadata().at("k"), "v");
}

TEST(Safetensors, ReadsHandBuiltFileWithUnalignedTensors) {
  const std::string path = test::scratch_dir() + "/hand.safetensors";
  // Keys out of data order, an odd offset for the F16 tensor, a gap and extra unknown fields.
  const std::string header =
      R"({"h":{"dtype":"F16","shape":[2],"data_offsets":[1,5]},)"
      R"("b":{"dtype":"U8","shape":[],"data_offsets":[0,1],"extra":true},)"
      R"("__metadata__":{"format":"pt"},)"
      R"("z":{"dtype":"I32","shape":[1],"data_offsets":[8,12]}})";
  test::write_file(path, raw_file(header, {7, 0x00, 0x3C, 0x00, 0xC0, 0xEE, 0xEE, 0xEE, 5, 0, 0, 0}));
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_EQ(f.names(), (std::vector<std::string>{"b", "h", "z"}));
  EXPECT_EQ(f.get("b").data[0], 7);
  EXPECT_EQ(f.get("b").shape, std::vector<int64_t>{});
  EXPECT_EQ(f.get("h").to_f32(), (std::vector<float>{1.0f, -2.0f}));
  int32_t z = 0;
  std::memcpy(&z, f.get("z").data, 4);
  EXPECT_EQ(z, 5);
  EXPECT_EQ(f.metadata().at("format"), "pt");
}

TEST(Safetensors, TensorsAreViewsIntoTheFile) {
  const std::string path = test::scratch_dir() + "/view.safetensors";
  const std::vector<float> a = {1, 2, 3, 4};
  const std::vector<float> b = {5, 6};
  write_safetensors(path, {wt("a", DType::kF32, {4}, a), wt("b", DType::kF32, {2}, b)});
  const SafetensorsFile f = SafetensorsFile::open(path);
  // Written in order, so b follows a directly in the same mapping.
  EXPECT_EQ(f.get("b").data, f.get("a").data + 16);
}

TEST(Safetensors, MovedFileKeepsTensorsValid) {
  const std::string path = test::scratch_dir() + "/move.safetensors";
  const std::vector<float> a = {1, 2, 3};
  write_safetensors(path, {wt("a", DType::kF32, {3}, a)});
  SafetensorsFile f = SafetensorsFile::open(path);
  const uint8_t* data = f.get("a").data;
  SafetensorsFile g = std::move(f);
  EXPECT_EQ(g.get("a").data, data);
  EXPECT_EQ(g.get("a").to_f32(), a);
  EXPECT_EQ(g.path(), path);
}

TEST(Safetensors, GetMissingTensorIsNotFound) {
  const std::string path = test::scratch_dir() + "/get.safetensors";
  const std::vector<float> a = {1};
  write_safetensors(path, {wt("a", DType::kF32, {1}, a)});
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_EQ(f.find("missing"), nullptr);
  EXPECT_NE(f.find("a"), nullptr);
  EXPECT_TRUE(throws_error([&] { f.get("missing"); }, StatusCode::kNotFound, {"'missing'", path}));
}

TEST(Safetensors, ToF32RejectsIntegerTensors) {
  const std::string path = test::scratch_dir() + "/i8.safetensors";
  const std::vector<int8_t> v = {1, 2};
  write_safetensors(path, {wt("q", DType::kI8, {2}, v)});
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_TRUE(throws_error([&] { f.get("q").to_f32(); }, StatusCode::kInvalidArgument, {"'q'", "I8"}));
}

TEST(Safetensors, ToF32RejectsInconsistentHandBuiltTensor) {
  SafetensorsTensor t;
  t.name = "t";
  t.shape = {4};
  const float v[2] = {1, 2};
  t.data = reinterpret_cast<const uint8_t*>(v);
  t.nbytes = sizeof v;
  EXPECT_TRUE(throws_error([&] { t.to_f32(); }, StatusCode::kInvalidArgument, {"'t'", "[4]"}));
}

TEST(Safetensors, OpenMissingFileIsNotFound) {
  const std::string path = test::scratch_dir() + "/missing.safetensors";
  EXPECT_TRUE(throws_error([&] { SafetensorsFile::open(path); }, StatusCode::kNotFound, {path}));
}

// ------------------------------------------------------------------------------------ writer

TEST(SafetensorsWrite, ReplacesExistingFileAndLeavesNoTemp) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/w.safetensors";
  const std::vector<float> a = {1, 2};
  const std::vector<float> b = {3, 4, 5};
  write_safetensors(path, {wt("a", DType::kF32, {2}, a)});
  write_safetensors(path, {wt("b", DType::kF32, {3}, b)});
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"w.safetensors"});
  const SafetensorsFile f = SafetensorsFile::open(path);
  EXPECT_EQ(f.names(), std::vector<std::string>{"b"});
  EXPECT_EQ(f.get("b").to_f32(), b);
}

TEST(SafetensorsWrite, MissingFolderFailsCleanly) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/no_such_dir/w.safetensors";
  const std::vector<float> a = {1};
  EXPECT_TRUE(throws_error([&] { write_safetensors(path, {wt("a", DType::kF32, {1}, a)}); }, StatusCode::kIoError,
                           {path, "No such file or directory"}));
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(SafetensorsWrite, ReadOnlyFolderFailsCleanly) {
  if (::geteuid() == 0) GTEST_SKIP() << "root ignores directory permissions";
  const std::string dir = test::scratch_dir() + "/ro";
  fs::create_directories(dir);
  ASSERT_EQ(::chmod(dir.c_str(), 0555), 0);
  const std::vector<float> a = {1};
  const std::string path = dir + "/w.safetensors";
  EXPECT_TRUE(throws_error([&] { write_safetensors(path, {wt("a", DType::kF32, {1}, a)}); }, StatusCode::kIoError,
                           {path, "Permission denied"}));
  ::chmod(dir.c_str(), 0755);
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(SafetensorsWrite, FailedRenameRemovesTempFile) {
  // The target is a non-empty folder: the temp file is written, the rename fails, the temp must go.
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/target";
  fs::create_directories(path + "/child");
  const std::vector<float> a = {1, 2, 3};
  EXPECT_TRUE(throws_error([&] { write_safetensors(path, {wt("a", DType::kF32, {3}, a)}); }, StatusCode::kIoError,
                           {path, "rename"}));
  EXPECT_EQ(list_dir(dir), std::vector<std::string>{"target"});
  EXPECT_TRUE(fs::is_directory(path + "/child"));
}

TEST(SafetensorsWrite, WriteErrorMidwayRemovesTempFile) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/big.safetensors";
  const std::vector<float> v(50000, 1.0f);
  {
    test::FileSizeLimit limit(4096);  // the 200 KB write fails part way with EFBIG
    EXPECT_TRUE(throws_error([&] { write_safetensors(path, {wt("big", DType::kF32, {50000}, v)}); },
                             StatusCode::kIoError, {path, "File too large"}));
  }
  EXPECT_TRUE(list_dir(dir).empty());
}

TEST(SafetensorsWrite, RejectsInconsistentTensorsWithoutWriting) {
  const std::string dir = test::scratch_dir();
  const std::string path = dir + "/w.safetensors";
  const std::vector<float> v = {1, 2, 3};
  auto write = [&](std::vector<SafetensorsWriteTensor> ts) { return [&path, ts] { write_safetensors(path, ts); }; };

  EXPECT_TRUE(throws_error(write({wt("a", DType::kF32, {2, 2}, v)}), StatusCode::kInvalidArgument,
                           {"'a'", "[2, 2]", "12 bytes"}));
  EXPECT_TRUE(throws_error(write({wt("a", DType::kF16, {3}, v)}), StatusCode::kInvalidArgument, {"'a'", "F16"}));
  EXPECT_TRUE(throws_error(write({wt("a", DType::kF32, {3}, v), wt("a", DType::kF32, {3}, v)}),
                           StatusCode::kInvalidArgument, {"'a'", "duplicate"}));
  EXPECT_TRUE(throws_error(write({wt("__metadata__", DType::kF32, {3}, v)}), StatusCode::kInvalidArgument,
                           {"reserved"}));
  EXPECT_TRUE(throws_error(write({wt("", DType::kF32, {3}, v)}), StatusCode::kInvalidArgument, {"empty name"}));
  EXPECT_TRUE(throws_error(write({wt("neg", DType::kF32, {-3}, v)}), StatusCode::kInvalidArgument,
                           {"'neg'", "negative dimension"}));
  EXPECT_TRUE(throws_error(write({{"null", DType::kF32, {3}, nullptr, 12}}), StatusCode::kInvalidArgument,
                           {"'null'", "null"}));
  EXPECT_TRUE(throws_error(write({wt("bad\xff", DType::kF32, {3}, v)}), StatusCode::kInvalidArgument,
                           {"JSON"}));
  EXPECT_TRUE(throws_error([&] { write_safetensors(path, {}, {{"k", "\xc3"}}); }, StatusCode::kInvalidArgument,
                           {"JSON"}));
  EXPECT_TRUE(list_dir(dir).empty());
}

// ------------------------------------------------------------------------------------ bad files

TEST_F(SafetensorsBad, EmptyFile) { EXPECT_TRUE(rejects({}, {"empty"})); }

TEST_F(SafetensorsBad, ShorterThanEightBytes) {
  for (size_t n = 1; n < 8; ++n) {
    EXPECT_TRUE(rejects(std::vector<uint8_t>(n, 0), {"has " + std::to_string(n) + " bytes", "8-byte"})) << n;
  }
}

TEST_F(SafetensorsBad, HeaderLengthPastEndOfFile) {
  EXPECT_TRUE(rejects(raw_file("{}", {}, 100), {"header length 100 exceeds file size 10"}));
  // One byte too many.
  EXPECT_TRUE(rejects(raw_file("{}  ", {}, 5), {"header length 5 exceeds file size 12"}));
}

TEST_F(SafetensorsBad, HugeHeaderLength) {
  EXPECT_TRUE(rejects(raw_file("{}", {}, uint64_t{1} << 63), {"header length 9223372036854775808", "limit"}));
  EXPECT_TRUE(rejects(raw_file("{}", {}, std::numeric_limits<uint64_t>::max()), {"header length", "limit"}));
  EXPECT_TRUE(rejects(raw_file("{}", {}, 100'000'001), {"header length 100000001", "limit"}));
}

TEST_F(SafetensorsBad, ZeroHeaderLength) { EXPECT_TRUE(rejects(raw_file("", {}), {"malformed JSON"})); }

TEST_F(SafetensorsBad, InvalidJson) {
  EXPECT_TRUE(rejects_header("{not json}", 0, {"malformed JSON"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32")", 0, {"malformed JSON"}));  // cut short
  EXPECT_TRUE(rejects_header("{} trailing", 0, {"malformed JSON"}));
  // nlohmann alone would stop at a NUL and ignore the rest.
  EXPECT_TRUE(rejects_header(std::string("{}\0\0\0\0\0\0", 8), 0, {"malformed JSON", "NUL byte at offset 2"}));
  EXPECT_TRUE(rejects_header(std::string("{}\0garbage", 10), 0, {"NUL byte"}));
  EXPECT_TRUE(rejects_header("{\"a\xff\":1}", 0, {"malformed JSON"}));                    // invalid UTF-8
}

TEST_F(SafetensorsBad, JsonNotAnObject) {
  EXPECT_TRUE(rejects_header("[1, 2]", 0, {"must be an object", "array"}));
  EXPECT_TRUE(rejects_header("\"text\"", 0, {"must be an object", "string"}));
  EXPECT_TRUE(rejects_header("42", 0, {"must be an object", "number"}));
  EXPECT_TRUE(rejects_header("null", 0, {"must be an object", "null"}));
}

TEST_F(SafetensorsBad, DuplicateKey) {
  const std::string e = R"({"dtype":"U8","shape":[1],"data_offsets":[0,1]})";
  EXPECT_TRUE(rejects_header("{\"a\":" + e + ",\"a\":" + e + "}", 1, {"duplicate key 'a'"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","dtype":"U8","shape":[1],"data_offsets":[0,1]}})", 1,
                             {"duplicate key 'dtype'"}));
}

TEST_F(SafetensorsBad, EntryNotAnObject) {
  EXPECT_TRUE(rejects_header(R"({"a": 5})", 0, {"tensor 'a'", "must be an object", "number"}));
  EXPECT_TRUE(rejects_header(R"({"a": ["F32", [1], [0, 4]]})", 4, {"tensor 'a'", "must be an object", "array"}));
}

TEST_F(SafetensorsBad, EmptyTensorName) {
  EXPECT_TRUE(rejects_header(R"({"":{"dtype":"U8","shape":[1],"data_offsets":[0,1]}})", 1, {"empty name"}));
}

TEST_F(SafetensorsBad, MissingFields) {
  EXPECT_TRUE(rejects_header(R"({"a":{"shape":[1],"data_offsets":[0,4]}})", 4, {"tensor 'a'", "missing 'dtype'"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","data_offsets":[0,4]}})", 4, {"tensor 'a'", "missing 'shape'"}));
  EXPECT_TRUE(
      rejects_header(R"({"a":{"dtype":"F32","shape":[1]}})", 4, {"tensor 'a'", "missing 'data_offsets'"}));
  EXPECT_TRUE(rejects_header(R"({"a":{}})", 0, {"tensor 'a'", "missing"}));
}

TEST_F(SafetensorsBad, WrongFieldTypes) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":3,"shape":[1],"data_offsets":[0,4]}})", 4,
                             {"tensor 'a'", "'dtype' must be a string", "number"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":null,"shape":[1],"data_offsets":[0,4]}})", 4,
                             {"'dtype' must be a string", "null"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":"1","data_offsets":[0,4]}})", 4,
                             {"tensor 'a'", "shape must be an array", "string"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":{"0":1},"data_offsets":[0,4]}})", 4,
                             {"shape must be an array", "object"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[1.5],"data_offsets":[0,4]}})", 4,
                             {"tensor 'a'", "non-integer"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[1.0],"data_offsets":[0,4]}})", 4, {"non-integer"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":["1"],"data_offsets":[0,4]}})", 4,
                             {"dimensions must be integers", "string"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[[1]],"data_offsets":[0,4]}})", 4,
                             {"dimensions must be integers", "array"}));
  for (const char* offsets : {R"("0,4")", "[0]", "[0,4,8]", "[0,\"4\"]", "[0.0,4]", "[-4,0]", "null", "{}"}) {
    EXPECT_TRUE(rejects_header(std::string(R"({"a":{"dtype":"F32","shape":[1],"data_offsets":)") + offsets + "}}",
                               4, {"tensor 'a'", "'data_offsets' must be an array of 2 non-negative integers"}))
        << offsets;
  }
}

TEST_F(SafetensorsBad, UnknownDtype) {
  for (const char* dtype : {"F8_E4M3", "BOOL", "f32", "", "I16"}) {
    EXPECT_TRUE(rejects_header(std::string(R"({"a":{"dtype":")") + dtype + R"(","shape":[1],"data_offsets":[0,1]}})",
                               1, {"tensor 'a'", std::string("unknown dtype '") + dtype + "'"}))
        << dtype;
  }
}

TEST_F(SafetensorsBad, NegativeDims) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[-1],"data_offsets":[0,4]}})", 4,
                             {"tensor 'a'", "negative dimension -1"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[2,-3],"data_offsets":[0,0]}})", 0,
                             {"negative dimension -3"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[-9223372036854775808],"data_offsets":[0,0]}})", 0,
                             {"negative dimension"}));
}

TEST_F(SafetensorsBad, HugeDims) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[18446744073709551615],"data_offsets":[0,1]}})", 1,
                             {"tensor 'a'", "dimension 18446744073709551615 is too large"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[4294967296,4294967296],"data_offsets":[0,1]}})", 1,
                             {"tensor 'a'", "overflows"}));
  // Element count fits in 64 bits but the byte count does not.
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[4611686018427387904],"data_offsets":[0,1]}})", 1,
                             {"tensor 'a'", "too large"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[99999999999999999999],"data_offsets":[0,1]}})", 1,
                             {"tensor 'a'"}));  // parsed as a float by nlohmann
}

TEST_F(SafetensorsBad, ShapeBytesMismatch) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[3],"data_offsets":[0,8]}})", 8,
                             {"tensor 'a'", "shape [3] with dtype F32 needs 12 bytes", "[0, 8] hold 8"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F16","shape":[2,2],"data_offsets":[0,16]}})", 16,
                             {"shape [2, 2] with dtype F16 needs 8 bytes"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[],"data_offsets":[0,0]}})", 0, {"needs 4 bytes"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[0],"data_offsets":[0,4]}})", 4, {"needs 0 bytes"}));
}

TEST_F(SafetensorsBad, OffsetsOutOfBounds) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[4],"data_offsets":[0,16]}})", 8,
                             {"tensor 'a'", "[0, 16]", "out of bounds", "8 bytes"}));
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[1],"data_offsets":[8,9]}})", 8, {"out of bounds"}));
  EXPECT_TRUE(rejects_header(
      R"({"a":{"dtype":"U8","shape":[1],"data_offsets":[18446744073709551614,18446744073709551615]}})", 8,
      {"out of bounds"}));
  // Even an empty tensor must point inside the data area.
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[0],"data_offsets":[9,9]}})", 8, {"out of bounds"}));
}

TEST_F(SafetensorsBad, ReversedOffsets) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[0],"data_offsets":[4,0]}})", 8,
                             {"tensor 'a'", "[4, 0]", "reversed"}));
}

TEST_F(SafetensorsBad, OverlappingTensors) {
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},)"
                             R"("b":{"dtype":"F32","shape":[2],"data_offsets":[4,12]}})",
                             12, {"'a' [0, 8]", "'b' [4, 12]", "overlap"}));
  // Identical ranges.
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},)"
                             R"("b":{"dtype":"U8","shape":[8],"data_offsets":[0,8]}})",
                             8, {"overlap"}));
  // One range inside a longer one that started earlier, with a third tensor in between.
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":[16],"data_offsets":[0,16]},)"
                             R"("b":{"dtype":"U8","shape":[2],"data_offsets":[2,4]},)"
                             R"("c":{"dtype":"U8","shape":[2],"data_offsets":[10,12]}})",
                             16, {"'a' [0, 16]", "overlap"}));
}

TEST_F(SafetensorsBad, EmptyTensorsDoNotOverlap) {
  // Not a rejection: an empty tensor inside another tensor's range is fine, as are adjacent tensors.
  test::write_file(path_, raw_file(R"({"a":{"dtype":"U8","shape":[8],"data_offsets":[0,8]},)"
                                   R"("e":{"dtype":"F32","shape":[0,5],"data_offsets":[4,4]},)"
                                   R"("b":{"dtype":"U8","shape":[8],"data_offsets":[8,16]}})",
                                   std::vector<uint8_t>(16)));
  const SafetensorsFile f = SafetensorsFile::open(path_);
  EXPECT_EQ(f.get("e").nbytes, 0u);
  EXPECT_EQ(f.get("e").elements(), 0u);
}

TEST_F(SafetensorsBad, TruncatedData) {
  const std::vector<float> v(16, 1.0f);
  write_safetensors(path_, {wt("a", DType::kF32, {16}, v)});
  std::vector<uint8_t> bytes = test::read_file(path_);
  ASSERT_GT(bytes.size(), 8u);
  bytes.pop_back();
  EXPECT_TRUE(rejects(bytes, {"tensor 'a'", "out of bounds", "truncated"}));
}

TEST_F(SafetensorsBad, EveryTruncationIsRejected) {
  const std::vector<float> v = {1, 2, 3};
  const std::vector<int8_t> q = {1, 2};
  write_safetensors(path_, {wt("a", DType::kF32, {3}, v), wt("q", DType::kI8, {2}, q)});
  const std::vector<uint8_t> full = test::read_file(path_);
  for (size_t n = 0; n < full.size(); ++n) {
    const std::vector<uint8_t> cut(full.begin(), full.begin() + static_cast<long>(n));
    EXPECT_TRUE(rejects(cut, {})) << "truncated to " << n << " of " << full.size();
  }
}

TEST_F(SafetensorsBad, MetadataWrongTypes) {
  EXPECT_TRUE(rejects_header(R"({"__metadata__":[1]})", 0, {"__metadata__ must be an object", "array"}));
  EXPECT_TRUE(rejects_header(R"({"__metadata__":"x"})", 0, {"__metadata__ must be an object", "string"}));
  EXPECT_TRUE(rejects_header(R"({"__metadata__":{"k":1}})", 0, {"__metadata__ value of 'k' must be a string",
                                                                "number"}));
  EXPECT_TRUE(rejects_header(R"({"__metadata__":{"k":{"nested":"v"}}})", 0, {"'k'", "object"}));
}

TEST_F(SafetensorsBad, DeeplyNestedJsonIsRejected) {
  const size_t depth = 200000;
  const std::string nested = std::string(depth, '[') + std::string(depth, ']');
  EXPECT_TRUE(rejects_header(R"({"a":{"dtype":"U8","shape":)" + nested + R"(,"data_offsets":[0,1]}})", 1,
                             {"nested deeper than 256 levels"}));
  EXPECT_TRUE(rejects_header(std::string(depth, '['), 0, {"malformed JSON"}));  // unterminated
  EXPECT_TRUE(rejects_header(R"({"__metadata__":{"k":)" + nested + "}}", 0, {"nested deeper"}));
  // At the limit (the top-level object counts as one level) the nesting itself is accepted.
  const std::string ok = std::string(254, '[') + std::string(254, ']');
  EXPECT_TRUE(rejects_header(R"({"__metadata__":{"k":)" + ok + "}}", 0, {"'k'", "must be a string"}));
  const std::string too_deep = std::string(255, '[') + std::string(255, ']');
  EXPECT_TRUE(rejects_header(R"({"__metadata__":{"k":)" + too_deep + "}}", 0, {"nested deeper"}));
}

TEST_F(SafetensorsBad, RandomCorruptionNeverCrashes) {
  const std::vector<float> v = {1, 2, 3, 4};
  const std::vector<uint16_t> h = {0x3C00, 0x4000};
  write_safetensors(path_, {wt("a", DType::kF32, {2, 2}, v), wt("h", DType::kF16, {2}, h)}, {{"k", "v"}});
  const std::vector<uint8_t> good = test::read_file(path_);
  std::mt19937 rng(12345);
  int opened = 0;
  int rejected = 0;
  for (int iter = 0; iter < 2000; ++iter) {
    std::vector<uint8_t> bytes = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < flips; ++k) {
      const size_t pos = rng() % (iter % 2 == 0 ? std::min<size_t>(bytes.size(), 8 + 128) : bytes.size());
      bytes[pos] = static_cast<uint8_t>(rng());
    }
    test::write_file(path_, bytes);
    try {
      const SafetensorsFile f = SafetensorsFile::open(path_);
      for (const std::string& name : f.names()) {
        const SafetensorsTensor& t = f.get(name);
        if (t.dtype == DType::kF32 || t.dtype == DType::kF16 || t.dtype == DType::kBF16) (void)t.to_f32();
      }
      ++opened;
    } catch (const Error& e) {
      ASSERT_EQ(e.code(), StatusCode::kDataLoss) << e.what();
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 0);
  EXPECT_EQ(opened + rejected, 2000);
}

}  // namespace
}  // namespace act
