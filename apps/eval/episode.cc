#include "apps/eval/episode.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act::eval {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void bad(const std::string& where, const std::string& problem) {
  fail(StatusCode::kInvalidArgument, where + ": " + problem);
}

std::string at_line(const std::string& file, size_t line) { return file + " line " + std::to_string(line); }

// A finite number, all of `text`; nullopt otherwise.
std::optional<float> parse_number(const std::string& text) {
  if (text.empty()) return std::nullopt;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v)) return std::nullopt;
  return static_cast<float>(v);
}

std::optional<size_t> parse_index(const std::string& text) {
  if (text.empty() || text.size() > 12 || !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  return static_cast<size_t>(std::stoull(text));
}

// A comma-separated table with a header line. Fields are not quoted (names and numbers need no quotes).
struct CsvTable {
  std::string path;
  std::vector<std::string> header;
  struct Row {
    size_t line = 0;
    std::vector<std::string> cells;
  };
  std::vector<Row> rows;

  // The number in row r, column c, or an error naming both.
  float number(const Row& row, size_t c) const {
    const std::optional<float> v = parse_number(row.cells[c]);
    if (!v) {
      bad(at_line(path, row.line) + " column " + std::to_string(c + 1) + " (" + header[c] + ")",
          "'" + row.cells[c] + "' is not a finite number");
    }
    return *v;
  }
};

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> cells(1);
  for (char ch : line) {
    if (ch == ',') {
      cells.emplace_back();
    } else {
      cells.back() += ch;
    }
  }
  for (auto& cell : cells) {  // spaces around a value are not part of it
    const size_t first = cell.find_first_not_of(" \t");
    cell = first == std::string::npos ? "" : cell.substr(first, cell.find_last_not_of(" \t") - first + 1);
  }
  return cells;
}

// The whole of an input file (read_regular_file's rules: a FIFO or a folder is refused at once, never
// waited on); a missing one is "cannot open <what> <path>".
std::string read_input_file(const std::string& path, const std::string& what) {
  try {
    return detail::read_regular_file(path);
  } catch (const Error& e) {
    if (e.code() == StatusCode::kNotFound) fail(StatusCode::kNotFound, "cannot open " + what + " " + path);
    throw;
  }
}

// `recording`: a file a killed act_drive may have cut short: a last row with too few columns is
// dropped (and counted in `cut_rows`) instead of being an error.
CsvTable read_csv(const std::string& path, const char* what, bool recording = false, size_t* cut_rows = nullptr) {
  std::istringstream in(read_input_file(path, std::string("the ") + what + " CSV"));
  CsvTable table{path, {}, {}};
  std::string line;
  size_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    const bool last = in.peek() == std::char_traits<char>::eof();
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find('"') != std::string::npos) bad(at_line(path, number), "quoted fields are not supported (names and numbers need no quotes)");
    if (line.empty()) continue;
    std::vector<std::string> cells = split(line);
    if (table.header.empty()) {
      if (cells.size() < 2) bad(at_line(path, number), "the header needs a frame column and at least one value column");
      for (size_t c = 0; c < cells.size(); ++c) {
        if (cells[c].empty() && c > 0) bad(at_line(path, number), "column " + std::to_string(c + 1) + " has no name");
      }
      table.header = std::move(cells);
      continue;
    }
    if (recording && last && !table.header.empty() && cells.size() < table.header.size()) {
      ++*cut_rows;
      continue;
    }
    if (cells.size() != table.header.size()) {
      bad(at_line(path, number), std::to_string(cells.size()) + " columns where the header has " + std::to_string(table.header.size()));
    }
    table.rows.push_back({number, std::move(cells)});
  }
  if (table.header.empty()) bad(path, std::string("the ") + what + " CSV is empty");
  if (table.rows.empty()) bad(path, std::string("the ") + what + " CSV has a header but no rows");
  return table;
}

// The actions CSV's value columns: per action dimension and chunk step, the column holding it.
struct ActionColumns {
  std::vector<std::string> names;
  std::vector<std::vector<size_t>> column;  // [step][dimension]
};

// Every form of actions CSV act_eval reads, with an example for a model of `action_dim` values:
// what a mismatch error lists.
std::string accepted_action_forms(int action_dim) {
  std::string names, chunk;
  for (int d = 0; d < action_dim; ++d) {
    const std::string sep = d ? "," : "";
    names.append(sep).append("a").append(std::to_string(d));
    chunk.append(sep).append("a").append(std::to_string(d)).append("@0");
  }
  return "act_eval reads these forms of actions CSV (the value names are yours; " + std::to_string(action_dim) +
         " per action here):\n"
         "  one action per row, after a frame column (an image name or a 0-based frame index): frame," + names + "\n"
         "  one action per row, no frame column (row 1 is frame 0, in frame order): " + names + "\n"
         "  a chunk per row, NAME@STEP columns: frame," + chunk + ",...@1,...\n"
         "  a chunk over rows (long form; is_pad optional, padded steps are not compared): file,chunk_index," + names +
         ",is_pad";
}

// The frame column's usual names: a first column named otherwise may be a value (no frame column).
bool is_frame_column_name(std::string name) {
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const char* n : {"frame", "file", "filename", "file_name", "image", "image_path", "path", "index", "frame_index"}) {
    if (name == n) return true;
  }
  return false;
}

// The value columns from `first` on, without `skip` (the long form's chunk_index and is_pad).
ActionColumns action_columns(const CsvTable& table, int action_dim, size_t first = 1, const std::vector<size_t>& skip = {}) {
  ActionColumns out;
  std::map<std::string, std::map<size_t, size_t>> chunked;  // name -> step -> column
  bool any_chunked = false;
  for (size_t c = first; c < table.header.size(); ++c) {
    if (std::find(skip.begin(), skip.end(), c) != skip.end()) continue;
    const std::string& h = table.header[c];
    const size_t at = h.rfind('@');
    const std::optional<size_t> step = at == std::string::npos ? std::nullopt : parse_index(h.substr(at + 1));
    any_chunked |= step.has_value();
    const std::string name = step ? h.substr(0, at) : h;
    if (std::find(out.names.begin(), out.names.end(), name) == out.names.end()) out.names.push_back(name);
    if (!chunked[name].emplace(step.value_or(0), c).second) bad(table.path, "column '" + h + "' appears twice");
  }
  if (out.names.size() != static_cast<size_t>(action_dim)) {
    std::string listed;
    for (const auto& n : out.names) listed += (listed.empty() ? "" : ", ") + n;
    bad(table.path, std::to_string(out.names.size()) + " action columns (" + listed + "; " +
        std::string(any_chunked ? "NAME@STEP counted once per NAME" : "one per dimension") + ") after the frame column '" +
        table.header[0] + "' but the model's actions have " + std::to_string(action_dim) + " values.\n" +
        accepted_action_forms(action_dim));
  }
  size_t steps = 0;
  for (const auto& [name, by_step] : chunked) steps = std::max(steps, by_step.size());
  for (size_t s = 0; s < steps; ++s) {
    out.column.emplace_back();
    for (const auto& name : out.names) {
      const auto& by_step = chunked[name];
      const auto it = by_step.find(s);
      if (it == by_step.end()) {
        bad(table.path, "action '" + name + "' lacks the column " + name + "@" + std::to_string(s) +
            " (a chunk row needs NAME@0..NAME@" + std::to_string(steps - 1) + " for every action)");
      }
      out.column[s].push_back(it->second);
    }
  }
  return out;
}

// With one action per frame, frame i's chunk is the actions of frames i, i+1, ... (up to the model's chunk).
void extend_demonstrations(std::vector<EpisodeFrame>& frames, const ModelInfo& model) {
  const size_t dim = static_cast<size_t>(model.action_dim);
  for (size_t i = 0; i < frames.size(); ++i) {
    for (size_t j = i + 1; j < frames.size() && j < i + static_cast<size_t>(model.chunk_size); ++j) {
      const auto& next = frames[j].demonstration;
      frames[i].demonstration.insert(frames[i].demonstration.end(), next.begin(), next.begin() + static_cast<std::ptrdiff_t>(dim));
    }
  }
}

void check_state_model(const ModelInfo& model, const std::string& where) {
  if (model.env_state_dim > 0) {
    fail(StatusCode::kUnimplemented, where + ": the model takes an environment state (" + model.env_state_key +
         "), which act_eval's episodes do not carry yet");
  }
}

// The column of each name `prefix`0 .. `prefix`(count - 1), or an error naming the first missing one.
std::vector<size_t> indexed_columns(const CsvTable& table, const std::string& prefix, int count, const std::string& what) {
  std::vector<size_t> columns(static_cast<size_t>(count), table.header.size());
  for (size_t c = 0; c < table.header.size(); ++c) {
    const std::string& h = table.header[c];
    if (h.rfind(prefix, 0) != 0) continue;
    const std::optional<size_t> i = parse_index(h.substr(prefix.size()));
    if (i && *i < columns.size()) columns[*i] = c;
  }
  for (size_t i = 0; i < columns.size(); ++i) {
    if (columns[i] == table.header.size()) {
      bad(table.path, "no '" + prefix + std::to_string(i) + "' column (" + what + " " + std::to_string(count) + " values)");
    }
  }
  return columns;
}

std::optional<size_t> column_named(const CsvTable& table, const std::string& name) {
  const auto it = std::find(table.header.begin(), table.header.end(), name);
  return it == table.header.end() ? std::nullopt : std::optional<size_t>(it - table.header.begin());
}

// The action names a recording's meta.json gives its ticks.csv columns (act_drive writes the blob's),
// or none (an older recording, or a blob without names: the columns are then numbered).
std::vector<std::string> recording_action_names(const fs::path& dir) {
  std::ifstream in(dir / "meta.json");
  const nlohmann::json meta = nlohmann::json::parse(in, nullptr, false);
  if (meta.is_discarded() || !meta.is_object() || !meta.contains("action_names") || !meta["action_names"].is_array()) return {};
  std::vector<std::string> names;
  for (const auto& name : meta["action_names"]) {
    if (!name.is_string()) return {};
    names.push_back(name.get<std::string>());
  }
  return names;
}

// A recording's action columns `prefix`<name> after meta.json's names, else `prefix`0, 1, ...
std::vector<size_t> action_columns(const CsvTable& table, const std::string& prefix, const ModelInfo& model,
                                   const std::vector<std::string>& names) {
  if (names.size() != static_cast<size_t>(model.action_dim)) {
    return indexed_columns(table, prefix, model.action_dim, "the model's actions have");
  }
  std::vector<size_t> columns;
  for (const std::string& name : names) {
    const std::optional<size_t> column = column_named(table, prefix + name);
    if (!column) {
      bad(table.path, "no '" + prefix + name + "' column (meta.json's action_names; the model's actions have " +
                          std::to_string(model.action_dim) + " values)");
    }
    columns.push_back(*column);
  }
  return columns;
}

// A recording whose ticks.csv holds every control tick (act_drive records the command it sent, who
// sent it, the state and the camera frame at each tick): the demonstration is what was sent, by a
// person or a policy, so a drive by hand is evaluated as well as an autonomous one. A frame is
// evaluated at the first tick that saw it; its chunk runs over the following ticks until the car was
// held safe (or the recording ends).
Episode read_tick_recording(const fs::path& dir, const ModelInfo& model, const CsvTable& ticks, size_t cut_lines) {
  Episode ep{dir.string(), "act_drive recording (every tick)", "", {}, {}, {}};
  const std::vector<size_t> command = action_columns(ticks, "command.", model, recording_action_names(dir));
  const std::vector<size_t> state = indexed_columns(ticks, "state.", model.state_dim, "the model's state has");
  const std::optional<size_t> driver = column_named(ticks, "driver"), frame = column_named(ticks, "frame");
  if (!driver || !frame) bad(ticks.path, "no 'driver' and 'frame' columns beside the 'command.<i>' ones");
  const std::optional<size_t> tick_column = column_named(ticks, "tick");
  if (!tick_column) bad(ticks.path, "no 'tick' column");
  for (size_t c : command) ep.action_names.push_back(ticks.header[c]);
  const auto held_safe = [&](const CsvTable::Row& row) { return row.cells[*driver] == "safe"; };
  size_t safe_frames = 0;
  for (size_t r = 0; r < ticks.rows.size(); ++r) {
    const CsvTable::Row& row = ticks.rows[r];
    if (!parse_index(row.cells[*tick_column])) {
      bad(at_line(ticks.path, row.line) + " column 'tick'", "'" + row.cells[*tick_column] + "' is not a tick number");
    }
    const std::string& image = row.cells[*frame];
    if (image.empty() || (r > 0 && ticks.rows[r - 1].cells[*frame] == image)) continue;  // no frame, or not a new one
    if (held_safe(row)) {
      ++safe_frames;
      continue;
    }
    EpisodeFrame f;
    f.source = image;
    f.image_path = (dir / image).string();
    f.where = at_line(ticks.path, row.line);
    for (size_t c : state) f.state.push_back(ticks.number(row, c));
    for (size_t t = r; t < ticks.rows.size() && t < r + static_cast<size_t>(model.chunk_size) && !held_safe(ticks.rows[t]); ++t) {
      for (size_t c : command) f.demonstration.push_back(ticks.number(ticks.rows[t], c));
    }
    ep.frames.push_back(std::move(f));
  }
  if (cut_lines > 0) ep.notes.push_back("skipped the last line of a file cut short (the recording was killed while writing)");
  if (safe_frames > 0) ep.notes.push_back(std::to_string(safe_frames) + " frame(s) skipped: the car was held safe at their tick");
  if (ep.frames.empty()) bad(ep.path, "no frame seen while a person or a policy drove");
  return ep;
}

Episode read_recording(const fs::path& dir, const ModelInfo& model) {
  Episode ep{dir.string(), "act_drive recording", "", {}, {}, {}};
  check_state_model(model, ep.path);
  size_t cut_lines = 0;
  const CsvTable ticks = read_csv((dir / "ticks.csv").string(), "ticks", true, &cut_lines);
  const bool every_tick = std::any_of(ticks.header.begin(), ticks.header.end(),
                                      [](const std::string& h) { return h.rfind("command.", 0) == 0; });
  if (every_tick) return read_tick_recording(dir, model, ticks, cut_lines);
  // An older recording: the frames the policy saw (log.jsonl), the actions it executed by tick (ticks.csv's action.<i>).
  const std::optional<size_t> tick_column = column_named(ticks, "tick");
  if (!tick_column) bad(ticks.path, "no 'tick' column");
  const std::vector<size_t> action_column = action_columns(ticks, "action.", model, recording_action_names(dir));
  for (size_t c : action_column) ep.action_names.push_back(ticks.header[c]);
  std::map<int64_t, std::vector<float>> executed;  // ticks whose action was the policy's (a safe action has none)
  for (const auto& row : ticks.rows) {
    const std::optional<size_t> tick = parse_index(row.cells[*tick_column]);
    if (!tick) bad(at_line(ticks.path, row.line) + " column 'tick'", "'" + row.cells[*tick_column] + "' is not a tick number");
    if (row.cells[action_column[0]].empty()) continue;
    std::vector<float> action;
    for (size_t c : action_column) action.push_back(ticks.number(row, c));
    executed[static_cast<int64_t>(*tick)] = std::move(action);
  }
  // The frames and their states, from log.jsonl.
  const fs::path log_path = dir / "log.jsonl";
  std::istringstream log(read_input_file(log_path.string(), "the recording's log"));
  std::string line;
  size_t line_number = 0, without_action = 0;
  while (std::getline(log, line)) {
    ++line_number;
    if (line.empty()) continue;
    const std::string where = at_line(log_path.string(), line_number);
    nlohmann::json entry;
    try {  // a key twice in a line is refused too (nlohmann alone would keep the last)
      entry = detail::parse_untrusted_json<nlohmann::json>(where, line.data(), line.size(), "not valid JSON");
    } catch (const Error&) {
      if (!log.eof()) throw;  // a whole line (it ends in a newline): not a cut one
      ++cut_lines;  // the last line of a run that was killed while writing it (no newline)
      continue;
    }
    if (!entry.is_object()) bad(where, "not a JSON object");
    if (!entry.contains("frame") || !entry["frame"].is_string()) bad(where, "no \"frame\" file name");
    if (!entry.contains("tick") || !entry["tick"].is_number_integer()) bad(where, "no integer \"tick\"");
    EpisodeFrame frame;
    frame.source = entry["frame"].get<std::string>();
    frame.image_path = (dir / frame.source).string();
    frame.where = where;
    if (model.state_dim > 0) {
      const auto& state = entry.contains("state") ? entry["state"] : nlohmann::json();
      if (!state.is_array() || state.size() != static_cast<size_t>(model.state_dim)) {
        bad(where, "\"state\" must hold the model's " + std::to_string(model.state_dim) + " values");
      }
      for (const auto& v : state) {
        if (!v.is_number() || !std::isfinite(v.get<double>())) bad(where, "\"state\" holds a value that is not a finite number");
        frame.state.push_back(v.get<float>());
      }
    }
    const int64_t tick = entry["tick"].get<int64_t>();
    for (int64_t t = tick; t < tick + model.chunk_size; ++t) {
      const auto it = executed.find(t);
      if (it == executed.end()) break;  // the chunk ends where the robot stopped following a policy
      frame.demonstration.insert(frame.demonstration.end(), it->second.begin(), it->second.end());
    }
    if (frame.demonstration.empty()) {
      ++without_action;
      continue;
    }
    ep.frames.push_back(std::move(frame));
  }
  if (cut_lines > 0) ep.notes.push_back("skipped the last line of a file cut short (the recording was killed while writing)");
  if (without_action > 0) {
    ep.notes.push_back(std::to_string(without_action) + " frame(s) skipped: no action was executed at their tick (a safe action)");
  }
  if (ep.frames.empty()) bad(ep.path, "no frame with an executed action to compare with");
  return ep;
}

// An actions CSV's rows as frames: the frame column's text (or, without one, the row's 0-based
// index), where it is, and the demonstration from that frame on (steps x action_dim).
struct DemonstrationRow {
  std::string key, where;
  std::vector<float> demonstration;
};
struct DemonstrationRows {
  std::vector<DemonstrationRow> rows;
  bool one_action_per_row = false;  ///< each row one action: a frame's chunk is the rows that follow
};

bool is_true(const std::string& cell) { return cell == "1" || cell == "true" || cell == "True" || cell == "TRUE"; }

// The long form, a chunk over rows: "file,chunk_index,steering,throttle,is_pad", chunk_index
// 0, 1, ... for each frame's rows, padded steps (is_pad true: past the episode's end) left out.
DemonstrationRows long_form_rows(const CsvTable& table, size_t step_column, const ModelInfo& model,
                                 std::vector<std::string>& names) {
  const std::optional<size_t> pad_column = column_named(table, "is_pad");
  std::vector<size_t> skip{step_column};
  if (pad_column) skip.push_back(*pad_column);
  if (step_column == 0) bad(table.path, "the first column is the frame's ('file' or 'frame'), then chunk_index");
  const ActionColumns columns = action_columns(table, model.action_dim, 1, skip);
  if (columns.column.size() != 1) bad(table.path, "a long-form CSV (chunk_index) holds one step per row: no NAME@STEP columns");
  names = columns.names;
  DemonstrationRows out;
  std::map<std::string, size_t> seen;  // frame -> its index in out.rows
  size_t expected_step = 0;
  bool padded = false;
  for (const auto& row : table.rows) {
    const std::string where = at_line(table.path, row.line);
    const std::string& key = row.cells[0];
    const std::optional<size_t> step = parse_index(row.cells[step_column]);
    if (!step) bad(where + " column 'chunk_index'", "'" + row.cells[step_column] + "' is not a step number");
    if (out.rows.empty() || out.rows.back().key != key) {
      if (seen.count(key)) bad(where, "frame '" + key + "' appears again after other frames (its rows must be together)");
      seen[key] = out.rows.size();
      out.rows.push_back({key, where, {}});
      expected_step = 0;
      padded = false;
    }
    if (*step != expected_step) {
      bad(where + " column 'chunk_index'", "step " + row.cells[step_column] + " where " + std::to_string(expected_step) +
          " comes next (each frame's rows run 0, 1, 2, ...)");
    }
    ++expected_step;
    padded |= pad_column && is_true(row.cells[*pad_column]);
    if (padded) continue;  // past the episode's end: nothing to compare with
    for (size_t c : columns.column[0]) out.rows.back().demonstration.push_back(table.number(row, c));
  }
  for (const auto& r : out.rows) {
    if (r.demonstration.empty()) bad(r.where, "frame '" + r.key + "' has only padded steps (is_pad at chunk_index 0)");
  }
  return out;
}

DemonstrationRows demonstration_rows(const CsvTable& table, const ModelInfo& model, std::vector<std::string>& names,
                                     std::vector<std::string>& notes) {
  if (const std::optional<size_t> step = column_named(table, "chunk_index")) return long_form_rows(table, *step, model, names);
  // Without a frame column: every column a value, in frame order.
  size_t first = 1;
  if (!is_frame_column_name(table.header[0])) {
    std::vector<std::string> all;
    for (const auto& h : table.header) {
      const std::string name = h.substr(0, h.rfind('@'));
      if (std::find(all.begin(), all.end(), name) == all.end()) all.push_back(name);
    }
    if (all.size() == static_cast<size_t>(model.action_dim)) {
      first = 0;
      notes.push_back(table.path + " has no frame column: its rows are the frames in order");
    }
  }
  const ActionColumns columns = action_columns(table, model.action_dim, first);
  names = columns.names;
  DemonstrationRows out;
  out.one_action_per_row = columns.column.size() == 1;
  for (size_t r = 0; r < table.rows.size(); ++r) {
    const auto& row = table.rows[r];
    DemonstrationRow d{first == 0 ? std::to_string(r) : row.cells[0], at_line(table.path, row.line), {}};
    for (const auto& step : columns.column) {
      for (size_t c : step) d.demonstration.push_back(table.number(row, c));
    }
    out.rows.push_back(std::move(d));
  }
  return out;
}

// --state last-action|mean|zeros: the states an episode without a states CSV gets, as act_drive
// would feed them (last-action: the action demonstrated at the frame before; the first frame, and
// mean: the training statistics' middle).
void fill_states(Episode& ep, const ModelInfo& model, const std::string& how) {
  const size_t dim = static_cast<size_t>(model.state_dim);
  std::vector<float> mean(dim);
  for (size_t i = 0; i < dim && i < model.state_low.size() && i < model.state_high.size(); ++i) {
    mean[i] = (model.state_low[i] + model.state_high[i]) / 2.0f;
  }
  if (how == "last-action" && dim > static_cast<size_t>(model.action_dim)) {
    bad(ep.path, "--state last-action: the model's state has " + std::to_string(dim) + " values but its action only " +
        std::to_string(model.action_dim) + " (use --state mean, zeros or a states CSV)");
  }
  for (size_t f = 0; f < ep.frames.size(); ++f) {
    std::vector<float>& state = ep.frames[f].state;
    if (how == "zeros") {
      state.assign(dim, 0.0f);
    } else if (how == "mean" || f == 0) {
      state = mean;
    } else {
      const std::vector<float>& before = ep.frames[f - 1].demonstration;
      state.assign(before.begin(), before.begin() + static_cast<std::ptrdiff_t>(dim));
    }
  }
  ep.notes.push_back(how == "last-action" ? "states: the action demonstrated at the frame before (the first frame: the "
                                            "training mean), --state last-action"
                     : how == "mean"      ? "states: the training mean for every frame, --state mean"
                                          : "states: zeros for every frame, --state zeros");
}

Episode read_frames_and_csv(const EpisodeSources& sources, const ModelInfo& model) {
  const fs::path p(sources.episode);
  const bool is_video = !fs::is_directory(p);
  if (is_video && !is_video_file(p)) {
    bad(sources.episode, "not a folder (of images or an act_drive recording) nor a video (mp4, avi, mkv, mov, webm)");
  }
  Episode ep{p.string(), is_video ? "video + CSV" : "image folder + CSV", is_video ? p.string() : "", {}, {}, {}};
  check_state_model(model, ep.path);
  if (sources.actions_csv.empty()) bad(ep.path, "an image folder or a video needs --actions FILE.csv (the demonstration)");
  if (model.state_dim > 0 && sources.states_csv.empty() && sources.state.empty()) {
    bad(ep.path, "the model takes a robot state of " + std::to_string(model.state_dim) + " values: give --states FILE.csv, "
        "or --state last-action|mean|zeros (as act_drive feeds it)");
  }
  const std::vector<fs::path> images = is_video ? std::vector<fs::path>{} : files_in(p, is_image_file);
  if (!is_video && images.empty()) bad(ep.path, "the folder has no images (png, jpg, jpeg, bmp)");

  const CsvTable actions = read_csv(sources.actions_csv, "actions");
  const DemonstrationRows demonstrations = demonstration_rows(actions, model, ep.action_names, ep.notes);
  const bool states_from_csv = model.state_dim > 0 && sources.state.empty();
  std::map<std::string, std::vector<float>> states;  // by the frame column's text (in frame order: the 0-based index)
  if (states_from_csv) {
    const CsvTable table = read_csv(sources.states_csv, "states");
    // Without a frame column (its first column's name is not a frame's and every column is a value): in frame order.
    const bool in_frame_order = !is_frame_column_name(table.header[0]) && table.header.size() == static_cast<size_t>(model.state_dim);
    const size_t first = in_frame_order ? 0 : 1;
    if (table.header.size() - first != static_cast<size_t>(model.state_dim)) {
      bad(table.path, std::to_string(table.header.size() - first) + " state columns after the frame column '" + table.header[0] +
          "' but the model's state has " + std::to_string(model.state_dim) + " values (a states CSV is a frame column then "
          "the values, or only the values, one row per frame in frame order)");
    }
    if (in_frame_order) ep.notes.push_back(table.path + " has no frame column: its rows are the frames in order");
    for (size_t r = 0; r < table.rows.size(); ++r) {
      const auto& row = table.rows[r];
      std::vector<float> values;
      for (size_t c = first; c < row.cells.size(); ++c) values.push_back(table.number(row, c));
      const std::string key = in_frame_order ? std::to_string(r) : row.cells[0];
      if (!states.emplace(key, std::move(values)).second) {
        bad(at_line(table.path, row.line), "frame '" + row.cells[0] + "' appears twice");
      }
    }
  }
  std::optional<size_t> previous_video_index;
  for (const auto& [key, where, demonstration] : demonstrations.rows) {
    EpisodeFrame frame;
    if (is_video) {
      const std::optional<size_t> index = parse_index(key);
      if (!index) bad(where + " column 1", "'" + key + "' is not a frame index of the video");
      if (previous_video_index && *index <= *previous_video_index) bad(where + " column 1", "video frame indices must increase");
      previous_video_index = frame.video_index = *index;
      frame.source = p.filename().string() + " frame " + key;
    } else if (!key.empty() && fs::is_regular_file(p / key)) {
      frame.image_path = (p / key).string();
      frame.source = key;
    } else if (const std::optional<size_t> index = parse_index(key); index && *index < images.size()) {
      frame.image_path = images[*index].string();
      frame.source = fs::relative(images[*index], p).string();
    } else {
      bad(where + " column 1", "'" + key + "' is neither an image in " + ep.path + " nor an index below its " +
          std::to_string(images.size()) + " images");
    }
    if (states_from_csv) {
      auto it = states.find(key);
      if (it == states.end()) {  // a states CSV in frame order, actions by image name
        const auto image = std::find(images.begin(), images.end(), fs::path(frame.image_path));
        if (image != images.end()) it = states.find(std::to_string(image - images.begin()));
      }
      if (it == states.end()) bad(where, "frame '" + key + "' has no row in " + sources.states_csv);
      frame.state = it->second;
    }
    frame.demonstration = demonstration;
    ep.frames.push_back(std::move(frame));
  }
  if (demonstrations.one_action_per_row) extend_demonstrations(ep.frames, model);
  if (model.state_dim > 0 && !sources.state.empty()) fill_states(ep, model, sources.state);
  return ep;
}

}  // namespace

Episode read_episode(const EpisodeSources& sources, const ModelInfo& model) {
  const fs::path p(sources.episode);
  if (!fs::exists(p)) fail(StatusCode::kNotFound, "episode not found: " + sources.episode);
  if (fs::is_directory(p) && fs::exists(p / "log.jsonl")) {
    if (!sources.actions_csv.empty() || !sources.states_csv.empty()) {
      bad(sources.episode, "an act_drive recording carries its own states and actions: drop --states and --actions");
    }
    return read_recording(p, model);
  }
  return read_frames_and_csv(sources, model);
}

EpisodeImages::EpisodeImages(const Episode& episode) : episode_(episode) {
  if (episode.video.empty()) return;
  // FFmpeg only, as act_convert and act_drive read video files: the same decoder gives the same frames.
  video_ = media::open_video(episode.video, cv::CAP_FFMPEG);
  if (!video_) fail(StatusCode::kDataLoss, "cannot open video " + episode.video + " (OpenCV/FFmpeg)");
}

cv::Mat EpisodeImages::image(size_t i) {
  const EpisodeFrame& frame = episode_.frames.at(i);
  if (!frame.image_path.empty()) {
    std::string why;
    cv::Mat image = media::read_image(frame.image_path, cv::IMREAD_COLOR, &why);
    if (image.empty()) fail(StatusCode::kDataLoss, frame.where.empty() ? why : frame.where + ": " + why);
    return image;
  }
  cv::Mat image;
  while (next_video_index_ <= frame.video_index) {
    if (!video_ || !video_->read(image)) {
      fail(StatusCode::kDataLoss, episode_.video + " has only " + std::to_string(next_video_index_) +
           " frames; the actions CSV names frame " + std::to_string(frame.video_index));
    }
    ++next_video_index_;
  }
  return image;
}

}  // namespace act::eval
