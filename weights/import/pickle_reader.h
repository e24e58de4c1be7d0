// A safe reader for the subset of Python's pickle format that PyTorch state dicts use.
//
// Nothing is ever executed: the reader builds a tree of plain values. The only callables a pickle
// may name are a fixed whitelist (collections.OrderedDict, torch._utils._rebuild_tensor_v2 and
// _rebuild_parameter, the torch.*Storage types as storage tags, _codecs.encode for byte strings),
// and each is interpreted, not called. Any other GLOBAL / STACK_GLOBAL, any other opcode, and any
// malformed input is an act::Error(kDataLoss / kUnimplemented) naming the construct and its byte
// offset. Every length is checked against the remaining input before anything is allocated, memo
// indices and the nesting depth are bounded, and a container stops being mutable once it is placed
// inside another one, so the value graph is acyclic and its depth is known (real pickles fill each
// container before they use it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "weights/blob/tensor_types.h"

namespace act {

/// A torch.*Storage class named by a pickle: the element type of a storage.
struct PickleStorageType {
  std::string name;              ///< e.g. "FloatStorage"
  std::optional<DType> dtype;    ///< nullopt for types this project does not read (Bool, Short, ...)
  size_t element_size = 0;
};

/// What torch._utils._rebuild_tensor_v2 describes: a strided view of a storage.
struct PickleTensor {
  std::string storage_key;  ///< the storage's name in the checkpoint (zip: data/<key>)
  PickleStorageType storage_type;
  std::string location;      ///< e.g. "cpu", "cuda:0" (informational)
  int64_t storage_elements = 0;
  int64_t offset = 0;  ///< in elements
  std::vector<int64_t> size;
  std::vector<int64_t> stride;
};

struct PickleValue;
using PickleRef = std::shared_ptr<const PickleValue>;

struct PickleValue {
  enum class Kind {
    kNone, kBool, kInt, kBigInt, kFloat, kString, kBytes,
    kTuple, kList, kDict,
    kGlobal,        ///< a whitelisted callable or storage type (internal: never a finished value's leaf)
    kPersistentId,  ///< BINPERSID's result: items[0] is the id
    kTensor,
  };
  Kind kind = Kind::kNone;
  bool boolean = false;
  int64_t integer = 0;
  double real = 0.0;
  std::string text;  ///< kString / kBytes; kBigInt: little-endian two's complement bytes; kGlobal: "module.name"
  std::vector<PickleRef> items;                        ///< kTuple / kList / kPersistentId
  std::vector<std::pair<PickleRef, PickleRef>> entries;  ///< kDict, insertion order, keys unique
  std::optional<PickleTensor> tensor;                  ///< kTensor
  int depth = 1;  ///< 1 for a leaf, 1 + deepest element for a container
  bool sealed = false;  ///< the reader's bookkeeping: placed inside a container, so no longer mutable

  bool is_string() const { return kind == Kind::kString; }
  /// The value of a dict entry with this string key, or nullptr.
  const PickleValue* find(const std::string& key) const;
  /// A short description for messages: "dict (3 entries)", "int 12", "str 'abc'", "tensor [2, 3] FloatStorage".
  std::string describe() const;
};

struct PickleLimits {
  size_t max_depth = 64;          ///< nesting of containers (state dicts need about 6)
  size_t max_memo = 1u << 24;     ///< memo entries
  size_t max_stack = 1u << 24;    ///< values on the stack plus marks
  size_t max_tensor_dims = 16;
  size_t max_values = 1u << 20;   ///< values created (bounds memory: a state dict needs ~20 per tensor)
};

/// Parses one pickle that must end with STOP. `origin` names it in messages (e.g. "model.pth: data.pkl").
/// If `consumed` is given the pickle may be followed by more bytes and *consumed receives its length
/// (the legacy .pth format is a sequence of pickles); otherwise trailing bytes are an error.
PickleRef parse_pickle(std::span<const uint8_t> bytes, const std::string& origin, const PickleLimits& limits = {},
                       size_t* consumed = nullptr);

}  // namespace act
