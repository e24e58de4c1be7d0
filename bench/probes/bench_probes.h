// What act_bench reads beside the public API: the peak of the engine's threads for its main
// kernels, the model facts of a blob (its config, its multiply-accumulates per stage, its size), and
// the bytes in huge pages. Part of act_bench_probes, the benchmarks' measuring library, which
// libactengine does not carry; the one header of it the apps may include (cmake/ActLayer.cmake).
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

namespace act::kernels {
struct PeakProbe;
}  // namespace act::kernels

namespace act::bench {

/// The register-only peak probe that bounds an Engine's main kernels (int8 dot products, or float
/// FMAs): the same probe as act_kernel_bench's, read on several threads at once
/// (graph/peak_together.h: one core's reading times T overstates T cores).
class KernelPeak {
 public:
  /// No probe (the scalar reference's level).
  KernelPeak() = default;
  /// The probe for kernels of the level ModelInfo::isa names (the scalar reference when it names
  /// none) and of `int8` or float multiply-accumulates.
  KernelPeak(const std::string& isa, bool int8);
  bool has_probe() const { return probe_ != nullptr; }
  /// The probe's instruction, e.g. "vpdpbusd_zmm"; "" without a probe.
  const char* probe_name() const;
  /// The kernels' level as the kernels spell it, e.g. "avx512vnni".
  const char* isa_name() const;
  /// Sustained GMAC/s of the probe on `threads` threads at once (peak_probe_threads); 0 without one.
  double read(int threads) const;

 private:
  int isa_ = 0;  // a kernels::Isa
  const kernels::PeakProbe* probe_ = nullptr;
};

/// The threads a peak of `threads` is read on: at least one, at most one per online core.
int peak_probe_threads(int threads);

/// Multiply-accumulates of one inference, per stage.
struct Macs {
  double backbone = 0, projections = 0, encoder = 0, decoder = 0, head = 0;
  double total() const { return backbone + projections + encoder + decoder + head; }
};

/// A blob's model facts, from its config. The blob stays open (mapped, its checksum verified) for
/// the object's lifetime.
class BlobFacts {
 public:
  /// Throws act::Error as the blob reader does (kNotFound, kDataLoss, ...).
  static BlobFacts open(const std::string& path);
  BlobFacts(BlobFacts&&) noexcept;
  BlobFacts& operator=(BlobFacts&&) noexcept;
  ~BlobFacts();

  size_t file_size() const;
  /// One line: backbone, dims, layers, cameras.
  std::string summary() const;
  /// The model config as the blob records it.
  nlohmann::json config_json() const;
  Macs macs() const;

 private:
  struct Impl;
  explicit BlobFacts(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Bytes of the engines' weights and values in huge pages, in this process.
size_t huge_page_bytes();

}  // namespace act::bench
