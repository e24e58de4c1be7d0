// The safe pickle reader on hand-made pickles: what state dicts use parses; code execution
// constructs, malformed input and resource bombs are refused with an act::Error naming them.
// (Real torch.save files: test/model/test_pytorch_checkpoints.cc.)
#include <gtest/gtest.h>

#include <string>

#include "actengine/status.h"
#include "weights/import/pickle_reader.h"

namespace act {
namespace {

using namespace std::string_literals;

using Kind = PickleValue::Kind;

PickleRef parse(const std::string& bytes, const PickleLimits& limits = {}) {
  return parse_pickle({reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()}, "test.pkl", limits);
}

// Expects parse() to throw act::Error with `code` and a message containing `text`.
void expect_error(const std::string& bytes, StatusCode code, const std::string& text, const PickleLimits& limits = {}) {
  try {
    parse(bytes, limits);
    ADD_FAILURE() << "parsed, expected an error containing '" << text << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

const std::string kProto2 = "\x80\x02";
// BINUNICODE with a 4-byte length (appends only: GCC 12 warns falsely about operator+ here).
std::string unicode(const std::string& s) {
  std::string out = "X";
  out.push_back(static_cast<char>(s.size()));
  out.append(3, '\0');
  out += s;
  return out;
}

TEST(PickleReader, ParsesTheContainersAndScalarsOfAStateDict) {
  // {"epoch": 12, "lr": 0.5, "ok": True, "x": None, "groups": [1, (2, "b")], "neg": -2}
  const std::string p = kProto2 + "}q\x00("s + unicode("epoch") + "K\x0c" + unicode("lr") +
                        std::string("G\x3f\xe0\x00\x00\x00\x00\x00\x00", 9) + unicode("ok") + "\x88" + unicode("x") + "N" +
                        unicode("groups") + "](K\x01K\x02" + unicode("b") + "\x86" + "e" + unicode("neg") +
                        std::string("J\xfe\xff\xff\xff", 5) + "u.";
  const PickleRef v = parse(p);
  ASSERT_EQ(v->kind, Kind::kDict);
  ASSERT_EQ(v->entries.size(), 6u);
  EXPECT_EQ(v->find("epoch")->integer, 12);
  EXPECT_EQ(v->find("lr")->real, 0.5);
  EXPECT_TRUE(v->find("ok")->boolean);
  EXPECT_EQ(v->find("x")->kind, Kind::kNone);
  const PickleValue* groups = v->find("groups");
  ASSERT_EQ(groups->kind, Kind::kList);
  ASSERT_EQ(groups->items.size(), 2u);
  EXPECT_EQ(groups->items[1]->kind, Kind::kTuple);
  EXPECT_EQ(groups->items[1]->items[1]->text, "b");
  EXPECT_EQ(v->find("neg")->integer, -2);
  EXPECT_EQ(v->depth, 4);
}

TEST(PickleReader, OrderedDictWithMetadataAndMemoReuse) {
  // OrderedDict() with a _metadata state set by BUILD; the memoised key is fetched again.
  const std::string p = kProto2 + "ccollections\nOrderedDict\nq\x00)Rq\x01"s + unicode("k") + "q\x02K\x07s" + "}" +
                        unicode("_metadata") + "h\x00)Rs"s + "b.";
  const PickleRef v = parse(p);
  ASSERT_EQ(v->kind, Kind::kDict);
  ASSERT_EQ(v->entries.size(), 1u);
  EXPECT_EQ(v->find("k")->integer, 7);
}

TEST(PickleReader, LaterValueWinsForARepeatedKey) {
  const std::string p = kProto2 + "}(" + unicode("a") + "K\x01" + unicode("a") + "K\x02u.";
  const PickleRef v = parse(p);
  ASSERT_EQ(v->entries.size(), 1u);
  EXPECT_EQ(v->find("a")->integer, 2);
}

TEST(PickleReader, BytesThroughCodecsEncode) {
  const std::string p = kProto2 + "c_codecs\nencode\n" + unicode("a\xc3\xbf") + unicode("latin1") + "\x86R.";
  const PickleRef v = parse(p);
  ASSERT_EQ(v->kind, Kind::kBytes);
  EXPECT_EQ(v->text, std::string("a\xff"));
}

TEST(PickleReader, RefusesGlobalsOutsideTheWhitelistByName) {
  expect_error(kProto2 + "cposix\nsystem\nq\x00"s + unicode("touch x") + "\x85R.", StatusCode::kUnimplemented,
               "GLOBAL 'posix.system' is not allowed");
  expect_error(kProto2 + "cbuiltins\neval\n.", StatusCode::kUnimplemented, "'builtins.eval'");
  expect_error(kProto2 + "ctorch\nload\n.", StatusCode::kUnimplemented, "'torch.load'");
  // Protocol 4's STACK_GLOBAL takes the names from the stack.
  expect_error("\x80\x04\x8c\x02os\x94\x8c\x06system\x94\x93.", StatusCode::kUnimplemented, "GLOBAL 'os.system'");
}

TEST(PickleReader, RefusesReduceOnAnythingButTheWhitelistedCallables) {
  expect_error(kProto2 + unicode("os.system") + ")R.", StatusCode::kDataLoss, "REDUCE on a str 'os.system'");
  expect_error(kProto2 + "ctorch\nFloatStorage\n)R.", StatusCode::kUnimplemented, "REDUCE calling torch.FloatStorage");
  expect_error(kProto2 + "ccollections\nOrderedDict\n]\x85R.", StatusCode::kUnimplemented, "OrderedDict(...) with arguments");
  expect_error(kProto2 + "ctorch._utils\n_rebuild_tensor_v2\n)R.", StatusCode::kDataLoss, "takes 6 or 7 arguments");
}

TEST(PickleReader, RefusesObjectConstructionOpcodes) {
  expect_error(kProto2 + "ccollections\nOrderedDict\n)\x81.", StatusCode::kUnimplemented, "NEWOBJ");
  expect_error("(i__builtin__\nobject\n.", StatusCode::kUnimplemented, "INST");
  expect_error(kProto2 + "\x8f.", StatusCode::kUnimplemented, "EMPTY_SET");
  expect_error(kProto2 + "\xff.", StatusCode::kDataLoss, "unknown opcode 0xff");
}

TEST(PickleReader, RefusesHugeLengthsBeforeAllocating) {
  expect_error(kProto2 + std::string("X\xf0\xff\xff\xff", 5) + "abc.", StatusCode::kDataLoss, "length 4294967280 runs past the end");
  expect_error(kProto2 + std::string("\x8d\xff\xff\xff\xff\xff\xff\xff\x7f", 9) + ".", StatusCode::kDataLoss, "runs past the end");
  expect_error(kProto2 + std::string("B\xff\xff\xff\x7f", 5) + ".", StatusCode::kDataLoss, "runs past the end");
  expect_error(kProto2 + std::string("\x8b\xff\xff\xff\x7f", 5) + ".", StatusCode::kDataLoss, "runs past the end");
  expect_error(kProto2 + std::string("\x8b\xff\xff\xff\xff", 5) + ".", StatusCode::kDataLoss, "negative length");
}

TEST(PickleReader, BoundsTheMemo) {
  expect_error(kProto2 + "h\x05.", StatusCode::kDataLoss, "memo entry 5 was never stored");
  expect_error(kProto2 + std::string("j\xff\xff\xff\xff", 5) + ".", StatusCode::kDataLoss, "memo entry 4294967295");
  PickleLimits small;
  small.max_memo = 2;
  expect_error(kProto2 + "Nq\x00q\x01q\x02."s, StatusCode::kDataLoss, "more than 2 memo entries", small);
  // Overwriting an existing index is no growth.
  EXPECT_EQ(parse(kProto2 + "Nq\x00q\x01q\x01q\x00."s, small)->kind, Kind::kNone);
}

TEST(PickleReader, BoundsTheNumberOfValues) {
  PickleLimits small;
  small.max_values = 100;
  std::string many = kProto2 + "]";
  for (int i = 0; i < 200; ++i) many += "Na";  // [None, None, ...]
  expect_error(many + ".", StatusCode::kDataLoss, "more than 100 values", small);
}

TEST(PickleReader, BoundsTheNestingDepth) {
  std::string deep = kProto2 + "N";
  for (int i = 0; i < 100000; ++i) deep += "\x85";  // ((((None,),),),...)
  deep += ".";
  expect_error(deep, StatusCode::kDataLoss, "nested deeper than 64");
  std::string ok = kProto2 + "N";
  for (int i = 0; i < 63; ++i) ok += "\x85";
  EXPECT_EQ(parse(ok + ".")->depth, 64);
}

TEST(PickleReader, NoCyclesAndNoChangesAfterAContainerIsPlaced) {
  expect_error(kProto2 + "]2a.", StatusCode::kUnimplemented, "after it was placed");          // l.append(l)
  expect_error(kProto2 + "]q\x00]h\x00"s "a" "a.", StatusCode::kUnimplemented, "placed");        // a in b, then b in a
  expect_error(kProto2 + "}q\x00]h\x00"s "a0h\x00K\x01K\x02s.", StatusCode::kUnimplemented, "SETITEM on a dict");
}

TEST(PickleReader, RefusesMalformedStructure) {
  expect_error(kProto2, StatusCode::kDataLoss, "runs past the end");                 // no STOP
  expect_error(kProto2 + ".", StatusCode::kDataLoss, "0 values on the stack");
  expect_error(kProto2 + "NN.", StatusCode::kDataLoss, "2 values on the stack");
  expect_error(kProto2 + "a.", StatusCode::kDataLoss, "stack underflow");
  expect_error(kProto2 + "N(a.", StatusCode::kDataLoss, "stack underflow");          // APPEND cannot reach below a MARK
  expect_error(kProto2 + "(N.", StatusCode::kDataLoss, "unclosed MARK");
  expect_error(kProto2 + "Nt.", StatusCode::kDataLoss, "no MARK");
  expect_error(kProto2 + "N.junk", StatusCode::kDataLoss, "4 bytes after STOP");
  expect_error(kProto2 + "NNa.", StatusCode::kDataLoss, "APPEND on a None");
  expect_error(kProto2 + "}(K\x01u.", StatusCode::kDataLoss, "odd number");
  expect_error(kProto2 + "}(]K\x01u.", StatusCode::kUnimplemented, "dict key of type list");
  expect_error(kProto2 + "ccollections\nOrderedDict\n.", StatusCode::kDataLoss, "bare global");
  expect_error(kProto2 + "ccollections", StatusCode::kDataLoss, "without a newline");
  expect_error("\x80\x09N.", StatusCode::kDataLoss, "protocol 9");
}

TEST(PickleReader, NeverCrashesOnDamagedInput) {
  // Every truncation and every single-byte change of a valid state-dict-like pickle either parses
  // or throws act::Error (the sanitizer build checks the "never crashes" part).
  const std::string valid = kProto2 + "ccollections\nOrderedDict\nq\x00)Rq\x01("s + unicode("w") +
                            "ctorch._utils\n_rebuild_tensor_v2\nq\x02((" + unicode("storage") +
                            "ctorch\nFloatStorage\n" + unicode("0") + unicode("cpu") + "K\x06tQK\x00K\x02K\x03\x86K\x03K\x01\x86\x89h\x00)Rtq\x03R"s +
                            "u}" + unicode("_metadata") + "h\x00)Rsb."s;
  const PickleRef v = parse(valid);
  ASSERT_EQ(v->kind, Kind::kDict);
  ASSERT_EQ(v->find("w")->kind, Kind::kTensor);
  EXPECT_EQ(v->find("w")->tensor->size, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(v->find("w")->tensor->stride, (std::vector<int64_t>{3, 1}));
  EXPECT_EQ(v->find("w")->tensor->storage_key, "0");
  size_t parsed = 0, refused = 0;
  for (size_t len = 0; len < valid.size(); ++len) {
    try {
      parse(valid.substr(0, len));
      ++parsed;
    } catch (const Error&) {
      ++refused;
    }
  }
  for (size_t i = 0; i < valid.size(); ++i) {
    for (int delta : {1, 0x40, 0x80, 0xff}) {
      std::string damaged = valid;
      damaged[i] = static_cast<char>(static_cast<uint8_t>(damaged[i]) + delta);
      try {
        parse(damaged);
        ++parsed;
      } catch (const Error&) {
        ++refused;
      }
    }
  }
  EXPECT_GT(refused, valid.size());
}

}  // namespace
}  // namespace act
