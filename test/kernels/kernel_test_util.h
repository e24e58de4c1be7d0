// Small helpers shared by the kernel tests.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "kernels/common/isa.h"
#include "kernels/config/kernel_config.h"

namespace act::kernels::test {

/// Distance between two floats in units in the last place (0 when equal, +0 and -0 included); a
/// large value when exactly one is NaN, 0 when both are.
inline int64_t ulp_distance(float a, float b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b) ? 0 : INT64_MAX;
  if (a == b) return 0;
  int32_t ia, ib;
  std::memcpy(&ia, &a, 4);
  std::memcpy(&ib, &b, 4);
  // Map the sign-magnitude bit patterns onto a monotonic integer line.
  const int64_t la = ia < 0 ? -static_cast<int64_t>(ia & 0x7fffffff) : ia;
  const int64_t lb = ib < 0 ? -static_cast<int64_t>(ib & 0x7fffffff) : ib;
  return la > lb ? la - lb : lb - la;
}

/// A test parameterized by ISA is named after it (".../avx512vnni").
inline std::string isa_param_name(const ::testing::TestParamInfo<Isa>& info) { return isa_name(info.param); }

/// The variants of a family the tests run, by ISA: every ISA this CPU runs that has its own variant
/// of the family, or, when ACT_ISA is set, only the variant an Engine at that level runs (none when
/// ACT_ISA is invalid: KernelConfig.ActIsaOfThisRunIsValid reports it).
template <class Table>
std::vector<Isa> isas_under_test(const Table* IsaTables::*family) {
  const char* forced = std::getenv("ACT_ISA");
  if (forced != nullptr && forced[0] != '\0') {
    const std::optional<Isa> level = parse_isa(forced);
    if (!level || !cpu_supports(*level)) return {};
    return {variant_for(*level, family).isa};
  }
  std::vector<Isa> out;
  for (Isa isa : cpu_isas()) {
    if (isa_tables(isa).*family != nullptr) out.push_back(isa);
  }
  return out;
}

/// The family's own table for `isa` (one that isas_under_test returned).
template <class Table>
const Table& table_of(Isa isa, const Table* IsaTables::*family) {
  return *(isa_tables(isa).*family);
}

/// ACT_TEST_REQUIRE_ISAS (comma-separated, set by CI to the ISA levels its machine must run: each
/// family's own variant for such a level must exist and not be the reference's); an unknown name
/// is returned as nullopt so that the caller fails on it.
inline std::vector<std::optional<Isa>> required_isas() {
  std::vector<std::optional<Isa>> out;
  const char* env = std::getenv("ACT_TEST_REQUIRE_ISAS");
  if (env == nullptr) return out;
  std::string name;
  for (const char* p = env;; ++p) {
    if (*p == ',' || *p == '\0') {
      if (!name.empty()) out.push_back(parse_isa(name));
      name.clear();
      if (*p == '\0') break;
    } else {
      name += *p;
    }
  }
  return out;
}

}  // namespace act::kernels::test
