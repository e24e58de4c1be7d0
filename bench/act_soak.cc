// Soak benchmark: many inferences of one model with the process's resident set size sampled along
// the way. The engine plans every buffer at load time, so after warm-up RSS must stay flat; the
// program exits 1 if it grows by more than --tolerance-kb after warm-up. A benchmark, not a timed
// test: CI runs a short version (ctest soak_short), the full 10^5 runs are done by hand.
//   act_soak --model model.actb [--runs 100000] [--warmup 2000] [--sample-every 1000] [--threads 2]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "actengine/engine.h"
#include "apps/bench_support.h"
#include "apps/version.h"

namespace {

double mb(size_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

}  // namespace

int main(int argc, char** argv) {
  std::string model;
  long runs = 100000, warmup = 2000, sample_every = 1000;
  int threads = 2;
  double tolerance_kb = 1024;
  CLI::App app{"act_soak: RSS over many inferences; exits 1 if it grows after warm-up"};
  app.add_option("-m,--model", model, "the .actb blob")->required();
  app.add_option("--runs", runs, "inferences after warm-up")->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "inferences before the RSS baseline is taken")->check(CLI::NonNegativeNumber);
  app.add_option("--sample-every", sample_every, "RSS sampling period, in inferences")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "engine threads")->check(CLI::PositiveNumber);
  app.add_option("--tolerance-kb", tolerance_kb, "allowed RSS growth after warm-up")->check(CLI::NonNegativeNumber);
  app.set_version_flag("--version", act::version_line("act_soak"));
  CLI11_PARSE(app, argc, argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // each sample shows at once, also when logged to a file

  auto engine_or = act::Engine::open(model, {.threads = threads});
  if (!engine_or.ok()) {
    std::fprintf(stderr, "act_soak: %s\n", engine_or.status().to_string().c_str());
    return 2;
  }
  act::Engine& engine = **engine_or;
  const act::ModelInfo& info = engine.model_info();
  std::printf("model %s (%s), %d threads\n", model.c_str(), info.summary.c_str(), threads);

  // Inputs change every run (like frames from a camera) but are made once: the loop allocates nothing.
  std::vector<std::vector<uint8_t>> images;
  for (const auto& cam : info.cameras) {
    std::vector<uint8_t> image(static_cast<size_t>(cam.height) * cam.width * 3);
    for (size_t i = 0; i < image.size(); ++i) image[i] = static_cast<uint8_t>((i * 37 + i / 7) % 251);
    images.push_back(std::move(image));
  }
  std::vector<float> state(static_cast<size_t>(info.state_dim)), env(static_cast<size_t>(info.env_state_dim));
  std::vector<float> chunk(info.chunk_values());
  act::Observation obs;
  for (size_t c = 0; c < images.size(); ++c) {
    obs.images.push_back(act::ImageView::rgb_u8(images[c].data(), info.cameras[c].height, info.cameras[c].width));
  }
  obs.state = state;
  obs.env_state = env;

  const auto run = [&](long i) {
    for (auto& image : images) image[static_cast<size_t>(i) % image.size()] ^= 0x5a;
    for (size_t k = 0; k < state.size(); ++k) state[k] = static_cast<float>((i + static_cast<long>(k)) % 17) * 0.1f;
    for (size_t k = 0; k < env.size(); ++k) env[k] = static_cast<float>((i * 3 + static_cast<long>(k)) % 13) * 0.1f;
    const act::Status s = engine.infer(obs, chunk);
    if (!s.ok()) {
      std::fprintf(stderr, "act_soak: inference %ld failed: %s\n", i, s.to_string().c_str());
      std::exit(2);
    }
  };

  const size_t rss_start = act::current_rss_bytes();
  for (long i = 0; i < warmup; ++i) run(i);
  const size_t rss_warm = act::current_rss_bytes();
  std::printf("RSS at start %.2f MB, after %ld warm-up inferences %.2f MB\n", mb(rss_start), warmup, mb(rss_warm));

  size_t rss_max = rss_warm, rss_last = rss_warm;
  const auto start = std::chrono::steady_clock::now();
  for (long i = 0; i < runs; ++i) {
    run(warmup + i);
    if ((i + 1) % sample_every == 0 || i + 1 == runs) {
      rss_last = act::current_rss_bytes();
      rss_max = std::max(rss_max, rss_last);
      std::printf("run %8ld  RSS %.2f MB\n", i + 1, mb(rss_last));
    }
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double growth_kb = (static_cast<double>(rss_max) - static_cast<double>(rss_warm)) / 1024.0;
  std::printf("%ld inferences in %.1f s (%.2f ms each); RSS after warm-up %.2f MB, at the end %.2f MB, "
              "max growth %.0f kB (tolerance %.0f kB), peak RSS %.2f MB\n",
              runs, secs, secs * 1e3 / static_cast<double>(runs), mb(rss_warm), mb(rss_last), growth_kb,
              tolerance_kb, mb(act::peak_rss_bytes()));
  if (growth_kb > tolerance_kb) {
    std::printf("FAIL: RSS grew after warm-up\n");
    return 1;
  }
  std::printf("OK: no RSS growth after warm-up\n");
  return 0;
}
