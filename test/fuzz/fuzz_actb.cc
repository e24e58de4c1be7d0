// libFuzzer target: the .actb blob loader, the range checks of the stored numbers, the parsers of
// the blob's JSON config (model and quantization sections) and their cross-check with the tensors
// (blob_model_config, which checks the numbers first, whatever the config), as Engine::open runs them. The checksum is skipped for most inputs (the first byte decides) so that mutations
// reach the header and tensor-directory checks behind it. (The check that the network reads every
// tensor needs a whole model, megabytes, beyond the inputs a fuzzer mutates.)
#include "actengine/status.h"
#include "test/fuzz/fuzz_input_file.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_tensors.h"
#include "weights/blob/quant_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static act::fuzz::InputFile input;
  const bool verify_checksum = size > 0 && data[0] % 8 == 0;
  try {
    const act::ActbFile blob = act::ActbFile::open(input.write(data, size), verify_checksum);
    for (const act::ActbTensor& t : blob.tensors()) {
      act::fuzz::touch(t.data, t.nbytes);
      if (t.dtype == act::DType::kF32) (void)t.f32();
    }
    // Each section on its own, so that a bad model section does not hide the quantization one.
    try {
      (void)act::blob_model_config(blob);
    } catch (const act::Error&) {
    }
    if (blob.config().contains("quantization")) (void)act::QuantConfig::from_json(blob.config()["quantization"]);
  } catch (const act::Error&) {  // a clear error is the expected outcome for bad input
  }
  return 0;
}
