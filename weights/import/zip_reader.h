// A small, fully bounds-checked reader of zip archives held in memory (a mapped file), enough for
// PyTorch's checkpoint format: the central directory (zip64 included), entries STORED or DEFLATED
// (through zlib), CRC-32 checked. Every offset and size is checked against the archive before use;
// a malformed archive is an act::Error(kDataLoss) naming the archive, the entry and the problem.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace act {

struct ZipEntry {
  std::string name;
  uint16_t method = 0;  ///< 0 stored, 8 deflated
  uint64_t compressed_size = 0;
  uint64_t size = 0;
  uint32_t crc32 = 0;
  uint64_t local_header_offset = 0;
};

class ZipArchive {
 public:
  /// Parses the central directory of `bytes` (which must outlive the archive). `origin` names the
  /// archive in messages. Throws act::Error(kDataLoss).
  static ZipArchive open(std::span<const uint8_t> bytes, std::string origin);

  /// True when the bytes start like a zip archive (local file header or empty-archive signature).
  static bool looks_like_zip(std::span<const uint8_t> bytes);

  const std::vector<ZipEntry>& entries() const { return entries_; }
  const ZipEntry* find(const std::string& name) const;

  /// The entry's content: a view into the archive for stored entries, else inflated into `scratch`
  /// (which then owns the bytes). The CRC-32 is checked either way.
  std::span<const uint8_t> read(const ZipEntry& entry, std::vector<uint8_t>& scratch) const;

  const std::string& origin() const { return origin_; }

 private:
  std::span<const uint8_t> bytes_;
  std::string origin_;
  std::vector<ZipEntry> entries_;
};

}  // namespace act
