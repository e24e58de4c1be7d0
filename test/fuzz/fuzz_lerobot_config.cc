// libFuzzer target: LeRobot's config.json (architecture, features, normalisation mapping) and the
// processor pipeline JSON (policy_preprocessor.json / policy_postprocessor.json). Each input is
// tried as both; JSON that does not parse is the JSON library's business, not ours.
#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "weights/import/lerobot_import.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto json = nlohmann::ordered_json::parse(data, data + size, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded()) return 0;
  try {
    (void)act::lerobot_model_config(json, "config.json");
  } catch (const act::Error&) {
  }
  for (const char* step : {"normalizer_processor", "unnormalizer_processor"}) {
    try {
      (void)act::parse_processor_step(json, step, "policy_processor.json");
    } catch (const act::Error&) {
    }
  }
  return 0;
}
