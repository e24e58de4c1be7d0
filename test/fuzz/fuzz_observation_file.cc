// libFuzzer target: act_eval's observation reader (a safetensors file checked against a model's
// inputs). The model is a small fixed one (a camera, robot and environment state) so that valid
// inputs stay a few hundred bytes.
#include "actengine/status.h"
#include "engine/src/convert/observation_file.h"
#include "test/fuzz/fuzz_input_file.h"
#include "test/fuzz/fuzz_models.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static act::fuzz::InputFile input;
  static const act::ModelInfo model = act::fuzz::observation_model();
  for (const act::ImageSource source : {act::ImageSource::kAuto, act::ImageSource::kU8}) {
    try {
      const act::ObservationBatch batch = act::ObservationBatch::read(input.write(data, size), model, source);
      for (size_t i = 0; i < batch.size(); ++i) {
        const act::Observation obs = batch.at(i);
        const auto& cam = model.cameras[0];
        const size_t image_bytes = static_cast<size_t>(cam.height) * cam.width * 3 *
                                   (batch.uses_u8_images(0) ? 1 : sizeof(float));
        act::fuzz::touch(static_cast<const uint8_t*>(obs.images[0].data), image_bytes);
        act::fuzz::touch(reinterpret_cast<const uint8_t*>(obs.state.data()), obs.state.size_bytes());
        act::fuzz::touch(reinterpret_cast<const uint8_t*>(obs.env_state.data()), obs.env_state.size_bytes());
        if (const float* expected = batch.expected_actions(i)) {
          act::fuzz::touch(reinterpret_cast<const uint8_t*>(expected), model.chunk_values() * sizeof(float));
        }
      }
    } catch (const act::Error&) {
    }
  }
  return 0;
}
