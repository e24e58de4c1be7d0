#include "graph/aligned_buffer.h"

#include <gtest/gtest.h>
#include <sys/mman.h>

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

// Threads carving buffers from the shared regions and returning them at once, some opening new
// regions: each gets zeroed memory no other thread writes.
TEST(AlignedBuffer, ThreadsAllocatingAndFreeingAtOnce) {
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([t] {
      for (int i = 0; i < 200; ++i) {
        const size_t bytes = 1000 + static_cast<size_t>((i * 7919 + t * 104729) % (3 << 20));
        AlignedBuffer b(bytes);
        ASSERT_TRUE(all_zero(b.data(), bytes));
        std::memset(b.data(), t + 1, bytes);
        ASSERT_EQ(b.data()[bytes - 1], t + 1);
      }
    });
  }
  for (auto& th : threads) th.join();
}

// The madvise hint takes wherever it takes for a mapping of the test's own: the control, a 2 MB-
// aligned region advised the same way. Where the control gets none (no THP for those who ask,
// qemu-user, which swallows madvise), there is nothing to compare with.
TEST(AlignedBuffer, LargeBuffersLieInHugePagesWhereTheSystemGivesThem) {
  if (!AlignedBuffer::carves_from_regions()) GTEST_SKIP() << "AddressSanitizer build: a plain allocation per buffer";
  constexpr size_t kBytes = 16u << 20, kHuge = 2u << 20;
  void* raw = ::mmap(nullptr, kBytes + kHuge, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(raw, MAP_FAILED);
  auto* control = reinterpret_cast<uint8_t*>((reinterpret_cast<uintptr_t>(raw) + kHuge - 1) / kHuge * kHuge);
  ::madvise(control, kBytes, MADV_HUGEPAGE);
  std::memset(control, 1, kBytes);
  const size_t control_huge = anon_huge_page_bytes({reinterpret_cast<uintptr_t>(control)});
  ::munmap(raw, kBytes + kHuge);
  if (control_huge == 0) GTEST_SKIP() << "a region advised MADV_HUGEPAGE here gets no huge pages (no THP, or emulated)";

  AlignedBuffer b(kBytes);
  std::memset(b.data(), 1, kBytes);  // fault the pages in
  EXPECT_GE(AlignedBuffer::huge_page_bytes(), kHuge);
}

}  // namespace
}  // namespace act::graph
