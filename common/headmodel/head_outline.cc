#include "common/headmodel/head_outline.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "common/core/options.h"

namespace headcast {

void OutlineOptions::Check() const {
  OptionsCheck c("OutlineOptions");
  c.InRange("bins", bins, 1, kMaxOutlineBins).InRange("rays_per_bin", rays_per_bin, 1, 256);
  c.InRange("centre_y_m", centre_y_m, -0.2, 0.2);
  c.ThrowIfErrors();
}

OutlineFrame OutlineFrame::Of(const PinholeCamera& camera, const RigidTransform& cam_from_head,
                              const OutlineOptions& options) {
  const Eigen::Vector3d point =
      cam_from_head.rotation * Eigen::Vector3d(0, options.centre_y_m, 0) + cam_from_head.translation;
  OutlineFrame f;
  f.centre_px = camera.Project(point);
  f.px_per_mm = point.z() > 0 ? camera.fy / point.z() / 1000 : 0;
  return f;
}

double OutlineBinWidth(const OutlineOptions& options) { return M_PI / options.bins; }
double OutlineBinCentre(const OutlineOptions& options, int k) { return (k + 0.5) * OutlineBinWidth(options); }

namespace {

// The mask's inside share at (x, y), bilinear; 0 beyond the picture.
template <typename T>
float Sample(const cv::Mat& m, double x, double y, float scale) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  auto at = [&](int xi, int yi) -> float {
    return xi < 0 || yi < 0 || xi >= m.cols || yi >= m.rows ? 0.f : m.at<T>(yi, xi) * scale;
  };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) +
         fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

// From beyond the picture inward, the first radius where the ray is inside.
template <typename T>
std::optional<double> OutermostInside(const cv::Mat& m, float scale, const Eigen::Vector2d& c, double angle) {
  const double dx = std::cos(angle), dy = -std::sin(angle);  // up is +angle; the picture's y runs down
  const double r_max = std::hypot(std::max(c.x(), m.cols - c.x()), std::max(c.y(), m.rows - c.y()));
  constexpr double kStep = 0.5;
  float outer = 0;
  for (double r = r_max; r >= 0; r -= kStep) {
    const float v = Sample<T>(m, c.x() + r * dx, c.y() + r * dy, scale);
    if (v >= 0.5f) {
      if (r == r_max) return r;
      return r + kStep * (v - 0.5f) / std::max(v - outer, 1e-6f);  // where the share crossed a half
    }
    outer = v;
  }
  return std::nullopt;
}

}  // namespace

std::vector<float> MeasureOutlinePx(const cv::Mat& mask, const OutlineFrame& frame, const OutlineOptions& o) {
  o.Check();
  if (mask.empty() || (mask.type() != CV_8U && mask.type() != CV_32F))
    throw std::invalid_argument("MeasureOutline: the mask must be a non-empty CV_8U or CV_32F image");
  if (!frame.centre_px.allFinite()) throw std::invalid_argument("MeasureOutline: the centre is not finite");
  std::vector<float> out(o.bins, kOutlineUnknown);
  std::vector<double> radii;
  for (int k = 0; k < o.bins; ++k) {
    radii.clear();
    for (int j = 0; j < o.rays_per_bin; ++j) {
      const double angle = k * OutlineBinWidth(o) + (j + 0.5) * OutlineBinWidth(o) / o.rays_per_bin;
      const std::optional<double> r = mask.type() == CV_8U
                                          ? OutermostInside<uint8_t>(mask, 1.f / 255, frame.centre_px, angle)
                                          : OutermostInside<float>(mask, 1.f, frame.centre_px, angle);
      if (r) radii.push_back(*r);
    }
    if (2 * radii.size() < static_cast<size_t>(o.rays_per_bin)) continue;
    std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
    out[k] = static_cast<float>(radii[radii.size() / 2]);
  }
  return out;
}

std::vector<float> MeasureOutline(const cv::Mat& mask, const OutlineFrame& frame, const OutlineOptions& o) {
  if (!(frame.px_per_mm > 0 && std::isfinite(frame.px_per_mm)))
    throw std::invalid_argument("MeasureOutline: the head point is not in front of the camera");
  std::vector<float> mm = MeasureOutlinePx(mask, frame, o);
  for (float& v : mm)
    if (v != kOutlineUnknown) v = std::clamp(static_cast<float>(v / frame.px_per_mm), 1e-3f, kMaxOutlineMm);
  return mm;
}

bool OutlineIsValid(const std::vector<float>& outline, std::string* why) {
  if (outline.size() > static_cast<size_t>(kMaxOutlineBins)) {
    if (why) *why = "outline has more than " + std::to_string(kMaxOutlineBins) + " bins";
    return false;
  }
  for (float v : outline)
    if (!(std::isfinite(v) && v >= 0 && v <= kMaxOutlineMm)) {
      if (why) *why = "outline value outside 0.." + std::to_string(static_cast<int>(kMaxOutlineMm)) + " mm";
      return false;
    }
  return true;
}

}  // namespace headcast
