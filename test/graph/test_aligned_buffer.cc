#include "graph/aligned_buffer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace act::graph {
namespace {

bool all_zero(const uint8_t* p, size_t n) {
  return std::all_of(p, p + n, [](uint8_t b) { return b == 0; });
}

TEST(AlignedBuffer, AlignedZeroedAndDisjoint) {
  // Sizes around the 64-byte line and the 2 MB page, and one larger than a whole region.
  const std::vector<size_t> sizes = {1, 63, 64, 65, 4096, (2u << 20) - 1, 2u << 20, 5u << 20, 40u << 20};
  std::vector<AlignedBuffer> buffers;
  for (size_t i = 0; i < sizes.size(); ++i) {
    AlignedBuffer& b = buffers.emplace_back(sizes[i]);
    ASSERT_NE(b.data(), nullptr);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(b.data()) % kAlignedBufferAlign, 0u) << sizes[i];
    EXPECT_TRUE(all_zero(b.data(), sizes[i])) << sizes[i];
    std::memset(b.data(), static_cast<int>(i + 1), sizes[i]);
  }
  // No buffer's writes landed in another.
  for (size_t i = 0; i < sizes.size(); ++i) {
    const uint8_t* p = buffers[i].data();
    EXPECT_TRUE(std::all_of(p, p + sizes[i], [&](uint8_t b) { return b == i + 1; })) << sizes[i];
  }
}

TEST(AlignedBuffer, ReusedMemoryComesBackZeroed) {
  const size_t bytes = 3u << 20;
  uint8_t* first = nullptr;
  {
    AlignedBuffer b(bytes);
    first = b.data();
    std::memset(b.data(), 0xA5, bytes);
  }
  AlignedBuffer again(bytes);
  EXPECT_TRUE(all_zero(again.data(), bytes));
  // The region the first came from had no other buffer: the second is carved from its start again.
  if (AlignedBuffer::carves_from_regions()) {
    EXPECT_EQ(again.data(), first);
  }
}

TEST(AlignedBuffer, MovingKeepsTheMemoryAndEmptiesTheSource) {
  AlignedBuffer a(1000);
  std::memset(a.data(), 7, 1000);
  uint8_t* p = a.data();
  AlignedBuffer b(std::move(a));
  EXPECT_EQ(b.data(), p);
  EXPECT_EQ(a.data(), nullptr);  // NOLINT(bugprone-use-after-move): the moved-from state is the point
  AlignedBuffer c;
  c = std::move(b);
  EXPECT_EQ(c.data(), p);
  EXPECT_EQ(c.data()[999], 7);
}

TEST(AlignedBuffer, ThreadsAllocatingAndFreeingAtOnce) {
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([t] {
      for (int i = 0; i < 200; ++i) {
        const size_t bytes = 1000 + static_cast<size_t>((i * 7919 + t * 104729) % (3 << 20));
        AlignedBuffer b(bytes);
        ASSERT_TRUE(all_zero(b.data(), bytes));
        std::memset(b.data(), t + 1, bytes);
      }
    });
  }
  for (auto& th : threads) th.join();
}

// The madvise hint takes where the kernel offers transparent huge pages to those who ask.
TEST(AlignedBuffer, LargeBuffersLieInHugePages) {
  if (!AlignedBuffer::carves_from_regions()) GTEST_SKIP() << "AddressSanitizer build: a plain allocation per buffer";
  std::ifstream mode_file("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(mode_file, mode);
  if (mode.find("[always]") == std::string::npos && mode.find("[madvise]") == std::string::npos) {
    GTEST_SKIP() << "this kernel gives no transparent huge pages on request (" << mode << ")";
  }
  AlignedBuffer b(16u << 20);
  std::memset(b.data(), 1, 16u << 20);  // fault the pages in
  EXPECT_GE(AlignedBuffer::huge_page_bytes(), size_t{2} << 20);
}

}  // namespace
}  // namespace act::graph
