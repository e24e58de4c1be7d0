// act_eval: run .actb models on observations and compare their action chunks: with a stored
// reference (a safetensors observation file), or with the demonstration of a recorded episode
// (apps/eval/: an act_drive recording, or images or a video with CSVs of states and actions).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>

#include "actengine/engine.h"
#include "actengine/status.h"
#include "actengine/vision.h"
#include "apps/diff_stats.h"
#include "apps/eval/episode.h"
#include "apps/eval/html_report.h"
#include "apps/eval/metrics.h"
#include "engine/src/convert/observation_file.h"
#include "apps/version.h"
#include "weights/blob/file_util.h"
#include "weights/import/safetensors.h"

namespace {

// Exit codes of --episode (also in --help).
constexpr int kExitGateMissed = 2;
constexpr int kExitNonFinite = 3;
// How the engine refuses to hand out a non-finite output (engine/src/engine.cc, check_finite).
constexpr const char* kEngineNonFiniteOutput = "values NaN or infinite";

struct Options {
  std::vector<std::string> models;
  std::string input_path, output_path, images = "auto";
  bool compare = false;
  double tol = 1e-4;
  int threads = 0;
  act::eval::EpisodeSources episode;
  std::string json_path, report_path;
  double max_mse = 0, max_added_error = 0;
  std::string state;  // --state last-action|mean|zeros|FILE
};

// --state: a way to make the states (as act_drive feeds them) or a states CSV, like --states.
void apply_state_option(Options& o) {
  if (o.state.empty()) return;
  if (!o.episode.states_csv.empty()) act::fail(act::StatusCode::kInvalidArgument, "give --states FILE or --state, not both");
  if (o.state == "last-action" || o.state == "mean" || o.state == "zeros") {
    o.episode.state = o.state;
  } else {
    o.episode.states_csv = o.state;
  }
}

std::unique_ptr<act::Engine> open_engine(const std::string& path, int threads) {
  auto engine = act::Engine::open(path, {.threads = threads});
  if (!engine.ok()) throw act::Error(engine.status().with_context(path));
  return std::move(engine).value();
}

// Today's mode: one model on an observation file, optionally against its stored reference.
int run_observation_file(const Options& o) {
  if (o.models.size() != 1) act::fail(act::StatusCode::kInvalidArgument, "--input takes exactly one --model");
  const std::unique_ptr<act::Engine> engine_ptr = open_engine(o.models[0], o.threads);
  act::Engine& engine = *engine_ptr;
  const act::ModelInfo& info = engine.model_info();
  const act::ImageSource source = o.images == "u8" ? act::ImageSource::kU8
                                  : o.images == "f32" ? act::ImageSource::kFloat
                                                      : act::ImageSource::kAuto;
  const act::ObservationBatch batch = act::ObservationBatch::read(o.input_path, info, source);
  if (o.compare && !batch.has_expected_actions()) {
    act::fail(act::StatusCode::kNotFound, o.input_path + ": --compare needs an 'output.action' tensor");
  }
  const size_t per = info.chunk_values();
  std::vector<float> actions(batch.size() * per);
  act::DiffStats diff;
  for (size_t i = 0; i < batch.size(); ++i) {
    std::span<float> out(actions.data() + i * per, per);
    const act::Status s = engine.infer(batch.at(i), out);
    if (!s.ok()) throw act::Error(s.with_context("observation " + std::to_string(i)));
    if (o.compare) {
      const float* ref = batch.expected_actions(i);
      for (size_t j = 0; j < per; ++j) diff.add(out[j], ref[j]);
    }
  }
  std::cout << "model        " << info.summary << "\n"
            << "observations " << batch.size() << " from " << o.input_path << "\n";
  if (!o.output_path.empty()) {
    act::write_safetensors(o.output_path, {{"action", act::DType::kF32,
                                            {static_cast<int64_t>(batch.size()), info.chunk_size, info.action_dim},
                                            actions.data(), actions.size() * sizeof(float)}});
    std::cout << "wrote        " << o.output_path << "\n";
  }
  if (o.compare) {
    const bool pass = diff.within(o.tol);
    if (diff.non_finite > 0) {
      std::printf("compare      %zu of %zu values are NaN or infinite (ours or the reference's)\n", diff.non_finite,
                  diff.count);
    }
    std::printf("compare      max abs error %.3g, max relative error %.3g, max |diff|/(1+|ref|) %.3g (tol %.3g): %s\n",
                diff.max_abs, diff.max_rel, diff.max_ratio, o.tol, pass ? "PASS" : "FAIL");
    return pass ? 0 : 1;
  }
  return 0;
}

// The models must take the same observations and give actions of the same shape.
void check_same_interface(const act::ModelInfo& a, const act::ModelInfo& b, const std::string& a_path, const std::string& b_path) {
  bool same = a.state_dim == b.state_dim && a.env_state_dim == b.env_state_dim && a.action_dim == b.action_dim &&
              a.chunk_size == b.chunk_size && a.cameras.size() == b.cameras.size();
  for (size_t c = 0; same && c < a.cameras.size(); ++c) {
    same = a.cameras[c].height == b.cameras[c].height && a.cameras[c].width == b.cameras[c].width;
  }
  if (!same) {
    act::fail(act::StatusCode::kInvalidArgument, b_path + " is not the same policy as " + a_path +
              " (cameras, state, action or chunk sizes differ): act_eval compares versions of one policy");
  }
}

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return std::isfinite(v) ? buf : "non-finite";
}

std::string percent(double fraction) { return std::isfinite(fraction) ? fmt(100 * fraction) + " %" : "non-finite"; }

// The baselines beside the policy's error, and whether it beats them.
void print_baselines(const act::eval::EpisodeEvaluation& e) {
  if (e.baselines.empty() || e.models.empty()) return;
  const double own = e.models[0].vs_demonstration.chunk_normalised.mse();
  std::cout << "baselines    chunk MSE against the demonstration (normalised), no policy: ";
  const act::eval::BaselineEvaluation* best = nullptr;
  for (const auto& b : e.baselines) {
    const double mse = b.vs_demonstration.chunk_normalised.mse();
    std::cout << (&b == &e.baselines.front() ? "" : ", ") << b.name << " " << fmt(mse);
    if (!best || mse < best->vs_demonstration.chunk_normalised.mse()) best = &b;
  }
  std::cout << "; model 1 " << fmt(own) << "\n";
  const double bar = best->vs_demonstration.chunk_normalised.mse();
  if (own < bar) {
    std::cout << "  model 1 beats every baseline (the best, " << best->name << ", " << fmt(bar) << ")\n";
  } else {
    std::cout << "  warning: model 1's chunk MSE " << fmt(own) << " is not below the " << best->name << " baseline's " << fmt(bar)
              << ": on this episode the policy does no better than one that " << best->description << "\n";
  }
}

void print_summary(const act::eval::EpisodeEvaluation& e, const act::eval::Episode& episode) {
  std::cout << "episode      " << episode.path << " (" << episode.kind << "), " << e.frame_sources.size() << " frames\n";
  for (const auto& note : episode.notes) std::cout << "note: " << note << "\n";
  for (size_t m = 0; m < e.models.size(); ++m) {
    const auto& model = e.models[m];
    const auto& d = model.vs_demonstration;
    std::cout << "model " << m + 1 << "      " << model.path << " (" << model.precision << "), "
              << fmt(model.seconds * 1e3 / static_cast<double>(e.frame_sources.size())) << " ms per frame\n"
              << "  vs demonstration  first action MSE " << fmt(d.first_raw.mse()) << " raw, " << fmt(d.first_normalised.mse())
              << " normalised; chunk MSE " << fmt(d.chunk_raw.mse()) << " raw, " << fmt(d.chunk_normalised.mse())
              << " normalised; max |err| " << fmt(d.chunk_raw.max_abs()) << " raw\n";
    for (size_t a = 0; a < e.action_names.size(); ++a) {
      std::cout << "    " << e.action_names[a] << ": first action MSE " << fmt(d.first_raw.dim_mse(a)) << ", max |err| "
                << fmt(d.first_raw.dim_max_abs(a)) << " (raw)\n";
    }
    if (m > 0) {
      const auto& r = model.vs_reference;
      std::cout << "  vs model 1        chunk MSE " << fmt(r.chunk_raw.mse()) << " raw, " << fmt(r.chunk_normalised.mse())
                << " normalised; max |err| " << fmt(r.chunk_raw.max_abs()) << " raw\n"
                << "  added error       " << percent(e.added_error(m))
                << " of model 1's own error (chunk MSE, normalised)\n";
    }
    if (model.non_finite_outputs > 0) {
      std::cout << "  FAIL: " << model.non_finite_outputs << " output values are NaN or infinite\n";
    }
  }
}

void write_file(const std::string& path, const std::string& text) {
  act::detail::AtomicFileWriter file(path);
  file.write(text);
  file.commit();
}

// Finite outputs but an error that is not (a demonstration of huge values: its square overflows):
// nothing was measured, which is an error, not a pass. "" when every error is a number.
std::string non_finite_error(const act::eval::EpisodeEvaluation& evaluation) {
  for (size_t m = 0; m < evaluation.models.size(); ++m) {
    const auto& d = evaluation.models[m].vs_demonstration;
    for (const double mse : {d.chunk_normalised.mse(), d.chunk_raw.mse(), d.first_raw.mse(), d.first_normalised.mse()}) {
      if (std::isfinite(mse)) continue;
      return "model " + std::to_string(m + 1) + "'s MSE against the demonstration is " + fmt(mse) +
             " although its outputs are finite: the demonstration's values are too large to compare (no error was measured)";
    }
  }
  return "";
}

// Every model on every frame of the episode (each camera given the frame), against the demonstration.
act::eval::EpisodeEvaluation evaluate_episode(const Options& o, const std::vector<std::unique_ptr<act::Engine>>& engines,
                                              const act::eval::Episode& episode) {
  const act::ModelInfo& info = engines[0]->model_info();
  act::eval::EpisodeEvaluation evaluation;
  // The blob's names (act_convert --action-names) when it has them, else the demonstrations' columns.
  evaluation.action_names = info.action_names.size() == episode.action_names.size() ? info.action_names : episode.action_names;
  evaluation.scale = {info.action_low, info.action_high};
  for (size_t m = 0; m < engines.size(); ++m) {
    evaluation.models.emplace_back(o.models[m], engines[m]->model_info().precision, episode.action_names.size());
  }
  act::eval::EpisodeImages images(episode);
  std::vector<std::vector<uint8_t>> rgb(info.cameras.size());
  std::vector<std::vector<float>> chunks(engines.size(), std::vector<float>(info.chunk_values()));
  for (size_t f = 0; f < episode.frames.size(); ++f) {
    const act::eval::EpisodeFrame& frame = episode.frames[f];
    const cv::Mat image = images.image(f);
    act::Observation observation;
    // Every camera sees the episode's one image (single-view sources).
    for (size_t c = 0; c < info.cameras.size(); ++c) {
      const act::CameraInfo& cam = info.cameras[c];
      const act::Status converted = act::frame_to_model_rgb(image, cam.height, cam.width, rgb[c]);
      if (!converted.ok()) throw act::Error(converted.with_context(frame.source));
      observation.images.push_back(act::ImageView::rgb_u8(rgb[c].data(), cam.height, cam.width));
    }
    observation.state = frame.state;
    for (size_t m = 0; m < engines.size(); ++m) {
      const auto start = std::chrono::steady_clock::now();
      const act::Status status = engines[m]->infer(observation, chunks[m]);
      evaluation.models[m].seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (!status.ok() && status.message().find(kEngineNonFiniteOutput) != std::string::npos) {
        // Counted as the model's answer on this frame, so the report shows where it happened.
        std::fill(chunks[m].begin(), chunks[m].end(), std::numeric_limits<float>::quiet_NaN());
        continue;
      }
      if (!status.ok()) throw act::Error(status.with_context(o.models[m] + " on " + frame.source));
    }
    evaluation.add_frame(frame.source, frame.demonstration, chunks);
  }

  return evaluation;
}

// One verdict line per model after the first: the error it adds, against --max-added-error.
void print_verdicts(const Options& o, const act::eval::EpisodeEvaluation& evaluation) {
  for (size_t m = 1; m < evaluation.models.size(); ++m) {
    const double added = evaluation.added_error(m);
    std::cout << "verdict      model " << m + 1 << " adds " << percent(added) << " to model 1's error";
    if (o.max_added_error > 0) {
      std::cout << (added <= o.max_added_error ? ": within" : ": above") << " --max-added-error " << fmt(o.max_added_error)
                << " (" << percent(o.max_added_error) << "), " << (added <= o.max_added_error ? "PASS" : "FAIL") << "\n";
    } else {
      std::cout << " (no gate given: --max-added-error 0.1 fails it above 10 %)\n";
    }
  }

}

// The exit code: non-finite outputs, an error that could not be measured, or a gate missed.
int episode_exit_code(const Options& o, const act::eval::EpisodeEvaluation& evaluation) {
  bool non_finite = false, gate_missed = false;
  for (size_t m = 0; m < evaluation.models.size(); ++m) {
    non_finite |= evaluation.models[m].non_finite_outputs > 0;
    const double mse = evaluation.models[m].vs_demonstration.chunk_normalised.mse();
    if (o.max_mse > 0 && !(mse <= o.max_mse)) {
      std::cout << "FAIL: model " << m + 1 << "'s chunk MSE against the demonstration, " << fmt(mse)
                << " (normalised), is above --max-mse " << fmt(o.max_mse) << "\n";
      gate_missed = true;
    }
    if (m > 0 && o.max_added_error > 0 && !(evaluation.added_error(m) <= o.max_added_error)) {
      std::cout << "FAIL: model " << m + 1 << " adds " << percent(evaluation.added_error(m))
                << " of model 1's own error, above --max-added-error " << fmt(o.max_added_error) << " ("
                << percent(o.max_added_error) << ")\n";
      gate_missed = true;
    }
  }
  if (non_finite) return kExitNonFinite;
  if (const std::string problem = non_finite_error(evaluation); !problem.empty()) {
    std::cerr << "act_eval: error: " << problem << "\n";
    return 1;
  }
  return gate_missed ? kExitGateMissed : 0;
}

int run_episode(const Options& o) {
  std::vector<std::unique_ptr<act::Engine>> engines;
  for (const auto& path : o.models) {
    engines.push_back(open_engine(path, o.threads));
    check_same_interface(engines[0]->model_info(), engines.back()->model_info(), o.models[0], path);
  }
  const act::ModelInfo& info = engines[0]->model_info();
  act::eval::Episode episode = act::eval::read_episode(o.episode, info);
  if (info.cameras.size() > 1) {
    episode.notes.push_back("single-view episode: each of the model's " + std::to_string(info.cameras.size()) +
                            " cameras was given the same frame");
  }

  const act::eval::EpisodeEvaluation evaluation = evaluate_episode(o, engines, episode);
  nlohmann::ordered_json json = evaluation.to_json();
  json["episode_path"] = episode.path;
  json["episode_kind"] = episode.kind;
  json["notes"] = episode.notes;
  if (!o.json_path.empty()) write_file(o.json_path, json.dump(2) + "\n");
  if (!o.report_path.empty()) {
    write_file(o.report_path, act::eval::render_html_report({{"title", "act_eval: " + episode.path}, {"episode", json}}));
  }
  print_summary(evaluation, episode);
  print_baselines(evaluation);
  print_verdicts(o, evaluation);
  return episode_exit_code(o, evaluation);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_eval: run .actb models on observations and compare their action chunks, either with the reference "
               "stored in a safetensors observation file (--input, as in the LeRobot fixtures), or with the "
               "demonstration of a recorded episode (--episode; every model on every frame, as fast as the machine allows)."};
  Options o;
  app.add_option("-m,--model", o.models, "the .actb model; with --episode repeatable (the first is the reference, "
                 "typically FP32: --model fp32.actb --model int8.actb)")->required();
  auto* input = app.add_option("-i,--input", o.input_path, "observations (safetensors)");
  app.add_option("-o,--output", o.output_path, "write the raw action chunks as 'action' [N, chunk, action_dim]")->needs(input);
  app.add_flag("--compare", o.compare, "compare with 'output.action' from the input file; exit 1 beyond --tol")->needs(input);
  app.add_option("--tol", o.tol, "tolerance: |ours - ref| <= tol * (1 + |ref|)")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("-t,--threads", o.threads, "threads (0 = all cores)")->capture_default_str()->check(CLI::Range(0, act::kMaxThreads));
  app.add_option("--images", o.images, "which image tensors to read: auto (float if present), f32, u8")->capture_default_str()
      ->check(CLI::IsMember({"auto", "f32", "u8"}));
  auto* episode = app.add_option("--episode", o.episode.episode,
                                 "a recorded episode: an act_drive --record folder, or a folder of images or a video "
                                 "with --actions (and --states)")->excludes(input);
  app.add_option("--actions", o.episode.actions_csv, "CSV of the demonstrated actions: a frame (image file name or index) "
                 "then named values, one action per row or a chunk as NAME@STEP columns; or only the values, one row per "
                 "frame in frame order; or the long form file,chunk_index,NAME...,is_pad (docs)")->needs(episode);
  app.add_option("--states", o.episode.states_csv, "CSV of the robot states: a frame, then the named state values (or "
                 "only the values, one row per frame in frame order)")->needs(episode);
  app.add_option("--state", o.state, "the robot states without a states CSV, as act_drive feeds them: last-action (the "
                 "action demonstrated at the frame before; the first frame gets the training mean), mean (the training "
                 "mean), zeros; or a states CSV FILE (as --states)")->needs(episode);
  app.add_option("--json", o.json_path, "write every metric, per model, dimension and frame, as JSON")->needs(episode);
  app.add_option("--report", o.report_path, "write a self-contained HTML report (charts, per-frame errors)")->needs(episode);
  app.add_option("--max-mse", o.max_mse, "gate: exit 2 when a model's chunk MSE against the demonstration (normalised) "
                 "is above this")->needs(episode)->check(CLI::PositiveNumber);
  app.add_option("--max-added-error", o.max_added_error, "gate: exit 2 when a model's chunk MSE against the first model "
                 "is above this fraction of the first model's own (normalised)")->needs(episode)->check(CLI::PositiveNumber);
  app.footer("Exit codes: 0 pass; 1 an error (unreadable model or input) or, with --compare, beyond --tol; with "
             "--episode 2 a gate (--max-mse, --max-added-error) missed, 3 a model gave NaN or infinite actions.");
  app.set_version_flag("--version", act::version_line("act_eval"));
  CLI11_PARSE(app, argc, argv);

  try {
    apply_state_option(o);
    if (o.input_path.empty() && o.episode.episode.empty()) {
      act::fail(act::StatusCode::kInvalidArgument, "give --input OBS.safetensors or --episode PATH");
    }
    return o.episode.episode.empty() ? run_observation_file(o) : run_episode(o);
  } catch (const std::exception& e) {
    std::cerr << "act_eval: error: " << e.what() << "\n";
    return 1;
  }
}
