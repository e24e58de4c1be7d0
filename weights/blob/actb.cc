#include "weights/blob/actb.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <utility>

#include "actengine/status.h"
#include "weights/blob/file_kind.h"
#include "weights/blob/file_util.h"
#include "weights/blob/tensor_header.h"

namespace act {

namespace {

constexpr char kMagic[8] = {'A', 'C', 'T', 'B', 'L', 'O', 'B', '\0'};
constexpr size_t kFixedHeaderSize = 64;
constexpr size_t kChecksumOffset = 40;  // in the fixed header
using detail::fail_corrupt;
using detail::put_le64;
using detail::read_le64;
constexpr uint64_t kMaxHeaderSize = detail::kMaxJsonHeaderSize;

uint32_t read_le32(const uint8_t* p) {
  return static_cast<uint32_t>(p[0]) | static_cast<uint32_t>(p[1]) << 8 | static_cast<uint32_t>(p[2]) << 16 |
         static_cast<uint32_t>(p[3]) << 24;
}

void put_le32(uint32_t v, uint8_t* p) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

std::string hex32(uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08x", static_cast<unsigned>(v));
  return buf;
}

uint64_t align_up(uint64_t v) { return (v + kActbAlignment - 1) / kActbAlignment * kActbAlignment; }

// zlib's crc32() takes a 32-bit length; feed large buffers in pieces.
uint32_t crc_update(uint32_t crc, const uint8_t* data, size_t size) {
  while (size > 0) {
    const size_t n = std::min<size_t>(size, size_t{1} << 30);
    crc = static_cast<uint32_t>(::crc32(crc, data, static_cast<uInt>(n)));
    data += n;
    size -= n;
  }
  return crc;
}

uint32_t crc_zeros(uint32_t crc, size_t size) {
  static constexpr uint8_t kZeros[kActbAlignment] = {};
  while (size > 0) {
    const size_t n = std::min(size, sizeof kZeros);
    crc = crc_update(crc, kZeros, n);
    size -= n;
  }
  return crc;
}

// Shared by writer (kInvalidArgument) and reader (kDataLoss): returns "" when the params fit the shape.
std::string check_quant(const QuantParams& q, const std::vector<int64_t>& shape) {
  if (q.scales.empty()) {
    return q.zero_points.empty() ? "" : "quant has zero_points but no scales";
  }
  if (q.zero_points.size() != q.scales.size()) {
    return "quant has " + std::to_string(q.scales.size()) + " scales but " + std::to_string(q.zero_points.size()) +
           " zero_points";
  }
  for (float s : q.scales) {
    if (!std::isfinite(s) || s <= 0.0f) return "quant scale " + std::to_string(s) + " is not a positive finite number";
  }
  if (q.scales.size() > 1) {
    if (q.axis < 0 || static_cast<size_t>(q.axis) >= shape.size()) {
      return "quant axis " + std::to_string(q.axis) + " is out of range for shape " + shape_string(shape);
    }
    if (static_cast<uint64_t>(shape[static_cast<size_t>(q.axis)]) != q.scales.size()) {
      return "quant has " + std::to_string(q.scales.size()) + " scales but shape " + shape_string(shape) +
             " has " + std::to_string(shape[static_cast<size_t>(q.axis)]) + " channels on axis " +
             std::to_string(q.axis);
    }
  }
  return "";
}

// Reads the optional "quant" object of a tensor entry; returns "" or what is wrong.
std::string parse_quant(const nlohmann::json& j, QuantParams* q) {
  if (!j.is_object()) return std::string("'quant' must be an object, got ") + j.type_name();
  const auto scales = j.find("scales");
  const auto zps = j.find("zero_points");
  const auto axis = j.find("axis");
  if (scales == j.end() || !scales->is_array()) return "'quant' needs a 'scales' array";
  if (zps == j.end() || !zps->is_array()) return "'quant' needs a 'zero_points' array";
  if (axis == j.end()) return "'quant' needs an 'axis'";
  q->scales.reserve(scales->size());
  for (const auto& s : *scales) {
    float scale = 0.0f;
    if (!s.is_number()) return "quant scales must be numbers";
    if (!detail::json_to_f32(s, &scale)) return "quant scale " + std::to_string(s.get<double>()) + " is out of float range";
    q->scales.push_back(scale);
  }
  q->zero_points.reserve(zps->size());
  for (const auto& z : *zps) {
    int32_t v = 0;
    if (!detail::json_to_i32(z, &v)) return "quant zero_points must be 32-bit integers";
    q->zero_points.push_back(v);
  }
  if (!detail::json_to_i32(*axis, &q->axis)) return "quant axis must be a 32-bit integer";
  return "";
}

}  // namespace

// ---------------------------------------------------------------------------------------------- tensor

const float* ActbTensor::f32() const {
  if (dtype != DType::kF32) {
    fail(StatusCode::kInvalidArgument, "tensor '" + name + "' has dtype " + dtype_name(dtype) + ", not F32");
  }
  // Data is 64-byte aligned inside the mapping (checked at open), so viewing it as floats is safe.
  return static_cast<const float*>(static_cast<const void*>(data));
}

// ---------------------------------------------------------------------------------------------- writer

void ActbWriter::add_tensor(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data,
                            size_t nbytes, QuantParams quant) {
  add(name, dtype, std::move(shape), data, nbytes, std::move(quant), true);
}

void ActbWriter::add_f32(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& values) {
  add(name, DType::kF32, std::move(shape), values.data(), values.size() * sizeof(float), {}, true);
}

void ActbWriter::add_f32_ref(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& values) {
  add(name, DType::kF32, std::move(shape), values.data(), values.size() * sizeof(float), {}, false);
}

void ActbWriter::add(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data, size_t nbytes,
                     QuantParams quant, bool copy) {
  const std::string where = "actb tensor '" + name + "': ";
  if (name.empty()) fail(StatusCode::kInvalidArgument, "actb tensor with an empty name");
  if (index_.count(name) != 0) fail(StatusCode::kInvalidArgument, where + "duplicate tensor name");
  uint64_t elements = 0;
  try {
    elements = shape_elements(shape);
  } catch (const Error& e) {
    fail(StatusCode::kInvalidArgument, where + e.what());
  }
  uint64_t expected = 0;
  if (!detail::checked_mul(elements, dtype_size(dtype), &expected) || expected != nbytes) {
    fail(StatusCode::kInvalidArgument, where + "shape " + shape_string(shape) + " with dtype " + dtype_name(dtype) +
                                            " does not match " + std::to_string(nbytes) + " bytes");
  }
  if (data == nullptr && nbytes != 0) fail(StatusCode::kInvalidArgument, where + "data is null");
  const std::string quant_error = check_quant(quant, shape);
  if (!quant_error.empty()) fail(StatusCode::kInvalidArgument, where + quant_error);

  const auto* bytes = static_cast<const uint8_t*>(data);
  Pending p{name, dtype, std::move(shape), {}, copy ? nullptr : bytes, nbytes, std::move(quant)};
  if (copy && nbytes != 0) p.copy.assign(bytes, bytes + nbytes);
  index_.emplace(name, tensors_.size());
  tensors_.push_back(std::move(p));
}

size_t ActbWriter::write(const std::string& path) const {
  detail::AtomicFileWriter out(path);
  write_to(out);
  const size_t total = out.bytes_written();
  out.commit();
  return total;
}

void ActbWriter::write_to(detail::AtomicFileWriter& out, Checksum checksum) const {
  const std::string& path = out.path();
  // The reader insists on an object; refuse to produce a file it would reject.
  if (!config_.is_object()) {
    fail(StatusCode::kInvalidArgument, "'" + path + "': .actb config must be a JSON object, got " +
                                            config_.type_name());
  }
  // Lay the tensors out back to back, each at a 64-byte aligned offset in the data area.
  nlohmann::ordered_json dir = nlohmann::ordered_json::array();
  std::vector<uint64_t> offsets;
  offsets.reserve(tensors_.size());
  uint64_t cursor = 0;
  for (const Pending& t : tensors_) {
    cursor = align_up(cursor);
    offsets.push_back(cursor);
    nlohmann::ordered_json e = nlohmann::ordered_json::object();
    e["name"] = t.name;
    e["dtype"] = dtype_name(t.dtype);
    e["shape"] = t.shape;
    e["offset"] = cursor;
    e["nbytes"] = t.nbytes;
    if (!t.quant.empty()) {
      nlohmann::ordered_json q = nlohmann::ordered_json::object();
      q["scales"] = t.quant.scales;
      q["zero_points"] = t.quant.zero_points;
      q["axis"] = t.quant.axis;
      e["quant"] = std::move(q);
    }
    dir.push_back(std::move(e));
    cursor += t.nbytes;
  }
  const uint64_t data_size = cursor;

  nlohmann::ordered_json header = nlohmann::ordered_json::object();
  header["producer"] = producer_;
  header["config"] = config_;
  header["tensors"] = std::move(dir);
  const std::string text = detail::dump_json(header, "the .actb header of '" + path + "'");
  if (text.size() > kMaxHeaderSize) {
    fail(StatusCode::kInvalidArgument, "'" + path + "': .actb header of " + std::to_string(text.size()) +
                                            " bytes exceeds the limit of " + std::to_string(kMaxHeaderSize));
  }
  const uint64_t data_offset = align_up(kFixedHeaderSize + text.size());

  // The checksum covers everything after the fixed header, including the zero padding.
  uint32_t crc = 0;
  if (checksum == Checksum::kNow) {
    crc = static_cast<uint32_t>(::crc32(0L, Z_NULL, 0));
    crc = crc_update(crc, reinterpret_cast<const uint8_t*>(text.data()), text.size());
    crc = crc_zeros(crc, data_offset - kFixedHeaderSize - text.size());
    for (size_t i = 0; i < tensors_.size(); ++i) {
      const uint64_t end = i + 1 < tensors_.size() ? offsets[i + 1] : data_size;
      crc = crc_update(crc, tensors_[i].data(), tensors_[i].nbytes);
      crc = crc_zeros(crc, end - offsets[i] - tensors_[i].nbytes);
    }
  }

  uint8_t fixed[kFixedHeaderSize] = {};
  std::memcpy(fixed, kMagic, sizeof kMagic);
  put_le32(kActbFormatVersion, fixed + 8);
  put_le64(text.size(), fixed + 16);
  put_le64(data_offset, fixed + 24);
  put_le64(data_size, fixed + 32);
  put_le64(crc, fixed + kChecksumOffset);

  out.write(fixed, sizeof fixed);
  out.write(text.data(), text.size());
  out.write_zeros(data_offset - kFixedHeaderSize - text.size());
  for (size_t i = 0; i < tensors_.size(); ++i) {
    const uint64_t end = i + 1 < tensors_.size() ? offsets[i + 1] : data_size;
    out.write(tensors_[i].data(), tensors_[i].nbytes);
    out.write_zeros(end - offsets[i] - tensors_[i].nbytes);
  }
}

// ---------------------------------------------------------------------------------------------- reader

namespace {

// The fixed 64-byte header, checked against the file's size.
struct FixedHeader {
  uint32_t version = 0;
  uint64_t header_size = 0, data_offset = 0, data_size = 0, checksum = 0;
};

FixedHeader read_fixed_header(const std::string& path, const uint8_t* base, uint64_t size) {
  if (size < sizeof kMagic) {
    fail_corrupt(path, "truncated or not an .actb file: file has " + std::to_string(size) +
                      " bytes, too short for the magic");
  }
  if (std::memcmp(base, kMagic, sizeof kMagic) != 0) fail_corrupt(path, "not an .actb file (bad magic)");
  if (size < kFixedHeaderSize) {
    fail_corrupt(path, "truncated: file has " + std::to_string(size) + " bytes, the fixed header needs " +
                      std::to_string(kFixedHeaderSize));
  }
  FixedHeader h;
  h.version = read_le32(base + 8);
  if (h.version != kActbFormatVersion) {
    fail(StatusCode::kUnimplemented, "'" + path + "': format version " + std::to_string(h.version) +
                                          ", this build reads " + std::to_string(kActbFormatVersion));
  }
  const uint32_t reserved0 = read_le32(base + 12);
  h.header_size = read_le64(base + 16);
  h.data_offset = read_le64(base + 24);
  h.data_size = read_le64(base + 32);
  h.checksum = read_le64(base + kChecksumOffset);
  bool reserved_zero = reserved0 == 0;
  for (size_t i = 48; i < kFixedHeaderSize; ++i) reserved_zero = reserved_zero && base[i] == 0;
  if (!reserved_zero) fail_corrupt(path, "reserved fixed-header bytes are not zero");

  uint64_t expected_size = 0;
  if (!detail::checked_add(h.data_offset, h.data_size, &expected_size)) {
    fail_corrupt(path, "data_offset " + std::to_string(h.data_offset) + " + data_size " + std::to_string(h.data_size) +
                      " overflows");
  }
  if (expected_size > size) {
    fail_corrupt(path, "truncated: file has " + std::to_string(size) + " bytes, header says " +
                      std::to_string(expected_size));
  }
  if (expected_size < size) {
    fail_corrupt(path, "file has " + std::to_string(size) + " bytes, header says " + std::to_string(expected_size) +
                      " (trailing garbage)");
  }
  if (h.header_size > kMaxHeaderSize) {
    fail_corrupt(path, "header_size " + std::to_string(h.header_size) + " exceeds the limit of " +
                      std::to_string(kMaxHeaderSize));
  }
  if (h.data_offset % kActbAlignment != 0) {
    fail_corrupt(path, "data_offset " + std::to_string(h.data_offset) + " is not 64-byte aligned");
  }
  if (h.data_offset < kFixedHeaderSize + h.header_size) {
    fail_corrupt(path, "JSON header of " + std::to_string(h.header_size) + " bytes at offset 64 overruns data_offset " +
                      std::to_string(h.data_offset));
  }
  if (h.checksum > std::numeric_limits<uint32_t>::max()) {
    fail_corrupt(path, "checksum field " + std::to_string(h.checksum) + " is not a zero-extended CRC-32");
  }
  return h;
}

// CRC-32 of everything after the fixed header.
uint32_t checksum_of(const uint8_t* base, uint64_t size) {
  const auto crc = static_cast<uint32_t>(::crc32(0L, Z_NULL, 0));
  return crc_update(crc, base + kFixedHeaderSize, static_cast<size_t>(size - kFixedHeaderSize));
}

void verify_checksum_of(const std::string& path, const uint8_t* base, uint64_t size, uint64_t checksum) {
  const uint32_t crc = checksum_of(base, size);
  if (crc != checksum) {
    fail_corrupt(path, "checksum mismatch (stored " + hex32(static_cast<uint32_t>(checksum)) + ", computed " +
                      hex32(crc) + "): the file is corrupt");
  }
}

// The JSON header's three parts.
struct JsonHeader {
  std::string producer;
  nlohmann::json config;   // an object
  nlohmann::json tensors;  // an array: the tensor directory
};

JsonHeader read_json_header(const std::string& path, const uint8_t* base, uint64_t header_size) {
  nlohmann::json header =
      detail::parse_json_object_header(path, base + kFixedHeaderSize, static_cast<size_t>(header_size));
  JsonHeader h;
  const auto producer = header.find("producer");
  if (producer == header.end() || !producer->is_string()) fail_corrupt(path, "JSON header needs a 'producer' string");
  h.producer = producer->get<std::string>();
  const auto config = header.find("config");
  if (config == header.end() || !config->is_object()) fail_corrupt(path, "JSON header needs a 'config' object");
  h.config = std::move(*config);
  const auto tensors = header.find("tensors");
  if (tensors == header.end() || !tensors->is_array()) fail_corrupt(path, "JSON header needs a 'tensors' array");
  h.tensors = std::move(*tensors);
  return h;
}

// Where tensor `t` lies: 'offset' and 'nbytes', which must match the `expected_nbytes` of its dtype and
// shape and lie inside the data area. `where` names the tensor in errors.
void read_tensor_extent(const std::string& path, const std::string& where, const nlohmann::json& e,
                        uint64_t expected_nbytes, const uint8_t* data_area, uint64_t data_size, ActbTensor& t) {
  const auto offset_it = e.find("offset");
  const auto nbytes_it = e.find("nbytes");
  uint64_t offset = 0;
  uint64_t nbytes = 0;
  if (offset_it == e.end() || !detail::json_to_u64(*offset_it, &offset)) {
    fail_corrupt(path, where + "needs a non-negative integer 'offset'");
  }
  if (nbytes_it == e.end() || !detail::json_to_u64(*nbytes_it, &nbytes)) {
    fail_corrupt(path, where + "needs a non-negative integer 'nbytes'");
  }
  if (expected_nbytes != nbytes) {
    fail_corrupt(path, where + "nbytes " + std::to_string(nbytes) + " does not match shape " + shape_string(t.shape) +
                      " with dtype " + dtype_name(t.dtype));
  }
  if (offset % kActbAlignment != 0) {
    fail_corrupt(path, where + "offset " + std::to_string(offset) + " is not 64-byte aligned");
  }
  uint64_t end = 0;
  if (!detail::checked_add(offset, nbytes, &end) || end > data_size) {
    fail_corrupt(path, where + "bytes [" + std::to_string(offset) + ", +" + std::to_string(nbytes) +
                      ") are out of bounds of the data area of " + std::to_string(data_size) + " bytes");
  }
  t.data = data_area + offset;
  t.nbytes = static_cast<size_t>(nbytes);
}

// Entry `i` of the tensor directory; `index` holds the names read so far (a duplicate is corrupt).
ActbTensor read_tensor_entry(const std::string& path, const nlohmann::json& e, size_t i,
                             const std::map<std::string, size_t>& index, const uint8_t* data_area, uint64_t data_size) {
  std::string where = "tensors[" + std::to_string(i) + "]: ";
  if (!e.is_object()) fail_corrupt(path, where + "must be an object, got " + e.type_name());
  const auto name = e.find("name");
  if (name == e.end() || !name->is_string() || name->get_ref<const std::string&>().empty()) {
    fail_corrupt(path, where + "needs a non-empty 'name' string");
  }
  ActbTensor t;
  t.name = name->get<std::string>();
  where = "tensor '" + t.name + "': ";
  if (index.count(t.name) != 0) fail_corrupt(path, where + "duplicate tensor name");

  detail::TensorEntryType type = detail::parse_tensor_entry_type(path, where, e);
  t.dtype = type.dtype;
  t.shape = std::move(type.shape);
  read_tensor_extent(path, where, e, type.nbytes, data_area, data_size, t);
  const auto quant = e.find("quant");
  if (quant != e.end()) {
    std::string error = parse_quant(*quant, &t.quant);
    if (error.empty()) error = check_quant(t.quant, t.shape);
    if (!error.empty()) fail_corrupt(path, where + error);
  }
  return t;
}

// No two non-empty tensors share a byte (checked in offset order).
void check_no_overlap(const std::string& path, const std::vector<ActbTensor>& tensors) {
  std::vector<const ActbTensor*> order;
  order.reserve(tensors.size());
  for (const ActbTensor& t : tensors) {
    if (t.nbytes != 0) order.push_back(&t);
  }
  std::sort(order.begin(), order.end(), [](const ActbTensor* a, const ActbTensor* b) { return a->data < b->data; });
  const ActbTensor* furthest = nullptr;
  for (const ActbTensor* t : order) {
    if (furthest != nullptr && t->data < furthest->data + furthest->nbytes) {
      fail_corrupt(path, "tensors '" + furthest->name + "' and '" + t->name + "' overlap");
    }
    if (furthest == nullptr || t->data + t->nbytes > furthest->data + furthest->nbytes) furthest = t;
  }
}

}  // namespace

void seal_actb_checksum(detail::AtomicFileWriter& file) {
  const FileMapping written = FileMapping::open(file.readable_path());
  if (written.size() < kFixedHeaderSize) {
    fail(StatusCode::kInvalidArgument, "'" + file.path() + "': no .actb blob was written to seal");
  }
  uint8_t field[8];
  put_le64(checksum_of(written.data(), written.size()), field);
  file.write_at(kChecksumOffset, field, sizeof field);
}

ActbFile ActbFile::open(const std::string& path, bool verify_checksum, FileMapping::Mode mode) {
  ActbFile f;
  // The wrong kind of input (a checkpoint folder, an image...) says what it is and what to run.
  if (const std::string hint = not_a_blob_hint(path); !hint.empty()) fail(StatusCode::kInvalidArgument, hint);
  f.mapping_ = FileMapping::open(path, mode);
  const uint8_t* base = f.mapping_.data();
  const uint64_t size = f.mapping_.size();
  const FixedHeader fixed = read_fixed_header(path, base, size);
  f.version_ = fixed.version;
  if (verify_checksum) verify_checksum_of(path, base, size, fixed.checksum);
  JsonHeader header = read_json_header(path, base, fixed.header_size);
  f.producer_ = std::move(header.producer);
  f.config_ = std::move(header.config);
  const uint8_t* data_area = base + fixed.data_offset;
  f.tensors_.reserve(header.tensors.size());
  for (size_t i = 0; i < header.tensors.size(); ++i) {
    ActbTensor t = read_tensor_entry(path, header.tensors[i], i, f.index_, data_area, fixed.data_size);
    f.index_.emplace(t.name, f.tensors_.size());
    f.tensors_.push_back(std::move(t));
  }
  check_no_overlap(path, f.tensors_);
  return f;
}

const ActbTensor* ActbFile::find(const std::string& name) const {
  const auto it = index_.find(name);
  return it == index_.end() ? nullptr : &tensors_[it->second];
}

const ActbTensor& ActbFile::get(const std::string& name) const {
  const ActbTensor* t = find(name);
  if (t == nullptr) fail(StatusCode::kNotFound, "tensor '" + name + "' not found in '" + path() + "'");
  return *t;
}

}  // namespace act
