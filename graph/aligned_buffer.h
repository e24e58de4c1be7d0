// AlignedBuffer: the memory of an engine's packed weights, the bias tables its linears read, its
// graph's arena and attention's packed keys and values: 64-byte aligned and zero-filled, in
// transparent huge pages where the OS gives them.
//
// Why: the default model's 35 MB of int8 weights do not fit the last-level cache and stream from
// DRAM at every inference; in 4 KB pages that is a TLB miss per page walked. Buffers are carved one
// after another from shared regions of 32 MB (or more for a larger buffer), mapped 2 MB-aligned with
// madvise(MADV_HUGEPAGE), so one engine's weights lie contiguous in a few huge pages. A region is
// unmapped when the last buffer carved from it goes (each buffer holds a reference to it); the region
// still open for carving is reused from its start once every buffer in it is gone. Where the OS has
// no huge pages the regions are ordinary pages, and where mmap fails (or under AddressSanitizer,
// whose redzones need each buffer apart) the buffer is std::aligned_alloc memory: the same contents
// either way.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <set>
#include <utility>

namespace act::graph {

/// Bytes of alignment every AlignedBuffer has (the packed-weight alignment of the GEMM kernels).
inline constexpr size_t kAlignedBufferAlign = 64;

class AlignedBuffer {
 public:
  AlignedBuffer() = default;
  /// `bytes` of zeroed memory (at least one 64-byte line). Throws std::bad_alloc when out of memory.
  explicit AlignedBuffer(size_t bytes);
  AlignedBuffer(AlignedBuffer&& other) noexcept
      : region_(std::move(other.region_)), data_(std::exchange(other.data_, nullptr)) {}
  AlignedBuffer& operator=(AlignedBuffer&& other) noexcept {
    region_ = std::move(other.region_);
    data_ = std::exchange(other.data_, nullptr);
    return *this;
  }
  AlignedBuffer(const AlignedBuffer&) = delete;
  AlignedBuffer& operator=(const AlignedBuffer&) = delete;
  uint8_t* data() const { return data_; }
  /// The same memory as floats (the arena, float weight panels, bias tables).
  float* floats() const { return reinterpret_cast<float*>(data_); }

  /// Bytes of this process's AlignedBuffer regions the kernel backs with huge pages right now, for
  /// benchmarks and tests to show the hint took.
  static size_t huge_page_bytes();
  /// False under AddressSanitizer: every buffer is then an allocation of its own.
  static bool carves_from_regions();

  struct Region;

 private:
  std::shared_ptr<Region> region_;  // keeps the memory alive
  uint8_t* data_ = nullptr;
};

/// Bytes the kernel backs with huge pages in this process's mappings that start at these addresses
/// (AnonHugePages in Linux's /proc/self/smaps; 0 where it has none).
size_t anon_huge_page_bytes(const std::set<uintptr_t>& mapping_starts);

}  // namespace act::graph
