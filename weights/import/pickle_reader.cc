#include "weights/import/pickle_reader.h"

#include <algorithm>
#include <cstring>
#include <unordered_map>

#include "actengine/status.h"

namespace act {

namespace {

using Kind = PickleValue::Kind;
using MutableRef = std::shared_ptr<PickleValue>;

// The storage classes torch.save names (torch/storage.py); those without a DType parse, but
// reading their data is refused later with the type's name.
struct StorageTypeInfo {
  const char* name;
  std::optional<DType> dtype;
  size_t element_size;
};
constexpr StorageTypeInfo kStorageTypes[] = {
    {"FloatStorage", DType::kF32, 4}, {"DoubleStorage", DType::kF64, 8}, {"HalfStorage", DType::kF16, 2},
    {"BFloat16Storage", DType::kBF16, 2}, {"LongStorage", DType::kI64, 8}, {"IntStorage", DType::kI32, 4},
    {"CharStorage", DType::kI8, 1}, {"ByteStorage", DType::kU8, 1}, {"ShortStorage", std::nullopt, 2},
    {"BoolStorage", std::nullopt, 1},
};

constexpr const char* kAllowedGlobals =
    "collections.OrderedDict, torch._utils._rebuild_tensor_v2, torch._utils._rebuild_parameter, "
    "torch.<type>Storage, _codecs.encode";

// Printable form of untrusted text for messages: at most 80 characters, control bytes escaped.
std::string printable(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size() && i < 80; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      static const char* kHex = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  if (s.size() > 80) out += "...";
  return out;
}

// Names of the opcodes this reader refuses, for a message better than a byte value.
const char* opcode_name(uint8_t op) {
  switch (op) {
    case 'I': return "INT (text protocol)";
    case 'L': return "LONG (text protocol)";
    case 'F': return "FLOAT (text protocol)";
    case 'S': return "STRING (text protocol)";
    case 'V': return "UNICODE (text protocol)";
    case 'P': return "PERSID (text protocol)";
    case 'g': return "GET (text protocol)";
    case 'p': return "PUT (text protocol)";
    case 'i': return "INST (object construction)";
    case 'o': return "OBJ (object construction)";
    case 0x81: return "NEWOBJ (object construction)";
    case 0x92: return "NEWOBJ_EX (object construction)";
    case 0x82: case 0x83: case 0x84: return "EXT (extension registry)";
    case 0x8f: return "EMPTY_SET";
    case 0x90: return "ADDITEMS (set)";
    case 0x91: return "FROZENSET";
    case 0x96: return "BYTEARRAY8";
    case 0x97: return "NEXT_BUFFER (out-of-band data)";
    case 0x98: return "READONLY_BUFFER (out-of-band data)";
    default: return nullptr;
  }
}

class Parser {
 public:
  Parser(std::span<const uint8_t> bytes, const std::string& origin, const PickleLimits& limits)
      : in_(bytes), origin_(origin), limits_(limits) {}

  PickleRef run(size_t* consumed) {
    while (true) {
      op_pos_ = pos_;
      const uint8_t op = read_u8();
      if (op == '.') break;
      step(op);
    }
    if (!marks_.empty()) error("STOP with an unclosed MARK");
    if (stack_.size() != 1) error("STOP with " + std::to_string(stack_.size()) + " values on the stack (expected 1)");
    if (consumed) {
      *consumed = pos_;
    } else if (pos_ != in_.size()) {
      error(std::to_string(in_.size() - pos_) + " bytes after STOP");
    }
    if (stack_.back()->kind == Kind::kGlobal || stack_.back()->kind == Kind::kPersistentId) {
      error("the pickle's result is a bare " + stack_.back()->describe());
    }
    return stack_.back();
  }

 private:
  [[noreturn]] void error(const std::string& what) const {
    fail(StatusCode::kDataLoss, origin_ + ": pickle byte " + std::to_string(op_pos_) + ": " + what);
  }
  [[noreturn]] void unsupported(const std::string& what) const {
    fail(StatusCode::kUnimplemented, origin_ + ": pickle byte " + std::to_string(op_pos_) + ": " + what +
         " (a PyTorch state dict only needs dicts, lists, tuples, numbers, strings and tensors; this reader "
         "never runs code from a checkpoint)");
  }

  // ---- input
  void need(uint64_t n) const {
    if (n > in_.size() - pos_) {
      error("length " + std::to_string(n) + " runs past the end of the data (" + std::to_string(in_.size() - pos_) +
            " bytes left)");
    }
  }
  uint8_t read_u8() {
    need(1);
    return in_[pos_++];
  }
  uint64_t read_le(size_t n) {
    need(n);
    uint64_t v = 0;
    for (size_t i = 0; i < n; ++i) v |= static_cast<uint64_t>(in_[pos_ + i]) << (8 * i);
    pos_ += n;
    return v;
  }
  std::string read_bytes(uint64_t n) {
    need(n);
    std::string s(reinterpret_cast<const char*>(in_.data() + pos_), static_cast<size_t>(n));
    pos_ += static_cast<size_t>(n);
    return s;
  }
  std::string read_line() {  // GLOBAL's "module\n" and "name\n"
    constexpr size_t kMaxLine = 256;
    for (size_t i = pos_; i < in_.size() && i - pos_ <= kMaxLine; ++i) {
      if (in_[i] == '\n') {
        std::string s(reinterpret_cast<const char*>(in_.data() + pos_), i - pos_);
        pos_ = i + 1;
        return s;
      }
    }
    error("GLOBAL name without a newline within " + std::to_string(kMaxLine) + " bytes");
  }

  // ---- values
  MutableRef make(Kind kind) {
    if (++values_ > limits_.max_values) error("more than " + std::to_string(limits_.max_values) + " values");
    auto v = std::make_shared<PickleValue>();
    v->kind = kind;
    return v;
  }
  void push(MutableRef v) {
    if (stack_.size() + marks_.size() >= limits_.max_stack) error("more than " + std::to_string(limits_.max_stack) + " values on the stack");
    stack_.push_back(std::move(v));
  }
  size_t base() const { return marks_.empty() ? 0 : marks_.back(); }
  MutableRef pop() {
    if (stack_.size() <= base()) error("stack underflow");
    MutableRef v = std::move(stack_.back());
    stack_.pop_back();
    return v;
  }
  MutableRef& top() {
    if (stack_.size() <= base()) error("stack underflow");
    return stack_.back();
  }
  std::vector<MutableRef> pop_to_mark() {
    if (marks_.empty()) error("no MARK to pop to");
    const size_t b = marks_.back();
    marks_.pop_back();
    std::vector<MutableRef> items(std::make_move_iterator(stack_.begin() + static_cast<ptrdiff_t>(b)),
                                  std::make_move_iterator(stack_.end()));
    stack_.resize(b);
    return items;
  }

  // A value placed inside a container can no longer change: the graph stays acyclic and depths stay exact.
  void place(PickleValue& container, const MutableRef& element) {
    if (element->kind == Kind::kGlobal || element->kind == Kind::kPersistentId) {
      if (container.kind != Kind::kTuple) unsupported("a " + element->describe() + " stored inside a " + container.describe());
    }
    element->sealed = true;
    dict_index_.erase(element.get());
    if (container.sealed) unsupported("modifying a " + container.describe() + " after it was placed in another container");
    container.depth = std::max(container.depth, element->depth + 1);
    if (static_cast<size_t>(container.depth) > limits_.max_depth) {
      error("containers nested deeper than " + std::to_string(limits_.max_depth));
    }
  }
  MutableRef make_tuple(std::vector<MutableRef> items) {
    MutableRef t = make(Kind::kTuple);
    for (const auto& item : items) place(*t, item);
    t->items.assign(items.begin(), items.end());
    return t;
  }
  MutableRef& mutable_container(MutableRef& v, Kind kind, const char* op) {
    if (v->kind != kind) error(std::string(op) + " on a " + v->describe());
    if (v->sealed) unsupported(std::string(op) + " on a " + v->describe() + " already placed in another container");
    return v;
  }
  void append(MutableRef& list, MutableRef item) {
    place(*list, item);
    list->items.push_back(std::move(item));
  }

  std::string dict_key(const PickleValue& key) const {
    switch (key.kind) {
      case Kind::kString: return "s" + key.text;
      case Kind::kBytes: return "y" + key.text;
      case Kind::kInt: return "i" + std::to_string(key.integer);
      case Kind::kBool: return key.boolean ? "i1" : "i0";  // Python: True == 1 as a key
      case Kind::kNone: return "n";
      default: unsupported("a dict key of type " + key.describe());
    }
  }
  void set_item(MutableRef& dict, MutableRef key, MutableRef value) {
    const std::string k = dict_key(*key);
    place(*dict, key);
    place(*dict, value);
    auto& index = dict_index_[dict.get()];
    if (!index.owner) index.owner = dict;
    const auto [it, inserted] = index.positions.emplace(k, dict->entries.size());
    if (inserted) {
      dict->entries.emplace_back(std::move(key), std::move(value));
    } else {
      dict->entries[it->second].second = std::move(value);  // Python keeps the last value
    }
  }

  int64_t checked_int(const MutableRef& v, const char* what) const {
    if (v->kind == Kind::kInt) return v->integer;
    if (v->kind == Kind::kBool) return v->boolean ? 1 : 0;
    error(std::string(what) + " must be an int, got " + v->describe());
  }

  MutableRef make_int_from_le(const std::string& bytes) {
    MutableRef v = make(Kind::kInt);
    if (bytes.size() > 8) {
      v->kind = Kind::kBigInt;
      v->text = bytes;
      return v;
    }
    uint64_t u = 0;
    for (size_t i = 0; i < bytes.size(); ++i) u |= static_cast<uint64_t>(static_cast<uint8_t>(bytes[i])) << (8 * i);
    if (!bytes.empty() && bytes.size() < 8 && (static_cast<uint8_t>(bytes.back()) & 0x80)) {
      u |= ~uint64_t{0} << (8 * bytes.size());  // sign-extend
    }
    v->integer = static_cast<int64_t>(u);
    return v;
  }

  MutableRef resolve_global(const std::string& module, const std::string& name) {
    const std::string full = module + "." + name;
    MutableRef g = make(Kind::kGlobal);
    g->text = full;
    if (full == "collections.OrderedDict" || full == "torch._utils._rebuild_tensor_v2" ||
        full == "torch._utils._rebuild_parameter" || full == "_codecs.encode") {
      return g;
    }
    if (module == "torch") {
      for (const auto& t : kStorageTypes) {
        if (name == t.name) return g;
      }
    }
    unsupported("GLOBAL '" + printable(full) + "' is not allowed (allowed: " + kAllowedGlobals + ")");
  }

  static std::optional<PickleStorageType> storage_type_of(const PickleValue& v) {
    if (v.kind != Kind::kGlobal || v.text.rfind("torch.", 0) != 0) return std::nullopt;
    const std::string name = v.text.substr(6);
    for (const auto& t : kStorageTypes) {
      if (name == t.name) return PickleStorageType{name, t.dtype, t.element_size};
    }
    return std::nullopt;
  }

  std::vector<int64_t> int_tuple(const MutableRef& v, const char* what) const {
    if (v->kind != Kind::kTuple) error(std::string(what) + " must be a tuple, got " + v->describe());
    if (v->items.size() > limits_.max_tensor_dims) {
      error(std::string(what) + " has " + std::to_string(v->items.size()) + " dimensions (at most " +
            std::to_string(limits_.max_tensor_dims) + ")");
    }
    std::vector<int64_t> out;
    for (const auto& item : v->items) {
      if (item->kind != Kind::kInt || item->integer < 0) error(std::string(what) + " must hold ints >= 0, got " + item->describe());
      out.push_back(item->integer);
    }
    return out;
  }

  // torch._utils._rebuild_tensor_v2(storage, storage_offset, size, stride, requires_grad, backward_hooks[, metadata])
  MutableRef rebuild_tensor(const std::vector<PickleRef>& args) {
    if (args.size() != 6 && args.size() != 7) error("_rebuild_tensor_v2 takes 6 or 7 arguments, got " + std::to_string(args.size()));
    const auto& pid = args[0];
    if (pid->kind != Kind::kPersistentId) error("_rebuild_tensor_v2's storage must be a persistent id, got " + pid->describe());
    const PickleValue& id = *pid->items[0];
    // ('storage', storage_type, key, location, numel[, view_metadata])
    if (id.kind != Kind::kTuple || (id.items.size() != 5 && id.items.size() != 6) || id.items[0]->kind != Kind::kString ||
        id.items[0]->text != "storage") {
      error("persistent id " + id.describe() + " is not ('storage', type, key, location, numel)");
    }
    PickleTensor t;
    const auto type = storage_type_of(*id.items[1]);
    if (!type) error("persistent id's storage type is a " + id.items[1]->describe());
    t.storage_type = *type;
    if (!id.items[2]->is_string() || !id.items[3]->is_string() || id.items[4]->kind != Kind::kInt || id.items[4]->integer < 0) {
      error("persistent id " + id.describe() + " needs a str key, a str location and an int numel >= 0");
    }
    if (id.items.size() == 6 && id.items[5]->kind != Kind::kNone) unsupported("a storage view (legacy view_metadata)");
    t.storage_key = id.items[2]->text;
    t.location = id.items[3]->text;
    t.storage_elements = id.items[4]->integer;
    auto as_mutable = [](const PickleRef& r) { return std::const_pointer_cast<PickleValue>(r); };
    t.offset = checked_int(as_mutable(args[1]), "storage_offset");
    if (t.offset < 0) error("negative storage_offset");
    t.size = int_tuple(as_mutable(args[2]), "tensor size");
    t.stride = int_tuple(as_mutable(args[3]), "tensor stride");
    if (t.size.size() != t.stride.size()) error("tensor size and stride have different lengths");
    if (args[4]->kind != Kind::kBool) error("requires_grad must be a bool, got " + args[4]->describe());
    if (args[5]->kind != Kind::kDict) error("backward_hooks must be a dict, got " + args[5]->describe());
    if (!args[5]->entries.empty()) unsupported("a tensor with backward hooks");
    if (args.size() == 7 && args[6]->kind != Kind::kDict && args[6]->kind != Kind::kNone) {
      error("tensor metadata must be a dict, got " + args[6]->describe());
    }
    MutableRef v = make(Kind::kTensor);
    v->tensor = std::move(t);
    return v;
  }

  // _codecs.encode(text, 'latin1'): how protocol 2 writes bytes objects.
  MutableRef encode_latin1(const std::vector<PickleRef>& args) {
    if (args.size() != 2 || !args[0]->is_string() || !args[1]->is_string() ||
        (args[1]->text != "latin1" && args[1]->text != "latin-1")) {
      unsupported("_codecs.encode other than (str, 'latin1')");
    }
    const std::string& s = args[0]->text;
    MutableRef v = make(Kind::kBytes);
    for (size_t i = 0; i < s.size();) {
      const uint8_t c = static_cast<uint8_t>(s[i]);
      if (c < 0x80) {
        v->text += static_cast<char>(c);
        i += 1;
      } else if ((c == 0xc2 || c == 0xc3) && i + 1 < s.size() && (static_cast<uint8_t>(s[i + 1]) & 0xc0) == 0x80) {
        v->text += static_cast<char>(((c & 0x1f) << 6) | (static_cast<uint8_t>(s[i + 1]) & 0x3f));
        i += 2;
      } else {
        error("_codecs.encode: text is not latin-1");
      }
    }
    return v;
  }

  void reduce() {
    MutableRef args = pop();
    MutableRef callable = pop();
    if (callable->kind != Kind::kGlobal) error("REDUCE on a " + callable->describe() + " (not a callable)");
    if (args->kind != Kind::kTuple) error("REDUCE arguments must be a tuple, got " + args->describe());
    const std::string& f = callable->text;
    const auto& a = args->items;
    if (f == "collections.OrderedDict") {
      if (!a.empty()) unsupported("OrderedDict(...) with arguments");
      push(make(Kind::kDict));
    } else if (f == "torch._utils._rebuild_tensor_v2") {
      push(rebuild_tensor(a));
    } else if (f == "torch._utils._rebuild_parameter") {
      // (data, requires_grad, backward_hooks): an nn.Parameter is its tensor here.
      if (a.size() != 3 || a[0]->kind != Kind::kTensor) error("_rebuild_parameter needs (tensor, requires_grad, hooks)");
      push(std::const_pointer_cast<PickleValue>(a[0]));
    } else if (f == "_codecs.encode") {
      push(encode_latin1(a));
    } else {
      unsupported("REDUCE calling " + printable(f));
    }
  }

  void build() {
    MutableRef state = pop();
    MutableRef& obj = top();
    // OrderedDict state dicts carry a `_metadata` attribute (module versions): kept out of the result.
    if (obj->kind != Kind::kDict) unsupported("BUILD (setting object state) on a " + obj->describe());
    if (state->kind != Kind::kDict && state->kind != Kind::kNone) unsupported("BUILD with a " + state->describe() + " state");
    mutable_container(obj, Kind::kDict, "BUILD");
  }

  // Opcodes that push one scalar: None, booleans, integers, floats, strings and bytes. False
  // when `op` is not one of them.
  bool push_scalar(uint8_t op) {
    switch (op) {
      case 'N': push(make(Kind::kNone)); return true;
      case 0x88: case 0x89: {
        MutableRef v = make(Kind::kBool);
        v->boolean = op == 0x88;
        push(std::move(v));
        return true;
      }
      case 'J': {
        MutableRef v = make(Kind::kInt);
        v->integer = static_cast<int32_t>(static_cast<uint32_t>(read_le(4)));
        push(std::move(v));
        return true;
      }
      case 'K': case 'M': {
        MutableRef v = make(Kind::kInt);
        v->integer = static_cast<int64_t>(read_le(op == 'K' ? 1 : 2));
        push(std::move(v));
        return true;
      }
      case 0x8a: push(make_int_from_le(read_bytes(read_le(1)))); return true;  // LONG1
      case 0x8b: {  // LONG4
        const int64_t n = static_cast<int32_t>(static_cast<uint32_t>(read_le(4)));
        if (n < 0) error("LONG4 with a negative length");
        push(make_int_from_le(read_bytes(static_cast<uint64_t>(n))));
        return true;
      }
      case 'G': {  // BINFLOAT: big-endian IEEE double
        need(8);
        uint64_t bits = 0;
        for (int i = 0; i < 8; ++i) bits = (bits << 8) | in_[pos_ + static_cast<size_t>(i)];
        pos_ += 8;
        MutableRef v = make(Kind::kFloat);
        std::memcpy(&v->real, &bits, sizeof bits);
        push(std::move(v));
        return true;
      }
      case 0x8c: case 'X': case 0x8d:  // SHORT_BINUNICODE, BINUNICODE, BINUNICODE8
      case 'U': case 'T': {            // SHORT_BINSTRING, BINSTRING (protocol <= 2 str, read as text)
        const size_t len_bytes = (op == 0x8c || op == 'U') ? 1 : (op == 0x8d ? 8 : 4);
        MutableRef v = make(Kind::kString);
        v->text = read_bytes(read_le(len_bytes));
        push(std::move(v));
        return true;
      }
      case 'C': case 'B': case 0x8e: {  // SHORT_BINBYTES, BINBYTES, BINBYTES8
        const size_t len_bytes = op == 'C' ? 1 : (op == 'B' ? 4 : 8);
        MutableRef v = make(Kind::kBytes);
        v->text = read_bytes(read_le(len_bytes));
        push(std::move(v));
        return true;
      }
      default: return false;
    }
  }

  // Opcodes that make or fill a tuple, list or dict. False when `op` is not one of them.
  bool build_container(uint8_t op) {
    switch (op) {
      case ')': push(make(Kind::kTuple)); return true;
      case 't': push(make_tuple(pop_to_mark())); return true;
      case 0x85: case 0x86: case 0x87: {  // TUPLE1..3
        const size_t n = static_cast<size_t>(op - 0x84);
        std::vector<MutableRef> items(n);
        for (size_t i = n; i-- > 0;) items[i] = pop();
        push(make_tuple(std::move(items)));
        return true;
      }
      case ']': push(make(Kind::kList)); return true;
      case 'l': {  // LIST
        MutableRef list = make(Kind::kList);
        for (auto& item : pop_to_mark()) append(list, std::move(item));
        push(std::move(list));
        return true;
      }
      case 'a': {
        MutableRef item = pop();
        append(mutable_container(top(), Kind::kList, "APPEND"), std::move(item));
        return true;
      }
      case 'e': {
        std::vector<MutableRef> items = pop_to_mark();
        MutableRef& list = mutable_container(top(), Kind::kList, "APPENDS");
        for (auto& item : items) append(list, std::move(item));
        return true;
      }
      case '}': push(make(Kind::kDict)); return true;
      case 'd': {  // DICT
        std::vector<MutableRef> items = pop_to_mark();
        if (items.size() % 2 != 0) error("DICT with an odd number of items");
        MutableRef dict = make(Kind::kDict);
        for (size_t i = 0; i < items.size(); i += 2) set_item(dict, std::move(items[i]), std::move(items[i + 1]));
        push(std::move(dict));
        return true;
      }
      case 's': {
        MutableRef value = pop();
        MutableRef key = pop();
        set_item(mutable_container(top(), Kind::kDict, "SETITEM"), std::move(key), std::move(value));
        return true;
      }
      case 'u': {
        std::vector<MutableRef> items = pop_to_mark();
        if (items.size() % 2 != 0) error("SETITEMS with an odd number of items");
        MutableRef& dict = mutable_container(top(), Kind::kDict, "SETITEMS");
        for (size_t i = 0; i < items.size(); i += 2) set_item(dict, std::move(items[i]), std::move(items[i + 1]));
        return true;
      }
      default: return false;
    }
  }

  // Runs one opcode: scalars and containers by kind, then framing, the stack, the memo and
  // objects (globals, calls, persistent ids) here.
  void step(uint8_t op) {
    if (push_scalar(op) || build_container(op)) return;
    switch (op) {
      case 0x80: {  // PROTO
        const uint8_t proto = read_u8();
        if (proto > 5) error("pickle protocol " + std::to_string(proto) + " is unknown");
        break;
      }
      case 0x95: read_le(8); break;  // FRAME: a framing hint only
      case '(':
        if (stack_.size() + marks_.size() >= limits_.max_stack) error("too many MARKs");
        marks_.push_back(stack_.size());
        break;
      case '0': pop(); break;
      case '1': pop_to_mark(); break;
      case '2': push(top()); break;
      case 'q': memo_put(read_le(1)); break;
      case 'r': memo_put(read_le(4)); break;
      case 0x94: memo_put(memo_.size()); break;  // MEMOIZE
      case 'h': memo_get(read_le(1)); break;
      case 'j': memo_get(read_le(4)); break;
      case 'c': {  // GLOBAL "module\nname\n"
        const std::string module = read_line();
        const std::string name = read_line();
        push(resolve_global(module, name));
        break;
      }
      case 0x93: {  // STACK_GLOBAL
        MutableRef name = pop();
        MutableRef module = pop();
        if (!module->is_string() || !name->is_string()) error("STACK_GLOBAL needs two strings");
        push(resolve_global(module->text, name->text));
        break;
      }
      case 'R': reduce(); break;
      case 'b': build(); break;
      case 'Q': {  // BINPERSID
        MutableRef id = pop();
        MutableRef pid = make(Kind::kPersistentId);
        place(*pid, id);
        pid->items.push_back(std::move(id));
        push(std::move(pid));
        break;
      }
      default: {
        const char* name = opcode_name(op);
        if (name) unsupported(std::string("opcode ") + name);
        error("unknown opcode 0x" + [&] {
          static const char* kHex = "0123456789abcdef";
          return std::string{kHex[op >> 4], kHex[op & 15]};
        }());
      }
    }
  }

  void memo_put(uint64_t index) {
    if (memo_.size() >= limits_.max_memo && memo_.count(index) == 0) error("more than " + std::to_string(limits_.max_memo) + " memo entries");
    memo_[index] = top();
  }
  void memo_get(uint64_t index) {
    const auto it = memo_.find(index);
    if (it == memo_.end()) error("memo entry " + std::to_string(index) + " was never stored");
    push(it->second);
  }

  std::span<const uint8_t> in_;
  const std::string& origin_;
  const PickleLimits& limits_;
  size_t pos_ = 0;
  size_t op_pos_ = 0;
  size_t values_ = 0;
  std::vector<MutableRef> stack_;
  std::vector<size_t> marks_;  // stack sizes at each MARK
  std::unordered_map<uint64_t, MutableRef> memo_;
  struct DictIndex {
    MutableRef owner;  // keeps the dict alive while indexed, so its address is never reused meanwhile
    std::unordered_map<std::string, size_t> positions;
  };
  std::unordered_map<const PickleValue*, DictIndex> dict_index_;  // dicts still being filled
};

}  // namespace

const PickleValue* PickleValue::find(const std::string& key) const {
  for (const auto& [k, v] : entries) {
    if (k->kind == Kind::kString && k->text == key) return v.get();
  }
  return nullptr;
}

std::string PickleValue::describe() const {
  switch (kind) {
    case Kind::kNone: return "None";
    case Kind::kBool: return boolean ? "bool True" : "bool False";
    case Kind::kInt: return "int " + std::to_string(integer);
    case Kind::kBigInt: return "int of " + std::to_string(text.size()) + " bytes";
    case Kind::kFloat: return "float " + std::to_string(real);
    case Kind::kString: return "str '" + printable(text) + "'";
    case Kind::kBytes: return "bytes of length " + std::to_string(text.size());
    case Kind::kTuple: return "tuple (" + std::to_string(items.size()) + " items)";
    case Kind::kList: return "list (" + std::to_string(items.size()) + " items)";
    case Kind::kDict: return "dict (" + std::to_string(entries.size()) + " entries)";
    case Kind::kGlobal: return "global " + printable(text);
    case Kind::kPersistentId: return "persistent id";
    case Kind::kTensor: return "tensor " + shape_string(tensor->size) + " " + tensor->storage_type.name;
  }
  return "?";
}

PickleRef parse_pickle(std::span<const uint8_t> bytes, const std::string& origin, const PickleLimits& limits,
                       size_t* consumed) {
  return Parser(bytes, origin, limits).run(consumed);
}

}  // namespace act
