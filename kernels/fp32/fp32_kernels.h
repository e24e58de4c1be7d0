// Float32 kernels of the FP32 path: GEMM (Eigen), convolution tiles (im2col per tile, never for a
// whole image), max-pool, LayerNorm, softmax, activations. Pure compute on raw pointers: no
// allocation, no threads, no knowledge of ACT. Callers split work into tiles and run tiles in
// parallel; every function here computes one tile.
//
// Layouts: images are NHWC (batch 1): element (y, x, c) at (y * width + x) * channels + c.
// Matrices are row-major with explicit leading dimensions (elements between rows).
#pragma once

#include <cstddef>
#include <cstdint>

namespace act::kernels {

/// C[m x n] = A[m x k] * B^T, B stored [n x k] row-major (the PyTorch Linear / OHWI conv layout).
/// Overwrites C. lda >= k, ldb >= k, ldc >= n. Runs the process's FP32 GEMM variant (gemm_f32.h).
void gemm_f32_nt(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c,
                 size_t ldc);

/// C[m x n] = A[m x k] * B[k x n], B row-major (ldb >= n). Overwrites C.
void gemm_f32_nn(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c,
                 size_t ldc);

struct Conv2dShape {
  int in_h = 0, in_w = 0, in_c = 0;
  int out_h = 0, out_w = 0, out_c = 0;
  int kernel_h = 1, kernel_w = 1;
  int stride = 1, pad = 0, dilation = 1;
  int patch_size() const { return kernel_h * kernel_w * in_c; }
  /// Output size of one spatial dim, as PyTorch computes it.
  static int out_dim(int in, int kernel, int stride, int pad, int dilation) {
    return (in + 2 * pad - dilation * (kernel - 1) - 1) / stride + 1;
  }
  /// A square-kernel conv of an in_h x in_w x in_c input, with its output size computed.
  static Conv2dShape square(int in_h, int in_w, int in_c, int out_c, int kernel, int stride, int pad, int dilation = 1) {
    Conv2dShape s;
    s.in_h = in_h;
    s.in_w = in_w;
    s.in_c = in_c;
    s.out_c = out_c;
    s.kernel_h = s.kernel_w = kernel;
    s.stride = stride;
    s.pad = pad;
    s.dilation = dilation;
    s.out_h = out_dim(in_h, kernel, stride, pad, dilation);
    s.out_w = out_dim(in_w, kernel, stride, pad, dilation);
    return s;
  }
};

/// Gathers the patches of output pixels [pixel_begin, pixel_begin + count) (row-major pixel index)
/// into `patches` [count x patch_size] with patch order (ky, kx, c); taps in the padding are 0.
void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches);

/// 2-D max-pool over NHWC for output rows [row_begin, row_end). Padding never wins (it is skipped).
void maxpool_nhwc_f32(int in_h, int in_w, int channels, int kernel, int stride, int pad, int out_h, int out_w,
                      const float* input, float* output, int row_begin, int row_end);

/// Row-wise LayerNorm over `cols` values: (x - mean) / sqrt(biased var + eps) * gamma + beta.
void layernorm_rows_f32(int rows, int cols, const float* x, size_t ldx, const float* gamma, const float* beta,
                        float eps, float* y, size_t ldy);

/// In-place numerically stable softmax of each row.
void softmax_rows_f32(int rows, int cols, float* x, size_t ldx);

void relu_f32(size_t n, float* x);
/// Exact (erf) GELU, as torch.nn.functional.gelu with approximate="none".
void gelu_f32(size_t n, float* x);
/// y[i] = a[i] + b[i]; y may be a or b.
void add_f32(size_t n, const float* a, const float* b, float* y);

// LayerNorm, softmax, ReLU, GELU and add run the SIMD variant chosen once per process
// (elementwise_f32.h states each variant's agreement with the scalar reference).

}  // namespace act::kernels
