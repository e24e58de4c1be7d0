// PyTorch checkpoint files (torch.save: a `.pth` / `.pt`) -> the state dict's tensors, without Python.
//
// Both formats torch.save writes: the zip format (torch >= 1.6: <name>/data.pkl + <name>/data/<key>
// storages) and the legacy one (magic, protocol and sys_info pickles, the object's pickle, the
// storage key list, then each storage's raw bytes). The pickles go through the safe reader of
// weights/import/pickle_reader.h, so a checkpoint can never run code. The state dict may be the
// saved object itself or one entry of a wrapping dict such as {"model_state_dict": ..., "epoch":
// ..., "optimizer_state_dict": ...}; only its tensors are read (optimizer state is parsed, not
// loaded).
#pragma once

#include <string>
#include <vector>

#include "weights/import/safetensors.h"

namespace act {

struct PyTorchCheckpoint {
  OwnedTensorSet state_dict{""};  ///< names as saved; tensors made contiguous, dtype kept
  std::string format;             ///< "zip" or "legacy"
  std::string location;           ///< where the state dict was: "the saved object", "entry 'model_state_dict'"
  std::vector<std::string> other_entries;  ///< the wrapping dict's other entries, described ("epoch: int 12")
  std::vector<std::string> saved_order;    ///< tensor names in the order they were saved (module registration order)
};

/// Reads the state dict of a torch.save file. `state_dict_key` picks the wrapping dict's entry when
/// the file holds several dicts of tensors (by default a lone one, else "model_state_dict",
/// "state_dict" or "model"). Throws act::Error naming the file and the problem: kNotFound,
/// kDataLoss (malformed, or damaged), kUnimplemented (a valid construct this reader refuses, e.g. a
/// GLOBAL outside the whitelist, or a dtype without a DType), kInvalidArgument (no state dict).
PyTorchCheckpoint read_pytorch_checkpoint(const std::string& path, const std::string& state_dict_key = {});

}  // namespace act
