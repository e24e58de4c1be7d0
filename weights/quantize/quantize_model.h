// Weight quantization of an imported model into an INT8 blob: every quantizable layer's weights
// become int8, symmetric per output channel (scale = max|w| / 127, values in [-127, 127]); biases,
// norms, tables and the small layers that write the action chunk or read the robot state stay
// float32.
#pragma once

#include <string>
#include <vector>

#include "weights/import/lerobot_import.h"
#include "weights/blob/quant_config.h"

namespace act {

/// The weight names of the layers an INT8 blob may store as int8, in blob order: the backbone
/// convs, the image projection and the transformer's linears. The action head and the state
/// projections (tiny, and directly on the robot's numbers) always stay float.
std::vector<std::string> quantizable_layers(const ImportedModel& model);

/// Symmetric per-row int8 quantization of w [rows x cols]: q = round(w / s[r]), s[r] = max|w_r| / 127
/// (1 for an all-zero row).
void quantize_weight_per_row(const std::vector<float>& w, size_t rows, size_t cols, std::vector<int8_t>& q,
                             std::vector<float>& scales);

/// The INT8 blob: quantizable layers not in quant.float_layers as int8, the rest float32, and
/// `quant` in the config. Throws kInvalidArgument for a float layer that is not quantizable. The
/// writer refers to the model's float tensors (no copy): write it while `model` lives, unchanged.
ActbWriter int8_blob(const ImportedModel& model, const QuantConfig& quant);
/// Writes int8_blob(model, quant), atomically like every blob write. Returns the bytes written.
size_t write_int8_blob(const ImportedModel& model, const QuantConfig& quant, const std::string& path);

}  // namespace act
