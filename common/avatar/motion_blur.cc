// The head's image motion between frames, and the picture smeared along it.
#include "common/avatar/motion_blur.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace headcast {

double ImageMotion::Largest(int width, int height) const {
  double largest = 0;
  for (double x : {0.0, width - 1.0})
    for (double y : {0.0, height - 1.0}) largest = std::max(largest, At(x, y).norm());
  return largest;
}

std::optional<ImageMotion> MeasureImageMotion(const RasterVertices& earlier, const RasterVertices& now,
                                              const PinholeCamera& camera, int frames, int stride) {
  if (earlier.rows() != now.rows() || frames < 1 || stride < 1) return std::nullopt;
  auto inside = [&](const Eigen::Vector3f& v, Eigen::Vector2d* pixel) {
    if (!(v.z() > 1e-3f)) return false;
    *pixel = camera.Project(v.cast<double>());
    return pixel->allFinite() && pixel->x() >= 0 && pixel->y() >= 0 && pixel->x() <= camera.width - 1 &&
           pixel->y() <= camera.height - 1;
  };
  // Normal equations of [x y 1] b = d for each of the two displacement components.
  Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
  Eigen::Matrix<double, 3, 2> atd = Eigen::Matrix<double, 3, 2>::Zero();
  int used = 0;
  for (Eigen::Index i = 0; i < now.rows(); i += stride) {
    Eigen::Vector2d p0, p1;
    if (!inside(earlier.row(i).transpose(), &p0) || !inside(now.row(i).transpose(), &p1)) continue;
    const Eigen::Vector3d row(p1.x(), p1.y(), 1);
    ata += row * row.transpose();
    atd += row * ((p1 - p0) / frames).transpose();
    ++used;
  }
  if (used < 20) return std::nullopt;
  const Eigen::LDLT<Eigen::Matrix3d> solver(ata);
  if (solver.info() != Eigen::Success) return std::nullopt;
  const Eigen::Matrix<double, 3, 2> b = solver.solve(atd);
  if (!b.allFinite()) return std::nullopt;
  ImageMotion m;
  m.a = {b(0, 0), b(1, 0), b(2, 0), b(0, 1), b(1, 1), b(2, 1)};
  return m;
}

torch::Tensor BlurAlongMotion(const torch::Tensor& image, const ImageMotion& motion, double exposure) {
  return BlurAlongMotion(image, motion, torch::scalar_tensor(exposure, image.dtype()));
}

torch::Tensor BlurAlongMotion(const torch::Tensor& image, const ImageMotion& motion, const torch::Tensor& exposure) {
  namespace F = torch::nn::functional;
  TORCH_CHECK(image.dim() == 4, "BlurAlongMotion: a (B, C, H, W) picture");
  TORCH_CHECK(exposure.numel() == 1, "BlurAlongMotion: one exposure");
  const int64_t b = image.size(0), h = image.size(2), w = image.size(3);
  const double extent = std::abs(exposure.item<double>()) * motion.Largest(static_cast<int>(w), static_cast<int>(h));
  if (!(extent >= 0.25)) return image;  // also NaN
  const int taps = std::clamp(1 + static_cast<int>(std::ceil(2 * extent)), 2, kMaxMotionBlurTaps);
  const torch::Tensor xs = torch::arange(w, torch::kFloat32).view({1, w}).expand({h, w});
  const torch::Tensor ys = torch::arange(h, torch::kFloat32).view({h, 1}).expand({h, w});
  const auto& a = motion.a;
  // grid_sample's normalised coordinates (align_corners false): pixel x is (2x + 1) / W - 1.
  const torch::Tensor flow =
      torch::stack({(xs * a[0] + ys * a[1] + a[2]) * (2.0 / w), (xs * a[3] + ys * a[4] + a[5]) * (2.0 / h)}, 2)
          .to(image.dtype());
  const torch::Tensor base = torch::stack({(xs * 2 + 1) / w - 1, (ys * 2 + 1) / h - 1}, 2).to(image.dtype());
  torch::Tensor sum;
  for (int k = 0; k < taps; ++k) {
    const torch::Tensor s = exposure.to(image.dtype()).reshape({}) * (static_cast<double>(k) / (taps - 1) - 0.5);
    const torch::Tensor grid = (base + s * flow).unsqueeze(0).expand({b, h, w, 2});
    const torch::Tensor tap = F::grid_sample(
        image, grid,
        F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
    sum = sum.defined() ? sum + tap : tap;
  }
  return sum / taps;
}

}  // namespace headcast
