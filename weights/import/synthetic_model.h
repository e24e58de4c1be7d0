// Built-in synthetic ACT models: a LeRobot config and a state dict with deterministic random weights
// of realistic scale, generated in-process, so act_bench shows numbers with nothing to download.
// They go through the same import (BN folding, constant folding) as a real checkpoint.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "weights/import/lerobot_import.h"
#include "weights/import/safetensors.h"

namespace act {

/// The LeRobot config.json content of a built-in model:
///  - "default": LeRobot's default ACT (resnet18, D 512, 8 heads, FFN 3200, 4+1 layers, chunk 100),
///    one 480x640 camera, state 6, action 6;
///  - "rover":   the same network on one 360x640 camera, state 2, action 2 (steering, throttle);
///  - "HxW" (e.g. "240x320": 240 high, 320 wide; height first, as everywhere): the default network on
///    one camera of that size.
/// Throws act::Error(kInvalidArgument) for anything else.
nlohmann::ordered_json synthetic_config(const std::string& name);

/// A legacy-layout state dict (normalisation buffers included) for `config`, from `seed`.
/// Convs: Kaiming-normal; FrozenBatchNorm: statistics near the identity, with the last BN of each
/// residual branch damped so activations stay O(1) through the network; transformer: Xavier-uniform
/// weights, small biases, LayerNorm near the identity; positional embeddings N(0, 1).
/// The random numbers are platform-independent (mt19937 + our own transforms).
OwnedTensorSet synthetic_state_dict(const nlohmann::ordered_json& config, uint32_t seed = 1);

/// synthetic_config + synthetic_state_dict + import.
ImportedModel make_synthetic_model(const std::string& name, uint32_t seed = 1);

}  // namespace act
