// libFuzzer target: the safetensors reader (header, dtypes, offsets) and the float conversions.
#include "actengine/status.h"
#include "test/fuzz/fuzz_input_file.h"
#include "weights/import/safetensors.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static act::fuzz::InputFile input;
  try {
    const act::SafetensorsFile file = act::SafetensorsFile::open(input.write(data, size));
    for (const std::string& name : file.names()) {
      const act::SafetensorsTensor& t = file.get(name);
      act::fuzz::touch(t.data, t.nbytes);
      try {
        (void)t.to_f32();
      } catch (const act::Error&) {  // a dtype without a float conversion
      }
    }
  } catch (const act::Error&) {  // a clear error is the expected outcome for bad input
  }
  return 0;
}
