// ACT_CHECK / ACT_DCHECK: invariant checks for the kernels layer (and anything above it).
// ACT_CHECK is always on; ACT_DCHECK only in debug builds and in sanitizer builds (ACT_ENABLE_DCHECK),
// so the kernels' preconditions are exercised by the ASan/UBSan test run without costing Release.
#pragma once

namespace act::detail {

/// Prints "file:line: check failed: expr (message)" to stderr and aborts. Out of line on purpose: ISA
/// files call it, and an inline body would be emitted with their -m flags (see kernels/gemm_s8/README.md).
[[noreturn]] void check_failed(const char* file, int line, const char* expr, const char* message);

}  // namespace act::detail

#define ACT_CHECK(cond, message)                                              \
  do {                                                                        \
    if (!(cond)) ::act::detail::check_failed(__FILE__, __LINE__, #cond, message); \
  } while (0)

#if !defined(NDEBUG) || defined(ACT_ENABLE_DCHECK)
#define ACT_DCHECK_IS_ON 1
#define ACT_DCHECK(cond, message) ACT_CHECK(cond, message)
#else
#define ACT_DCHECK_IS_ON 0
#define ACT_DCHECK(cond, message) \
  do {                            \
    (void)sizeof(!(cond));        \
  } while (0)
#endif
