// The geometry of a 2-D NHWC convolution (batch 1, square stride / padding / dilation), shared by
// the float and int8 convolutions and their im2col.
#pragma once

namespace act::kernels {

struct Conv2dShape {
  int in_h = 0, in_w = 0, in_c = 0;
  int out_h = 0, out_w = 0, out_c = 0;
  int kernel_h = 1, kernel_w = 1;
  int stride = 1, pad = 0, dilation = 1;
  int patch_size() const { return kernel_h * kernel_w * in_c; }
  /// True when the patches are the input's own pixels (1x1, stride 1, no padding): no im2col.
  bool reads_input_in_place() const { return kernel_h == 1 && kernel_w == 1 && stride == 1 && pad == 0; }
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

}  // namespace act::kernels
