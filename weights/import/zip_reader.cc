#include "weights/import/zip_reader.h"

#include <set>

#include <zlib.h>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act {

namespace {

constexpr uint32_t kLocalHeaderSig = 0x04034b50;
constexpr uint32_t kCentralHeaderSig = 0x02014b50;
constexpr uint32_t kEndSig = 0x06054b50;
constexpr uint32_t kZip64EndSig = 0x06064b50;
constexpr uint32_t kZip64LocatorSig = 0x07064b50;
constexpr size_t kEndSize = 22;
constexpr size_t kCentralHeaderSize = 46;
constexpr size_t kLocalHeaderSize = 30;
constexpr size_t kMaxComment = 0xffff;
// DEFLATE cannot expand data by more than ~1032:1; a larger declared size is a lie.
constexpr uint64_t kMaxDeflateRatio = 1032;

// Little-endian reads of fixed fields; callers check the range first.
uint64_t le(const uint8_t* p, size_t n) {
  uint64_t v = 0;
  for (size_t i = 0; i < n; ++i) v |= static_cast<uint64_t>(p[i]) << (8 * i);
  return v;
}

}  // namespace

bool ZipArchive::looks_like_zip(std::span<const uint8_t> bytes) {
  return bytes.size() >= 4 && (le(bytes.data(), 4) == kLocalHeaderSig || le(bytes.data(), 4) == kEndSig);
}

ZipArchive ZipArchive::open(std::span<const uint8_t> bytes, std::string origin) {
  ZipArchive zip;
  zip.bytes_ = bytes;
  zip.origin_ = std::move(origin);
  const auto corrupt = [&](const std::string& what) { fail(StatusCode::kDataLoss, zip.origin_ + ": zip: " + what); };
  const size_t n = bytes.size();
  const uint8_t* d = bytes.data();
  // [begin, begin + size) lies inside the archive.
  const auto inside = [&](uint64_t begin, uint64_t size) { return begin <= n && size <= n - begin; };

  if (n < kEndSize) corrupt("too short for a zip archive (" + std::to_string(n) + " bytes)");
  // The end-of-central-directory record: the last signature whose comment ends exactly at the end.
  size_t end = n;  // not found
  for (size_t i = n - kEndSize + 1; i-- > 0 && n - i <= kEndSize + kMaxComment;) {
    if (le(d + i, 4) == kEndSig && i + kEndSize + le(d + i + 20, 2) == n) {
      end = i;
      break;
    }
  }
  if (end == n) corrupt("no end-of-central-directory record (not a zip archive, or truncated)");
  uint64_t count = le(d + end + 10, 2);
  uint64_t cd_size = le(d + end + 12, 4);
  uint64_t cd_offset = le(d + end + 16, 4);
  if (le(d + end + 4, 2) != 0 || le(d + end + 6, 2) != 0) corrupt("multi-disk archives are not supported");
  if (count == 0xffff || cd_size == 0xffffffff || cd_offset == 0xffffffff) {
    // zip64: the locator sits right before the end record and points at the zip64 end record.
    if (end < 20 || le(d + end - 20, 4) != kZip64LocatorSig) corrupt("zip64 sizes without a zip64 locator");
    const uint64_t z64 = le(d + end - 20 + 8, 8);
    if (!inside(z64, 56) || le(d + z64, 4) != kZip64EndSig) corrupt("zip64 end record out of range or malformed");
    count = le(d + z64 + 32, 8);
    cd_size = le(d + z64 + 40, 8);
    cd_offset = le(d + z64 + 48, 8);
  }
  if (!inside(cd_offset, cd_size)) corrupt("central directory out of range");
  if (count > cd_size / kCentralHeaderSize) corrupt(std::to_string(count) + " entries cannot fit in a central directory of " + std::to_string(cd_size) + " bytes");

  std::set<std::string> names;
  uint64_t pos = cd_offset;
  const uint64_t cd_end = cd_offset + cd_size;
  for (uint64_t i = 0; i < count; ++i) {
    if (cd_end - pos < kCentralHeaderSize || le(d + pos, 4) != kCentralHeaderSig) corrupt("central directory entry " + std::to_string(i) + " is malformed");
    const uint8_t* h = d + pos;
    ZipEntry e;
    const uint64_t flags = le(h + 8, 2);
    e.method = static_cast<uint16_t>(le(h + 10, 2));
    e.crc32 = static_cast<uint32_t>(le(h + 16, 4));
    e.compressed_size = le(h + 20, 4);
    e.size = le(h + 24, 4);
    const uint64_t name_len = le(h + 28, 2), extra_len = le(h + 30, 2), comment_len = le(h + 32, 2);
    e.local_header_offset = le(h + 42, 4);
    const uint64_t record = kCentralHeaderSize + name_len + extra_len + comment_len;
    if (cd_end - pos < record) corrupt("central directory entry " + std::to_string(i) + " runs past the directory");
    e.name.assign(reinterpret_cast<const char*>(h + kCentralHeaderSize), name_len);
    if (flags & 1) corrupt("entry '" + e.name + "' is encrypted");
    // zip64 extra field: the 64-bit values of the fields saturated at 0xffffffff, in this order.
    const uint8_t* extra = h + kCentralHeaderSize + name_len;
    for (uint64_t x = 0; x + 4 <= extra_len;) {
      const uint64_t id = le(extra + x, 2), len = le(extra + x + 2, 2);
      if (x + 4 + len > extra_len) corrupt("entry '" + e.name + "' has a malformed extra field");
      if (id == 1) {
        uint64_t at = x + 4;
        for (uint64_t* field : {&e.size, &e.compressed_size, &e.local_header_offset}) {
          if (*field != 0xffffffff) continue;
          if (at + 8 > x + 4 + len) corrupt("entry '" + e.name + "' has a short zip64 extra field");
          *field = le(extra + at, 8);
          at += 8;
        }
      }
      x += 4 + len;
    }
    if (e.method != 0 && e.method != 8) {
      corrupt("entry '" + e.name + "' uses compression method " + std::to_string(e.method) + " (only stored and deflated are supported)");
    }
    if (!names.insert(e.name).second) corrupt("entry '" + e.name + "' appears twice");
    zip.entries_.push_back(std::move(e));
    pos += record;
  }
  return zip;
}

const ZipEntry* ZipArchive::find(const std::string& name) const {
  for (const auto& e : entries_) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

std::span<const uint8_t> ZipArchive::read(const ZipEntry& e, std::vector<uint8_t>& scratch) const {
  const auto corrupt = [&](const std::string& what) {
    fail(StatusCode::kDataLoss, origin_ + ": zip entry '" + e.name + "': " + what);
  };
  const size_t n = bytes_.size();
  const uint8_t* d = bytes_.data();
  const uint64_t at = e.local_header_offset;
  if (at > n || n - at < kLocalHeaderSize || le(d + at, 4) != kLocalHeaderSig) corrupt("local header out of range or malformed");
  // The local header's own name and extra lengths (PyTorch pads the extra field to align the data).
  uint64_t data_at = 0;
  if (!detail::checked_add(at + kLocalHeaderSize, le(d + at + 26, 2) + le(d + at + 28, 2), &data_at) ||
      data_at > n || n - data_at < e.compressed_size) {
    corrupt("data runs past the end of the archive");
  }
  std::span<const uint8_t> raw(d + data_at, e.compressed_size);
  std::span<const uint8_t> out;
  if (e.method == 0) {
    if (e.size != e.compressed_size) corrupt("stored entry with different sizes");
    out = raw;
  } else {
    if (e.size / kMaxDeflateRatio > e.compressed_size) corrupt("declared size " + std::to_string(e.size) + " is impossible for its compressed size");
    scratch.assign(e.size, 0);
    z_stream zs{};
    if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) corrupt("zlib inflateInit failed");
    // zlib counts in uInt; bounded by 4 GiB chunks.
    uint64_t in_left = raw.size(), out_left = scratch.size();
    zs.next_in = const_cast<Bytef*>(raw.data());
    zs.next_out = scratch.data();
    int rc = Z_OK;
    while (rc == Z_OK) {
      const uInt in_chunk = static_cast<uInt>(std::min<uint64_t>(in_left, 1u << 30));
      const uInt out_chunk = static_cast<uInt>(std::min<uint64_t>(out_left, 1u << 30));
      zs.avail_in = in_chunk;
      zs.avail_out = out_chunk;
      rc = inflate(&zs, Z_NO_FLUSH);
      in_left -= in_chunk - zs.avail_in;
      out_left -= out_chunk - zs.avail_out;
      if (rc == Z_OK && in_chunk == zs.avail_in && out_chunk == zs.avail_out) rc = Z_BUF_ERROR;  // no progress
    }
    inflateEnd(&zs);
    if (rc != Z_STREAM_END || out_left != 0) corrupt("deflate data is corrupt or does not match the declared size");
    out = scratch;
  }
  uLong crc = crc32(0L, Z_NULL, 0);
  for (size_t done = 0; done < out.size();) {
    const size_t chunk = std::min<size_t>(out.size() - done, 1u << 30);
    crc = crc32(crc, out.data() + done, static_cast<uInt>(chunk));
    done += chunk;
  }
  if (static_cast<uint32_t>(crc) != e.crc32) corrupt("CRC-32 mismatch (the file is damaged)");
  return out;
}

}  // namespace act
