// THE requantization rule of every INT8 kernel, written down once. Every ISA variant must produce
// exactly these bits; the tests compare them with exact equality.
//
// int32 accumulator -> int8 (the "s8 out" epilogue), per output channel n:
//
//   v = float(acc) * scale[n]                          scale[n] = s_a * s_w[n] / s_out
//     or, with per-row activation scales a[m] and a float bias b[n] (output units):
//   s = a[m] * scale[n]                                scale[n] = s_w[n] / s_out
//   v = float(acc) * s
//   v = v + b[n]
//   v = v + float(r - z_r) * residual_scale            optional residual r (int8, zero point z_r),
//                                                        residual_scale = s_r / s_out
//   v = v + float(z_out)
//   v = v > qmin ? v : qmin                            clamp as floats, before rounding; a NaN
//   v = v < qmax ? v : qmax                              becomes qmin (x86 maxps / NEON fmaxnm agree)
//   q = round_half_to_even(v)                          lrintf semantics; exact, since v is in range
//
// int32 accumulator -> float (the "f32 out" epilogue), row m, channel n:
//
//   y = float(acc) * (s_a[m] * s_w[n])                 s_a per tensor or per row (dynamic quant)
//   y = y + bias[n]                                    (0 when there is no bias)
//   y = y + residual[m][n]                             optional
//   y = y > 0 ? y : 0                                  optional ReLU (a NaN becomes 0)
//
// Every operation is one IEEE-754 single-precision operation rounded to nearest: no fused
// multiply-add (the kernels layer builds with -ffp-contract=off and the barrier below keeps this
// header exact wherever it is included), no reassociation. The caller's floating-point environment
// must be the default one (round to nearest, no flush-to-zero); float(acc) rounds to nearest even
// when |acc| > 2^24.
//
// Why float and not gemmlowp's fixed point: per-channel scales, the residual add and f32 outputs
// are trivial in float, and it costs the same on NEON and less on x86 (XNNPACK's "fp32"
// requantization makes the same choice).
#pragma once

#include <cmath>
#include <cstdint>

namespace act::kernels::ref {

/// Stops the compiler from fusing the operation that produced `v` with the next one (FMA
/// contraction) even where -ffp-contract=fast is in effect.
inline float fp_barrier(float v) {
#if defined(__x86_64__) || defined(__i386__)
  __asm__("" : "+x"(v));
#elif defined(__aarch64__)
  __asm__("" : "+w"(v));
#else
  volatile float keep = v;
  v = keep;
#endif
  return v;
}

/// Round half to even (lrintf in the default rounding mode), for |v| <= 2^31 - 1.
inline int32_t round_half_even(float v) { return static_cast<int32_t>(std::nearbyint(v)); }

/// float(acc) * scale.
inline float scale_acc(int32_t acc, float scale) { return fp_barrier(static_cast<float>(acc) * scale); }

/// float(r - z_r) * residual_scale: the residual's contribution in output units.
inline float residual_term(int8_t r, int32_t residual_zero_point, float residual_scale) {
  return fp_barrier(static_cast<float>(static_cast<int32_t>(r) - residual_zero_point) * residual_scale);
}

/// Adds the output zero point, clamps to [qmin, qmax] and rounds half to even.
inline int8_t finish_s8(float v, int32_t out_zero_point, int32_t qmin, int32_t qmax) {
  v = fp_barrier(v + static_cast<float>(out_zero_point));
  const float lo = static_cast<float>(qmin), hi = static_cast<float>(qmax);
  v = v > lo ? v : lo;
  v = v < hi ? v : hi;
  return static_cast<int8_t>(round_half_even(v));
}

/// float(acc) * (a_scale * scale) + bias, the s8-out rule's scaling with a per-row activation scale
/// and a float bias; a_scale 1 and bias 0 give scale_acc(acc, scale)'s value exactly.
inline float scale_acc_row(int32_t acc, float a_scale, float scale, float bias) {
  const float s = fp_barrier(a_scale * scale);
  return fp_barrier(fp_barrier(static_cast<float>(acc) * s) + bias);
}

/// The s8-out rule without a residual.
inline int8_t requantize_s8(int32_t acc, float scale, int32_t out_zero_point, int32_t qmin, int32_t qmax) {
  return finish_s8(scale_acc(acc, scale), out_zero_point, qmin, qmax);
}

/// The s8-out rule with an int8 residual added in float before rounding.
inline int8_t requantize_s8_residual(int32_t acc, float scale, int8_t r, int32_t residual_zero_point,
                                     float residual_scale, int32_t out_zero_point, int32_t qmin, int32_t qmax) {
  const float v = fp_barrier(scale_acc(acc, scale) + residual_term(r, residual_zero_point, residual_scale));
  return finish_s8(v, out_zero_point, qmin, qmax);
}

/// The f32-out rule. `residual` is added when `has_residual`; ReLU applied when `relu`.
inline float dequantize_f32(int32_t acc, float a_scale, float w_scale, float bias, bool has_residual, float residual,
                            bool relu) {
  const float s = fp_barrier(a_scale * w_scale);
  float y = fp_barrier(static_cast<float>(acc) * s);
  y = fp_barrier(y + bias);
  if (has_residual) y = fp_barrier(y + residual);
  if (relu) y = y > 0.0f ? y : 0.0f;
  return y;
}

}  // namespace act::kernels::ref
