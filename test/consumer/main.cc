// consumer BLOB: opens the blob with the installed libactengine, runs one zero observation, takes
// tick 0's action through the chunk scheduler and prints the first action. Exits non-zero on any failure, including a non-finite action.
#include <actengine/engine.h>
#include <actengine/scheduler.h>

#include <cmath>
#include <cstdio>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: consumer MODEL.actb\n");
    return 2;
  }
  auto bad = act::Engine::open("/nonexistent/model.actb");
  if (bad.ok() || bad.status().code() != act::StatusCode::kNotFound) {
    std::fprintf(stderr, "expected a not-found error for a missing blob\n");
    return 1;
  }
  auto engine = act::Engine::open(argv[1], {.threads = 1});
  if (!engine.ok()) {
    std::fprintf(stderr, "%s\n", engine.status().to_string().c_str());
    return 1;
  }
  const act::ModelInfo& info = (*engine)->model_info();
  std::vector<std::vector<uint8_t>> images;
  act::Observation obs;
  for (const auto& cam : info.cameras) {
    images.emplace_back(static_cast<size_t>(cam.height) * cam.width * 3, 128);
    obs.images.push_back(act::ImageView::rgb_u8(images.back().data(), cam.height, cam.width));
  }
  std::vector<float> state(static_cast<size_t>(info.state_dim), 0.0f), env(static_cast<size_t>(info.env_state_dim), 0.0f);
  obs.state = state;
  obs.env_state = env;
  std::vector<float> chunk(info.chunk_values());
  const act::Status s = (*engine)->infer(obs, chunk);
  if (!s.ok()) {
    std::fprintf(stderr, "%s\n", s.to_string().c_str());
    return 1;
  }
  for (float v : chunk) {
    if (!std::isfinite(v)) return 1;
  }
  auto scheduler = act::ChunkScheduler::create(info);
  std::vector<float> action(static_cast<size_t>(info.action_dim));
  const act::Status scheduled = scheduler.ok() ? scheduler->add(chunk, 0) : scheduler.status();
  if (!scheduled.ok() || !scheduler->action_at(0, action).ok() || action[0] != chunk[0]) {
    std::fprintf(stderr, "the chunk scheduler did not return row 0 for tick 0: %s\n", scheduled.to_string().c_str());
    return 1;
  }
  std::printf("actengine %s: %s -> first action %g\n", act::version(), info.summary.c_str(), chunk[0]);
  return 0;
}
