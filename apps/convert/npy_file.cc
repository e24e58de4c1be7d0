#include "apps/convert/npy_file.h"

#include <bit>

#include "actengine/status.h"

namespace act {

void write_npy_f32(detail::AtomicFileWriter& out, const std::vector<int64_t>& shape, const std::vector<float>& values) {
  static_assert(std::endian::native == std::endian::little, "the .npy data is written as '<f4'");
  int64_t count = 1;
  std::string dims;
  for (int64_t d : shape) {
    count *= d;
    dims += std::to_string(d) + ", ";
  }
  if (shape.size() > 1) dims.resize(dims.size() - 2);  // a 1-d shape keeps its comma: "(3,)"
  if (count != static_cast<int64_t>(values.size())) {
    fail(StatusCode::kInvalidArgument, out.path() + ": an array of shape (" + dims + ") holds " +
                                           std::to_string(count) + " values, not " + std::to_string(values.size()));
  }
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" + dims + "), }";
  // Magic (6) + version (2) + header length (2) + header + '\n' is padded with spaces to 64 bytes.
  const size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header += '\n';
  const uint16_t length = static_cast<uint16_t>(header.size());
  std::string prefix = "\x93NUMPY";
  prefix += '\x01';
  prefix += '\x00';
  prefix += static_cast<char>(length & 0xff);
  prefix += static_cast<char>(length >> 8);
  out.write(prefix + header);
  out.write(values.data(), values.size() * sizeof(float));
}

}  // namespace act
