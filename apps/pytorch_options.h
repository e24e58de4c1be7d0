// act_convert's options for PyTorch .pth input (config sources) and its --explain report.
#pragma once

#include <iosfwd>
#include <string>

#include "actengine/convert.h"

namespace CLI {
class App;
}

namespace act {

/// Registers --config, --stats, --image-size, --n-heads, --activation, --camera,
/// --assume-lerobot-defaults, --no-normalization and --state-dict-key, filling `options`.
void add_pytorch_options(CLI::App& app, PthOptions& options);

/// Registers --n-action-steps and --temporal-ensemble-coeff (LeRobot's null: "none"), filling `deployment`.
void add_deployment_options(CLI::App& app, DeploymentOptions& deployment);

/// True when any of the .pth options was given (they only apply to a .pth input).
bool any_pytorch_option(const CLI::App& app);

/// What was read, every config value with its source, and what cannot be known.
void print_explanation(std::ostream& out, const PthExplanation& plan);

}  // namespace act
