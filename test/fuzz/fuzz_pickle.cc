// libFuzzer target: the PyTorch .pth reader — the zip archive and legacy formats through
// read_pytorch_checkpoint, and the same bytes as one bare pickle through the safe pickle reader.
#include <span>

#include "actengine/status.h"
#include "test/fuzz/fuzz_input_file.h"
#include "weights/import/pickle_reader.h"
#include "weights/import/pytorch_checkpoint.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static act::fuzz::InputFile input;
  try {
    const act::PyTorchCheckpoint checkpoint = act::read_pytorch_checkpoint(input.write(data, size));
    for (const std::string& name : checkpoint.state_dict.names()) {
      const act::SafetensorsTensor& t = checkpoint.state_dict.get(name);
      act::fuzz::touch(t.data, t.nbytes);
    }
  } catch (const act::Error&) {
  }
  try {
    (void)act::parse_pickle(std::span<const uint8_t>(data, size), "fuzz.pkl");
  } catch (const act::Error&) {
  }
  return 0;
}
