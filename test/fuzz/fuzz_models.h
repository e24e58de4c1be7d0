// The model the observation-file fuzz target and its seed writer share.
#pragma once

#include "actengine/engine.h"

namespace act::fuzz {

inline ModelInfo observation_model() {
  ModelInfo m;
  m.cameras = {{"observation.images.front", 4, 6}};
  m.state_dim = 2;
  m.env_state_dim = 3;
  m.env_state_key = "observation.environment_state";
  m.action_dim = 2;
  m.chunk_size = 3;
  m.n_action_steps = 3;
  return m;
}

}  // namespace act::fuzz
