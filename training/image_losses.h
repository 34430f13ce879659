// Image losses for training and the figures of evaluation: SSIM (the
// perceptual substitute when no VGG16 is supplied, and the SSIM figure) and a
// perceptual feature distance through a user-supplied TorchScript network.
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>

namespace headcast {

// Mean SSIM of two (B, 3, H, W) images in [0, 1]: 11x11 Gaussian window
// (sigma 1.5), C1 = 0.01^2, C2 = 0.03^2, per channel, averaged; differentiable.
// The window is applied as a 1x11 and an 11x1 pass (the same value, 22
// multiply-adds a pixel instead of 121).
torch::Tensor Ssim(const torch::Tensor& a, const torch::Tensor& b);

// The same SSIM by its definition: one 2D 11x11 convolution per statistic.
// What Ssim is checked (tests) and timed (headcast-bench train) against.
torch::Tensor SsimFullWindow(const torch::Tensor& a, const torch::Tensor& b);

// `image` (B, C, H, W) with its content moved by `shift` pixels ((B, 2): x
// right, y down), bilinear, the border's values carried in; differentiable in
// both. A whole-picture shift stands in for a frame's small placement error.
torch::Tensor ShiftImage(const torch::Tensor& image, const torch::Tensor& shift);

// PSNR in dB of two images in [0, 1].
double Psnr(const torch::Tensor& a, const torch::Tensor& b);
double PsnrOfMse(double mse);

// The figures of a picture against its target (images in [0, 1]): what
// evaluation and the benchmarks report per frame.
struct ImageScore {
  double mse = 0, psnr = 0, ssim = 0;
};
ImageScore ScoreImage(const torch::Tensor& image, const torch::Tensor& target);

// Distances between a network's features of two images (METHOD §4's VGG16
// term). The file is a TorchScript module (torch.jit.save) whose forward takes
// (B, 3, H, W) RGB normalised with ImageNet's mean and deviation and returns a
// tensor or a list/tuple of tensors (e.g. VGG16's relu1_2 .. relu4_3); the loss
// is the sum over them of the mean squared difference. Weights cannot be
// downloaded here: the user supplies the file.
class PerceptualLoss {
 public:
  // Throws naming the file when it is missing or not a usable TorchScript module.
  explicit PerceptualLoss(const std::string& path);
  ~PerceptualLoss();
  torch::Tensor operator()(const torch::Tensor& a, const torch::Tensor& b);
  const std::string& path() const { return path_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string path_;
};

}  // namespace headcast
