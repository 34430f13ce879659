// SSIM, PSNR and the TorchScript perceptual loss.
#include "training/image_losses.h"

#include <torch/script.h>

#include <cmath>
#include <filesystem>
#include <vector>

namespace headcast {
namespace {

// The 11-tap Gaussian (sigma 1.5) of SSIM's standard window.
torch::Tensor GaussianTaps() {
  const int size = 11;
  const double sigma = 1.5;
  torch::Tensor g = torch::arange(size, torch::kFloat32) - (size - 1) / 2.0;
  g = torch::exp(-g * g / (2 * sigma * sigma));
  return g / g.sum();
}

// The 11x11 Gaussian window is separable: a 1x11 pass and an 11x1 pass cost
// 22 multiply-adds a pixel where the 2D window costs 121, with the same result
// up to rounding. Valid convolution, as the 2D window had: (H - 10, W - 10).
torch::Tensor GaussianBlur(const torch::Tensor& x, const torch::Tensor& taps) {
  namespace F = torch::nn::functional;
  const int64_t k = x.size(1);
  const auto groups = F::Conv2dFuncOptions().groups(k);
  const torch::Tensor rows = F::conv2d(x, taps.view({1, 1, 1, -1}).expand({k, 1, 1, taps.size(0)}), groups);
  return F::conv2d(rows, taps.view({1, 1, -1, 1}).expand({k, 1, taps.size(0), 1}), groups);
}

// The SSIM map's mean from the windowed means, second moments and cross moment.
torch::Tensor SsimFromMoments(const torch::Tensor& mu_a, const torch::Tensor& mu_b, const torch::Tensor& aa,
                              const torch::Tensor& bb, const torch::Tensor& ab) {
  const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
  const torch::Tensor var_a = aa - mu_a * mu_a;
  const torch::Tensor var_b = bb - mu_b * mu_b;
  const torch::Tensor cov = ab - mu_a * mu_b;
  const torch::Tensor map =
      ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a * mu_a + mu_b * mu_b + c1) * (var_a + var_b + c2));
  return map.mean();
}

}  // namespace

torch::Tensor Ssim(const torch::Tensor& a, const torch::Tensor& b) {
  TORCH_CHECK(a.dim() == 4 && a.sizes() == b.sizes(), "Ssim: two (B, C, H, W) images of one size");
  const int64_t c = a.size(1);
  const torch::Tensor taps = GaussianTaps().to(a.dtype());
  // One blur per image for its mean and second moment (a target without
  // gradient costs no backward pass), one for the cross term.
  const std::vector<torch::Tensor> moments_a = GaussianBlur(torch::cat({a, a * a}, 1), taps).split(c, 1);
  const std::vector<torch::Tensor> moments_b = GaussianBlur(torch::cat({b, b * b}, 1), taps).split(c, 1);
  return SsimFromMoments(moments_a[0], moments_b[0], moments_a[1], moments_b[1], GaussianBlur(a * b, taps));
}

torch::Tensor SsimFullWindow(const torch::Tensor& a, const torch::Tensor& b) {
  TORCH_CHECK(a.dim() == 4 && a.sizes() == b.sizes(), "SsimFullWindow: two (B, C, H, W) images of one size");
  const int64_t c = a.size(1);
  const torch::Tensor g = GaussianTaps().to(a.dtype());
  const torch::Tensor window = torch::outer(g, g).expand({c, 1, g.size(0), g.size(0)}).contiguous();
  auto blur = [&](const torch::Tensor& x) {
    return torch::nn::functional::conv2d(x, window, torch::nn::functional::Conv2dFuncOptions().groups(c));
  };
  return SsimFromMoments(blur(a), blur(b), blur(a * a), blur(b * b), blur(a * b));
}

double PsnrOfMse(double mse) { return 10 * std::log10(1.0 / std::max(mse, 1e-12)); }

double Psnr(const torch::Tensor& a, const torch::Tensor& b) { return PsnrOfMse(torch::mse_loss(a, b).item<double>()); }

ImageScore ScoreImage(const torch::Tensor& image, const torch::Tensor& target) {
  ImageScore s;
  s.mse = torch::mse_loss(image, target).item<double>();
  s.psnr = PsnrOfMse(s.mse);
  s.ssim = Ssim(image, target).item<double>();
  return s;
}

struct PerceptualLoss::Impl {
  torch::jit::Module module;
  torch::Tensor mean, std;
};

PerceptualLoss::PerceptualLoss(const std::string& path) : impl_(std::make_unique<Impl>()), path_(path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such file (a VGG16 TorchScript file)");
  try {
    impl_->module = torch::jit::load(path, torch::kCPU);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": not a TorchScript module (" + std::string(e.what()).substr(0, 200) + ")");
  }
  impl_->module.eval();
  for (auto p : impl_->module.parameters()) p.requires_grad_(false);
  impl_->mean = torch::tensor({0.485f, 0.456f, 0.406f}).view({1, 3, 1, 1});
  impl_->std = torch::tensor({0.229f, 0.224f, 0.225f}).view({1, 3, 1, 1});
  // One call on a small image now, so a module with the wrong interface fails here and not mid-training.
  try {
    const torch::Tensor x = torch::rand({1, 3, 32, 32});
    (*this)(x, x);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": the module does not map (B, 3, H, W) images to features (" +
                             std::string(e.what()).substr(0, 200) + ")");
  }
}

PerceptualLoss::~PerceptualLoss() = default;

torch::Tensor PerceptualLoss::operator()(const torch::Tensor& a, const torch::Tensor& b) {
  const torch::Tensor both = torch::cat({a, b}, 0);
  const torch::IValue out = impl_->module.forward({(both - impl_->mean) / impl_->std});
  std::vector<torch::Tensor> features;
  if (out.isTensor()) {
    features.push_back(out.toTensor());
  } else if (out.isTensorList()) {
    for (const auto& t : out.toTensorVector()) features.push_back(t);
  } else if (out.isTuple() || out.isList()) {
    const auto elements = out.isTuple() ? out.toTupleRef().elements().vec() : out.toListRef().vec();
    for (const auto& e : elements) features.push_back(e.toTensor());
  } else {
    throw std::runtime_error(path_ + ": forward must return a tensor or a list of tensors");
  }
  torch::Tensor loss = torch::zeros({});
  const int64_t n = a.size(0);
  for (const auto& f : features) loss = loss + torch::mse_loss(f.narrow(0, 0, n), f.narrow(0, n, n));
  return loss;
}

torch::Tensor ShiftImage(const torch::Tensor& image, const torch::Tensor& shift) {
  namespace F = torch::nn::functional;
  const int64_t b = image.size(0), h = image.size(2), w = image.size(3);
  // affine_grid's normalised coordinates span 2 over the picture (align_corners
  // false); the content moves by +shift when each pixel samples -shift away.
  const torch::Tensor to_unit = torch::tensor({-2.0f / static_cast<float>(w), -2.0f / static_cast<float>(h)});
  const torch::Tensor eye = torch::tensor({1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f}).view({1, 2, 3});
  const torch::Tensor theta = eye + torch::constant_pad_nd((shift * to_unit).view({b, 2, 1}), {2, 0});
  const torch::Tensor grid = F::affine_grid(theta, {b, image.size(1), h, w}, false);
  return F::grid_sample(
      image, grid, F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
}

}  // namespace headcast
