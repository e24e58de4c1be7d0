#include "graph/aligned_buffer.h"

#include <sys/mman.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <new>
#include <string>
#include <utility>

namespace act::graph {

namespace {

constexpr size_t kHugePage = size_t{2} << 20;         // x86-64 and 4 KB-page arm64; others just align more
constexpr size_t kRegionBytes = size_t{32} << 20;     // the default model's weights in two regions

// Under AddressSanitizer every buffer is an allocation of its own, so that its redzones catch a
// kernel reading past its packed weights (carved side by side, they would read the next buffer).
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kCarveFromRegions = false;
#else
constexpr bool kCarveFromRegions = true;
#endif

size_t round_up(size_t bytes, size_t to) { return (bytes + to - 1) / to * to; }

}  // namespace

/// A mapping buffers are carved from; unmapped (or freed) with its last reference.
struct AlignedBuffer::Region {
  uint8_t* base = nullptr;
  size_t size = 0;
  size_t used = 0;     // bytes carved so far
  bool mapped = true;  // false: std::aligned_alloc memory for one buffer
  ~Region();
};

namespace {

// Start addresses of the mapped regions alive, for huge_page_bytes().
struct Regions {
  std::mutex mutex;
  std::shared_ptr<AlignedBuffer::Region> open;  // the region new buffers are carved from
  std::set<uintptr_t> mapped;
};

Regions& regions() {
  static Regions* r = new Regions;  // never destroyed: buffers may outlive static destruction order
  return *r;
}

// `bytes` (a multiple of kHugePage) mapped at a kHugePage-aligned address, asking for huge pages;
// nullptr when the mapping fails.
uint8_t* map_huge_aligned(size_t bytes) {
  const size_t span = bytes + kHugePage;
  void* p = mmap(nullptr, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return nullptr;
  const uintptr_t start = reinterpret_cast<uintptr_t>(p);
  const uintptr_t aligned = round_up(start, kHugePage);
  if (aligned > start) munmap(p, aligned - start);
  if (const size_t tail = start + span - (aligned + bytes); tail > 0) munmap(reinterpret_cast<void*>(aligned + bytes), tail);
#ifdef MADV_HUGEPAGE
  madvise(reinterpret_cast<void*>(aligned), bytes, MADV_HUGEPAGE);  // a hint: fine if the OS declines
#endif
  return reinterpret_cast<uint8_t*>(aligned);
}

}  // namespace

AlignedBuffer::Region::~Region() {
  if (!mapped) {
    std::free(base);
    return;
  }
  {
    Regions& r = regions();
    std::lock_guard<std::mutex> lock(r.mutex);
    r.mapped.erase(reinterpret_cast<uintptr_t>(base));
  }
  munmap(base, size);
}

AlignedBuffer::AlignedBuffer(size_t bytes) {
  bytes = round_up(std::max<size_t>(bytes, 1), kAlignedBufferAlign);
  Regions& r = regions();
  std::shared_ptr<Region> retired;  // a region replaced here is released after the lock (~Region takes it)
  std::lock_guard<std::mutex> lock(r.mutex);
  if (r.open && r.open.use_count() == 1) r.open->used = 0;  // every buffer carved from it is gone
  if (!r.open || r.open->size - r.open->used < bytes) {
    const size_t size = std::max(kRegionBytes, round_up(bytes, kHugePage));
    auto region = std::make_shared<Region>();
    region->base = kCarveFromRegions ? map_huge_aligned(size) : nullptr;
    if (region->base == nullptr) {  // a plain allocation of this buffer alone
      region->mapped = false;
      region->base = static_cast<uint8_t*>(std::aligned_alloc(kAlignedBufferAlign, bytes));
      if (region->base == nullptr) throw std::bad_alloc();
      std::memset(region->base, 0, bytes);
      data_ = region->base;
      region_ = std::move(region);
      return;
    }
    region->size = size;
    r.mapped.insert(reinterpret_cast<uintptr_t>(region->base));
    retired = std::exchange(r.open, std::move(region));
  }
  data_ = r.open->base + r.open->used;
  r.open->used += bytes;
  std::memset(data_, 0, bytes);  // fresh pages are zero already; a reused region's are not
  region_ = r.open;
}

bool AlignedBuffer::carves_from_regions() { return kCarveFromRegions; }

size_t AlignedBuffer::huge_page_bytes() {
  std::set<uintptr_t> mapped;
  {
    Regions& r = regions();
    std::lock_guard<std::mutex> lock(r.mutex);
    mapped = r.mapped;
  }
  return anon_huge_page_bytes(mapped);
}

size_t anon_huge_page_bytes(const std::set<uintptr_t>& mapping_starts) {
  std::ifstream smaps("/proc/self/smaps");
  size_t total = 0;
  bool ours = false;
  for (std::string line; std::getline(smaps, line);) {
    const size_t dash = line.find('-');
    if (dash != std::string::npos && dash > 0 && line.find_first_not_of("0123456789abcdef") == dash) {
      ours = mapping_starts.count(std::stoull(line.substr(0, dash), nullptr, 16)) > 0;  // a mapping's header line
    } else if (ours && line.rfind("AnonHugePages:", 0) == 0) {
      total += std::stoull(line.substr(14)) * 1024;  // "AnonHugePages:   2048 kB"
    }
  }
  return total;
}

}  // namespace act::graph
