#include "weights/blob/file_mapping.h"
#include "weights/blob/file_util.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include "support/file_test_util.h"
#include "support/test_paths.h"

namespace act {
namespace {

using test::throws_error;

TEST(FileMapping, MapsWholeFile) {
  const std::string path = test::scratch_dir() + "/data.bin";
  std::vector<uint8_t> bytes(10000);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<uint8_t>(i * 7);
  test::write_file(path, bytes);

  FileMapping m = FileMapping::open(path);
  ASSERT_EQ(m.size(), bytes.size());
  ASSERT_NE(m.data(), nullptr);
  EXPECT_EQ(m.path(), path);
  EXPECT_EQ(std::memcmp(m.data(), bytes.data(), bytes.size()), 0);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(m.data()) % static_cast<uintptr_t>(sysconf(_SC_PAGESIZE)), 0u);
}

// Releasing [1.5 pages, 4.25 pages) gives back pages 2 and 3 only: the partly covered pages keep
// their bytes. A mapped file reads them again from the file, a private copy as zeros.
TEST(FileMapping, ReleasedPagesAreReadAgainFromTheFileOrAsZeros) {
  const auto page = static_cast<size_t>(sysconf(_SC_PAGESIZE));
  const std::string path = test::scratch_dir() + "/pages.bin";
  std::vector<uint8_t> bytes(5 * page);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<uint8_t>(i % 251 + 1);
  test::write_file(path, bytes);
  const size_t begin = page + page / 2, end = 4 * page + page / 4;

  FileMapping shared = FileMapping::open(path);
  shared.release_pages(shared.data() + begin, end - begin);
  EXPECT_EQ(std::memcmp(shared.data(), bytes.data(), bytes.size()), 0);

  FileMapping copy = FileMapping::open(path, FileMapping::Mode::kPrivateCopy);
  copy.release_pages(copy.data() + begin, end - begin);
  for (size_t i = 0; i < bytes.size(); ++i) {
    const bool released = i >= 2 * page && i < 4 * page;
    ASSERT_EQ(copy.data()[i], released ? 0 : bytes[i]) << "byte " << i;
  }
  EXPECT_TRUE(throws_error([&] { copy.release_pages(copy.data() + page, 5 * page); }, StatusCode::kInternal,
                           {path, "outside the mapping"}));
}

TEST(FileMapping, EmptyFileMapsToNull) {
  const std::string path = test::scratch_dir() + "/empty.bin";
  test::write_file(path, {});
  FileMapping m = FileMapping::open(path);
  EXPECT_EQ(m.size(), 0u);
  EXPECT_EQ(m.data(), nullptr);
  EXPECT_EQ(m.path(), path);
}

TEST(FileMapping, DefaultConstructedIsEmpty) {
  FileMapping m;
  EXPECT_EQ(m.size(), 0u);
  EXPECT_EQ(m.data(), nullptr);
  EXPECT_TRUE(m.path().empty());
}

TEST(FileMapping, MissingFileIsNotFound) {
  const std::string path = test::scratch_dir() + "/nope.bin";
  EXPECT_TRUE(throws_error([&] { FileMapping::open(path); }, StatusCode::kNotFound,
                           {path, "No such file or directory"}));
}

TEST(FileMapping, MissingFolderIsNotFound) {
  const std::string path = test::scratch_dir() + "/no_dir/nope.bin";
  EXPECT_TRUE(throws_error([&] { FileMapping::open(path); }, StatusCode::kNotFound, {path}));
}

TEST(FileMapping, DirectoryIsIoError) {
  const std::string dir = test::scratch_dir();
  EXPECT_TRUE(throws_error([&] { FileMapping::open(dir); }, StatusCode::kIoError, {dir, "not a regular file"}));
}

TEST(FileMapping, PrivateCopyIsImmuneToChangesOfTheFile) {
  // A model copied over the running one (cp, scp: same inode) must not change what was loaded, and a
  // truncated file must not kill the process with SIGBUS.
  const std::string path = test::scratch_dir() + "/model.bin";
  std::vector<uint8_t> original(3 * 4096 + 17);
  for (size_t i = 0; i < original.size(); ++i) original[i] = static_cast<uint8_t>(i * 7 + 1);
  test::write_file(path, original);
  const FileMapping copy = FileMapping::open(path, FileMapping::Mode::kPrivateCopy);
  ASSERT_EQ(copy.size(), original.size());
  test::write_file(path, std::vector<uint8_t>(original.size(), 0xEE));  // rewritten in place
  EXPECT_TRUE(std::equal(original.begin(), original.end(), copy.data()));
  ASSERT_EQ(::truncate(path.c_str(), 100), 0);
  EXPECT_TRUE(std::equal(original.begin(), original.end(), copy.data()));  // every page still readable
  // The shared mapping, by contrast, shows the rewrite: this is what kPrivateCopy exists for.
  test::write_file(path, original);
  const FileMapping shared = FileMapping::open(path);
  test::write_file(path, std::vector<uint8_t>(original.size(), 0xEE));
  EXPECT_EQ(shared.data()[0], 0xEE);
}

TEST(FileMapping, FifoIsRefusedAtOnce) {
  // Opening a FIFO for reading used to wait for a writer forever (and ignore SIGINT/SIGTERM).
  const std::string path = test::scratch_dir() + "/model.fifo";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  EXPECT_TRUE(throws_error([&] { FileMapping::open(path); }, StatusCode::kIoError, {path, "a FIFO"}));
  EXPECT_TRUE(throws_error([&] { detail::read_regular_file(path); }, StatusCode::kIoError, {path, "a FIFO"}));
}

TEST(FileMapping, ReadRegularFileReadsItWhole) {
  const std::string path = test::scratch_dir() + "/text.json";
  test::write_file(path, test::bytes_of("{\"a\": 1}"));
  EXPECT_EQ(detail::read_regular_file(path), "{\"a\": 1}");
  EXPECT_TRUE(throws_error([&] { detail::read_regular_file(path + ".missing"); }, StatusCode::kNotFound, {path}));
}

TEST(FileMapping, UnreadableFileIsIoError) {
  if (::geteuid() == 0) GTEST_SKIP() << "root ignores file permissions";
  const std::string path = test::scratch_dir() + "/secret.bin";
  test::write_file(path, {1, 2, 3});
  ASSERT_EQ(::chmod(path.c_str(), 0), 0);
  EXPECT_TRUE(throws_error([&] { FileMapping::open(path); }, StatusCode::kIoError, {path, "Permission denied"}));
}

TEST(FileMapping, MoveTransfersOwnership) {
  const std::string dir = test::scratch_dir();
  test::write_file(dir + "/a.bin", {1, 2, 3, 4});
  test::write_file(dir + "/b.bin", {9, 8});

  FileMapping a = FileMapping::open(dir + "/a.bin");
  const uint8_t* a_data = a.data();
  FileMapping moved(std::move(a));
  EXPECT_EQ(moved.data(), a_data);
  EXPECT_EQ(moved.size(), 4u);
  EXPECT_EQ(moved.path(), dir + "/a.bin");
  EXPECT_EQ(a.data(), nullptr);  // NOLINT(bugprone-use-after-move): moved-from state is specified
  EXPECT_EQ(a.size(), 0u);
  EXPECT_TRUE(a.path().empty());

  FileMapping b = FileMapping::open(dir + "/b.bin");
  b = std::move(moved);  // unmaps b's old mapping
  EXPECT_EQ(b.data(), a_data);
  EXPECT_EQ(b.size(), 4u);
  EXPECT_EQ(b.data()[3], 4);
  EXPECT_EQ(moved.data(), nullptr);  // NOLINT(bugprone-use-after-move)

  FileMapping& self = b;
  b = std::move(self);  // self-move keeps the mapping
  EXPECT_EQ(b.data(), a_data);
  EXPECT_EQ(b.size(), 4u);
}

TEST(FileMapping, MappingOutlivesUnlink) {
  const std::string path = test::scratch_dir() + "/gone.bin";
  test::write_file(path, {42, 43});
  FileMapping m = FileMapping::open(path);
  std::filesystem::remove(path);
  EXPECT_EQ(m.data()[0], 42);
  EXPECT_EQ(m.data()[1], 43);
}

}  // namespace
}  // namespace act
