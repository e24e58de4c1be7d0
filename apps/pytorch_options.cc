#include "apps/pytorch_options.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>

namespace act {

namespace {

constexpr const char* kGroup = "PyTorch .pth input (what the weights do not say)";
constexpr const char* kOptionNames[] = {"--config", "--stats", "--image-size", "--n-heads",
                                        "--activation", "--camera", "--assume-lerobot-defaults", "--no-normalization",
                                        "--state-dict-key"};

}  // namespace

void add_pytorch_options(CLI::App& app, PthOptions& s) {
  app.add_option("--config", s.config_path, "LeRobot config.json of the trained policy (the weights must agree with it)")
      ->check(CLI::ExistingFile)->group(kGroup);
  app.add_option("--stats", s.stats_paths,
                 "normalisation statistics: the dataset's meta/stats.json or a LeRobot "
                 "policy_*_normalizer_processor.safetensors (repeatable)")
      ->check(CLI::ExistingFile)->group(kGroup);
  app.add_option_function<std::string>(
         "--image-size",
         [&s](const std::string& text) {
           int h = 0, w = 0;
           char x = 0, extra = 0;
           if (std::sscanf(text.c_str(), "%d%c%d%c", &h, &x, &w, &extra) != 3 || (x != 'x' && x != 'X') || h <= 0 || w <= 0) {
             throw CLI::ValidationError("--image-size", "expected HxW, e.g. 480x640, got '" + text + "'");
           }
           s.image_size = std::make_pair(h, w);
         },
         "camera image size in training, HxW (e.g. 480x640)")
      ->group(kGroup);
  app.add_option_function<int>("--n-heads", [&s](int n) { s.n_heads = n; }, "attention heads")
      ->check(CLI::PositiveNumber)->group(kGroup);
  app.add_option_function<std::string>("--activation", [&s](const std::string& a) { s.activation = a; },
                                       "feed-forward activation")
      ->check(CLI::IsMember({"relu", "gelu", "glu"}))->group(kGroup);
  app.add_option("--camera", s.cameras, "camera feature key, e.g. observation.images.front; repeat in token order")
      ->group(kGroup);
  app.add_flag("--assume-lerobot-defaults", s.lerobot_defaults,
               "take LeRobot's ACTConfig defaults for what leaves no trace in the weights "
               "(n_heads 8, relu, no dilation, MEAN_STD normalisation)")
      ->group(kGroup);
  app.add_flag("--no-normalization", s.no_normalization, "the model was trained on raw inputs and actions (no statistics)")
      ->group(kGroup);
  app.add_option("--state-dict-key", s.state_dict_key, "entry of the saved dict that holds the state dict")->group(kGroup);
}

bool any_pytorch_option(const CLI::App& app) {
  for (const char* name : kOptionNames) {
    if (app.count(name) > 0) return true;
  }
  return false;
}

void add_deployment_options(CLI::App& app, DeploymentOptions& d) {
  constexpr const char* group = "Deployment (replaces the model's own)";
  app.add_option_function<int>("--n-action-steps", [&d](int n) { d.n_action_steps = n; },
                               "actions executed per predicted chunk (1..chunk_size)")
      ->check(CLI::PositiveNumber)->group(group);
  app.add_option_function<std::string>(
         "--temporal-ensemble-coeff",
         [&d](const std::string& text) {
           if (text == "none") {
             d.temporal_ensemble_coeff.emplace(std::nullopt);
             return;
           }
           size_t used = 0;
           double coeff = 0;
           try {
             coeff = std::stod(text, &used);
           } catch (const std::exception&) {
             used = 0;
           }
           if (used != text.size() || !std::isfinite(coeff)) {
             throw CLI::ValidationError("--temporal-ensemble-coeff", "expected a finite number or none, got '" + text + "'");
           }
           d.temporal_ensemble_coeff.emplace(coeff);
         },
         "LeRobot's temporal ensembling, weights exp(-coeff * i) (e.g. 0.01; needs --n-action-steps 1), or none to "
         "turn it off")
      ->group(group);
}

void print_explanation(std::ostream& out, const PthExplanation& plan) {
  out << "checkpoint   " << plan.origin << " (torch.save " << plan.format << " format), state dict: " << plan.location
      << ", " << plan.tensors << " tensors\n";
  for (const auto& e : plan.other_entries) out << "  also saved  " << e << "  (not used)\n";
  for (const auto& n : plan.notes) out << "keys         " << n << "\n";
  out << "statistics   " << (plan.statistics_source.empty() ? "(none found)" : plan.statistics_source) << "\n";
  out << "config       (value <- where it comes from)\n";
  size_t width = 0;
  for (const auto& f : plan.config) width = std::max(width, f.field.size() + 2 + std::min<size_t>(f.value.size(), 40));
  for (const auto& f : plan.config) {
    std::string value = f.value.size() > 40 ? f.value.substr(0, 37) + "..." : f.value;
    std::string left = f.field + "  " + value;
    out << "  " << left << std::string(width - left.size() + 2, ' ') << "<- " << f.source << "\n";
  }
  if (!plan.missing.empty()) {
    out << "cannot be known from what was given (refusing to guess):\n";
    for (const auto& m : plan.missing) out << "  - " << m << "\n";
  }
}

}  // namespace act
