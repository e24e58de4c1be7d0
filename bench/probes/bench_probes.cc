#include "bench/probes/bench_probes.h"

#include <utility>

#include "graph/aligned_buffer.h"
#include "graph/peak_together.h"
#include "kernels/common/isa.h"
#include "kernels/peak/peak_probe.h"
#include "weights/blob/actb.h"
#include "weights/blob/model_config.h"

namespace act::bench {

KernelPeak::KernelPeak(const std::string& isa, bool int8) {
  const kernels::Isa level = kernels::parse_isa(isa).value_or(kernels::Isa::kRef);
  isa_ = static_cast<int>(level);
  probe_ = kernels::isa_peak_probe(level, int8 ? kernels::PeakKind::kInt8 : kernels::PeakKind::kFp32);
}

const char* KernelPeak::probe_name() const { return probe_ ? probe_->name : ""; }

const char* KernelPeak::isa_name() const { return kernels::isa_name(static_cast<kernels::Isa>(isa_)); }

double KernelPeak::read(int threads) const { return probe_ ? graph::measure_peak_gmacs_together(*probe_, threads) : 0.0; }

int peak_probe_threads(int threads) { return graph::peak_probe_threads(threads); }

struct BlobFacts::Impl {
  ActbFile file;
  ModelConfig config;
};

BlobFacts BlobFacts::open(const std::string& path) {
  ActbFile file = ActbFile::open(path);
  ModelConfig config = ModelConfig::from_json(file.config());
  return BlobFacts(std::make_unique<Impl>(Impl{std::move(file), std::move(config)}));
}

BlobFacts::BlobFacts(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BlobFacts::BlobFacts(BlobFacts&&) noexcept = default;
BlobFacts& BlobFacts::operator=(BlobFacts&&) noexcept = default;
BlobFacts::~BlobFacts() = default;

size_t BlobFacts::file_size() const { return impl_->file.file_size(); }

std::string BlobFacts::summary() const { return impl_->config.summary(); }

nlohmann::json BlobFacts::config_json() const { return impl_->config.to_json(); }

Macs BlobFacts::macs() const {
  const ModelConfig::Macs m = impl_->config.macs();
  return {m.backbone, m.projections, m.encoder, m.decoder, m.head};
}

size_t huge_page_bytes() { return graph::AlignedBuffer::huge_page_bytes(); }

}  // namespace act::bench
