#include "weights/import/pytorch_checkpoint.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <map>
#include <optional>

#include "actengine/status.h"
#include "weights/blob/file_mapping.h"
#include "weights/blob/file_util.h"
#include "weights/import/pickle_reader.h"
#include "weights/import/zip_reader.h"

namespace act {

namespace {

using Kind = PickleValue::Kind;

// The legacy format's first pickle: torch.serialization.MAGIC_NUMBER as a 10-byte LONG1, and its version.
constexpr uint8_t kLegacyMagic[] = {0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19};
constexpr int64_t kLegacyProtocolVersion = 1001;
constexpr uint8_t kLegacyStart[] = {0x80, 0x02, 0x8a, 0x0a};  // PROTO 2, LONG1 of 10 bytes

bool is_tensor_dict(const PickleValue& v) {
  if (v.kind != Kind::kDict || v.entries.empty()) return false;
  for (const auto& [k, t] : v.entries) {
    if (k->kind != Kind::kString || t->kind != Kind::kTensor) return false;
  }
  return true;
}

// Bytes of the tensor's whole storage as the pickle declares it (UINT64_MAX when that overflows).
uint64_t storage_bytes(const PickleTensor& t) {
  uint64_t bytes = 0;
  if (t.storage_elements < 0 ||
      !detail::checked_mul(static_cast<uint64_t>(t.storage_elements), t.storage_type.element_size, &bytes)) {
    return UINT64_MAX;
  }
  return bytes;
}

// Copies a (possibly strided) view of a storage into a contiguous buffer, checking every bound.
std::vector<uint8_t> materialize(const std::string& where, const PickleTensor& t, std::span<const uint8_t> storage) {
  if (!t.storage_type.dtype) {
    fail(StatusCode::kUnimplemented, where + ": torch." + t.storage_type.name + " tensors are not supported");
  }
  const uint64_t esize = t.storage_type.element_size;
  if (storage.size() / esize != static_cast<uint64_t>(t.storage_elements) || storage.size() % esize != 0) {
    fail(StatusCode::kDataLoss, where + ": storage '" + t.storage_key + "' has " + std::to_string(storage.size()) +
         " bytes, the pickle says " + std::to_string(t.storage_elements) + " elements of " + std::to_string(esize) + " bytes");
  }
  uint64_t elements = 1;
  uint64_t last = static_cast<uint64_t>(t.offset);  // index of the view's last element
  for (size_t i = 0; i < t.size.size(); ++i) {
    if (!detail::checked_mul(elements, static_cast<uint64_t>(t.size[i]), &elements)) elements = UINT64_MAX;
  }
  if (elements > 0) {
    for (size_t i = 0; i < t.size.size(); ++i) {
      uint64_t span = 0;
      if (!detail::checked_mul(static_cast<uint64_t>(t.size[i] - 1), static_cast<uint64_t>(t.stride[i]), &span) ||
          !detail::checked_add(last, span, &last)) {
        last = UINT64_MAX;
      }
    }
    if (last >= static_cast<uint64_t>(t.storage_elements)) {
      fail(StatusCode::kDataLoss, where + ": view (offset " + std::to_string(t.offset) + ", size " + shape_string(t.size) +
           ", stride " + shape_string(t.stride) + ") reaches outside its storage of " + std::to_string(t.storage_elements) + " elements");
    }
    // More elements than the storage holds only happens for expanded (stride 0) views; refusing them
    // keeps the memory used bounded by the file size.
    if (elements > static_cast<uint64_t>(t.storage_elements)) {
      fail(StatusCode::kUnimplemented, where + ": expanded views (more elements than their storage) are not supported");
    }
  }
  std::vector<uint8_t> out(static_cast<size_t>(elements * esize));
  if (elements == 0) return out;
  // C-contiguous (dims of size 1 may have any stride): one copy.
  bool contiguous = true;
  uint64_t expected = 1;
  for (size_t i = t.size.size(); i-- > 0;) {
    if (t.size[i] != 1 && static_cast<uint64_t>(t.stride[i]) != expected) contiguous = false;
    expected *= static_cast<uint64_t>(t.size[i]);
  }
  const uint8_t* base = storage.data();
  if (contiguous) {
    std::memcpy(out.data(), base + static_cast<uint64_t>(t.offset) * esize, out.size());
    return out;
  }
  std::vector<int64_t> index(t.size.size(), 0);
  for (uint64_t n = 0; n < elements; ++n) {
    uint64_t src = static_cast<uint64_t>(t.offset);
    for (size_t i = 0; i < index.size(); ++i) src += static_cast<uint64_t>(index[i] * t.stride[i]);
    std::memcpy(out.data() + n * esize, base + src * esize, esize);
    for (size_t i = index.size(); i-- > 0;) {  // odometer
      if (++index[i] < t.size[i]) break;
      index[i] = 0;
    }
  }
  return out;
}

// Finds the state dict in the saved object.
const PickleValue& select_state_dict(const PickleValue& root, const std::string& path, const std::string& key,
                                     PyTorchCheckpoint& out) {
  if (key.empty() && is_tensor_dict(root)) {
    out.location = "the saved object";
    return root;
  }
  if (root.kind != Kind::kDict) {
    fail(StatusCode::kInvalidArgument, path + ": the saved object is a " + root.describe() + ", not a state dict");
  }
  std::vector<std::string> candidates, entries;
  for (const auto& [k, v] : root.entries) {
    const std::string name = k->kind == Kind::kString ? k->text : k->describe();
    entries.push_back(name);
    if (k->kind == Kind::kString && is_tensor_dict(*v)) candidates.push_back(name);
  }
  auto list = [](const std::vector<std::string>& names) {
    std::string s;
    for (size_t i = 0; i < names.size() && i < 12; ++i) s += (i ? ", " : "") + ("'" + names[i] + "'");
    if (names.size() > 12) s += ", ...";
    return s;
  };
  std::string chosen = key;
  if (!key.empty()) {
    const PickleValue* v = root.find(key);
    if (!v) fail(StatusCode::kNotFound, path + ": no entry '" + key + "' (entries: " + list(entries) + ")");
    if (!is_tensor_dict(*v)) fail(StatusCode::kInvalidArgument, path + ": entry '" + key + "' is a " + v->describe() + ", not a dict of tensors");
  } else if (candidates.size() == 1) {
    chosen = candidates[0];
  } else {
    for (const char* preferred : {"model_state_dict", "state_dict", "model"}) {
      if (std::find(candidates.begin(), candidates.end(), preferred) != candidates.end()) {
        chosen = preferred;
        break;
      }
    }
    if (chosen.empty()) {
      if (candidates.empty()) {
        fail(StatusCode::kInvalidArgument, path + ": no state dict (a dict of tensors) in the saved dict; its entries: " + list(entries));
      }
      fail(StatusCode::kInvalidArgument, path + ": several dicts of tensors (" + list(candidates) +
           "); pick one with --state-dict-key");
    }
  }
  out.location = "entry '" + chosen + "'";
  for (const auto& [k, v] : root.entries) {
    if (k->kind == Kind::kString && k->text == chosen) continue;
    out.other_entries.push_back((k->kind == Kind::kString ? k->text : k->describe()) + ": " + v->describe());
  }
  return *root.find(chosen);
}

// Every tensor's storage type by key (the legacy format needs them to size each storage).
void collect_storage_types(const PickleValue& v, std::map<std::string, PickleStorageType>& types, const std::string& path) {
  if (v.kind == Kind::kTensor) {
    const auto [it, inserted] = types.emplace(v.tensor->storage_key, v.tensor->storage_type);
    if (!inserted && it->second.name != v.tensor->storage_type.name) {
      fail(StatusCode::kDataLoss, path + ": storage '" + v.tensor->storage_key + "' is both " + it->second.name + " and " +
           v.tensor->storage_type.name);
    }
  }
  for (const auto& item : v.items) collect_storage_types(*item, types, path);
  for (const auto& [k, item] : v.entries) collect_storage_types(*item, types, path);
}

PickleRef read_zip(const std::string& path, std::span<const uint8_t> file, std::vector<uint8_t>& pickle_scratch,
                   ZipArchive& zip, std::string& prefix) {
  zip = ZipArchive::open(file, path);
  const ZipEntry* pkl = nullptr;
  for (const auto& e : zip.entries()) {
    const size_t slash = e.name.find('/');
    if (slash != std::string::npos && e.name.compare(slash, std::string::npos, "/data.pkl") == 0) {
      if (pkl) fail(StatusCode::kDataLoss, path + ": two data.pkl entries ('" + pkl->name + "', '" + e.name + "')");
      pkl = &e;
    }
  }
  if (!pkl) fail(StatusCode::kDataLoss, path + ": a zip archive without <name>/data.pkl is not a PyTorch checkpoint");
  prefix = pkl->name.substr(0, pkl->name.size() - std::strlen("data.pkl"));
  if (const ZipEntry* order = zip.find(prefix + "byteorder")) {
    std::vector<uint8_t> scratch;
    const auto bytes = zip.read(*order, scratch);
    if (std::string(bytes.begin(), bytes.end()) != "little") {
      fail(StatusCode::kUnimplemented, path + ": saved on a big-endian machine (byteorder '" +
           std::string(bytes.begin(), bytes.begin() + static_cast<ptrdiff_t>(std::min<size_t>(bytes.size(), 16))) + "')");
    }
  }
  return parse_pickle(zip.read(*pkl, pickle_scratch), path + ": " + pkl->name);
}

// The legacy format: five pickles (magic number, protocol version, sys_info, the object, the
// storage keys) and then each storage's bytes, which go into `storages` by key. Returns the object.
PickleRef read_legacy(const std::string& path, std::span<const uint8_t> bytes,
                      std::map<std::string, std::span<const uint8_t>>& storages) {
  size_t pos = 0;
  auto next = [&](const char* what) {
    size_t used = 0;
    PickleRef v = parse_pickle(bytes.subspan(pos), path + ": " + what + " pickle at byte " + std::to_string(pos), {}, &used);
    pos += used;
    return v;
  };
  const PickleRef magic = next("magic number");
  if (magic->kind != Kind::kBigInt || magic->text != std::string(std::begin(kLegacyMagic), std::end(kLegacyMagic))) {
    fail(StatusCode::kDataLoss, path + ": not a PyTorch checkpoint (wrong magic number)");
  }
  const PickleRef version = next("protocol version");
  if (version->kind != Kind::kInt || version->integer != kLegacyProtocolVersion) {
    fail(StatusCode::kUnimplemented, path + ": legacy format version " + version->describe() + " (only 1001 is supported)");
  }
  const PickleRef sys_info = next("sys_info");
  const PickleValue* little = sys_info->find("little_endian");
  if (!little || little->kind != Kind::kBool || !little->boolean) {
    fail(StatusCode::kUnimplemented, path + ": saved on a big-endian machine, or sys_info is missing little_endian");
  }
  PickleRef root = next("main");
  const PickleRef keys = next("storage keys");
  if (keys->kind != Kind::kList) fail(StatusCode::kDataLoss, path + ": the storage key list is a " + keys->describe());
  std::map<std::string, PickleStorageType> types;
  collect_storage_types(*root, types, path);
  for (const auto& key : keys->items) {
    if (!key->is_string()) fail(StatusCode::kDataLoss, path + ": storage key " + key->describe() + " is not a str");
    const auto type = types.find(key->text);
    if (type == types.end()) fail(StatusCode::kDataLoss, path + ": storage '" + key->text + "' is used by no tensor");
    if (bytes.size() - pos < 8) fail(StatusCode::kDataLoss, path + ": truncated before storage '" + key->text + "'");
    uint64_t numel = 0;
    for (int i = 7; i >= 0; --i) numel = (numel << 8) | bytes[pos + static_cast<size_t>(i)];
    pos += 8;
    uint64_t nbytes = 0;
    if (!detail::checked_mul(numel, type->second.element_size, &nbytes) || nbytes > bytes.size() - pos) {
      fail(StatusCode::kDataLoss, path + ": storage '" + key->text + "' (" + std::to_string(numel) + " elements) runs past the end of the file");
    }
    if (!storages.emplace(key->text, bytes.subspan(pos, static_cast<size_t>(nbytes))).second) {
      fail(StatusCode::kDataLoss, path + ": storage '" + key->text + "' is listed twice");
    }
    pos += static_cast<size_t>(nbytes);
  }
  if (pos != bytes.size()) fail(StatusCode::kDataLoss, path + ": " + std::to_string(bytes.size() - pos) + " unexpected bytes at the end");
  return root;
}

// Every tensor of `state_dict` into out.state_dict, in saved order. A zip's storages are read
// from `zip` (under `prefix`) as tensors first need them; the legacy format's are all in `storages`.
void read_tensors(const std::string& path, const PickleValue& state_dict,
                  std::map<std::string, std::span<const uint8_t>>& storages, const ZipArchive& zip,
                  const std::string& prefix, PyTorchCheckpoint& out) {
  std::map<std::string, std::vector<uint8_t>> inflated;  // deflated zip storages, by key
  for (const auto& [k, v] : state_dict.entries) {
    const PickleTensor& t = *v->tensor;
    const std::string where = path + ": tensor '" + k->text + "'";
    auto storage = storages.find(t.storage_key);
    if (storage == storages.end()) {
      if (out.format != "zip") fail(StatusCode::kDataLoss, where + ": storage '" + t.storage_key + "' is not in the file");
      // Read (and CRC-checked) once, however many tensors view it.
      const ZipEntry* entry = zip.find(prefix + "data/" + t.storage_key);
      if (!entry) fail(StatusCode::kDataLoss, where + ": storage " + prefix + "data/" + t.storage_key + " is missing");
      // The size the pickle implies is known before inflating: a deflated entry that declares more is
      // refused here, not after inflating it (a few kB can declare gigabytes).
      if (t.storage_type.dtype && entry->size != storage_bytes(t)) {
        fail(StatusCode::kDataLoss, where + ": storage " + entry->name + " declares " + std::to_string(entry->size) +
             " bytes, the pickle says " + std::to_string(t.storage_elements) + " elements of " +
             std::to_string(t.storage_type.element_size) + " bytes");
      }
      storage = storages.emplace(t.storage_key, zip.read(*entry, inflated[t.storage_key])).first;
    }
    std::vector<uint8_t> data = materialize(where, t, storage->second);  // checks that the dtype is supported
    out.state_dict.add(k->text, *t.storage_type.dtype, t.size, std::move(data));
    out.saved_order.push_back(k->text);
  }
}

}  // namespace

PyTorchCheckpoint read_pytorch_checkpoint(const std::string& path, const std::string& state_dict_key) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail(StatusCode::kNotFound, "PyTorch checkpoint not found: " + path);
  const FileMapping file = FileMapping::open(path);
  const std::span<const uint8_t> bytes(file.data(), file.size());
  PyTorchCheckpoint out;
  out.state_dict = OwnedTensorSet(path);
  std::map<std::string, std::span<const uint8_t>> storages;
  std::vector<uint8_t> pickle_scratch;
  PickleRef root;
  ZipArchive zip;
  std::string prefix;

  if (ZipArchive::looks_like_zip(bytes)) {
    out.format = "zip";
    root = read_zip(path, bytes, pickle_scratch, zip, prefix);
  } else if (bytes.size() >= sizeof kLegacyStart && std::memcmp(bytes.data(), kLegacyStart, sizeof kLegacyStart) == 0) {
    out.format = "legacy";
    root = read_legacy(path, bytes, storages);
  } else {
    fail(StatusCode::kInvalidArgument, path + ": not a PyTorch checkpoint (neither torch.save's zip format nor its legacy format)");
  }
  read_tensors(path, select_state_dict(*root, path, state_dict_key, out), storages, zip, prefix, out);
  return out;
}

}  // namespace act
