// Iris location by converging gradients (the method of Timm and Barth, 2011),
// restricted to the lids' polygon and weighted by darkness.
#include "common/tracking/iris_locator.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "common/core/options.h"

namespace headcast {

void IrisLocatorOptions::Check() const {
  OptionsCheck c("IrisLocatorOptions");
  c.InRange("eye_width_px", eye_width_px, 12, 200).InRange("min_opening", min_opening, 0.0, 1.0);
  c.InRange("gradient_threshold", gradient_threshold, 0.0, 1.0).InRange("iris_radius", iris_radius, 0.05, 0.5);
  c.ThrowIfErrors();
}

std::array<Eigen::Vector2d, 6> EyeLandmarks(const Landmarks2d& landmarks, int first) {
  std::array<Eigen::Vector2d, 6> eye;
  for (int k = 0; k < 6; ++k) eye[k] = landmarks[first + k];
  return eye;
}

namespace {

// The eye's frame: centre, unit axis from corner 0 to corner 3, its normal
// (down in the image for an upright eye) and the corner distance.
struct EyeFrame {
  Eigen::Vector2d centre, x_axis, y_axis;
  double width = 0;
  explicit EyeFrame(const std::array<Eigen::Vector2d, 6>& eye) {
    centre = 0.5 * (eye[0] + eye[3]);
    width = (eye[3] - eye[0]).norm();
    x_axis = width > 0 ? Eigen::Vector2d((eye[3] - eye[0]) / width) : Eigen::Vector2d(1, 0);
    y_axis = Eigen::Vector2d(-x_axis.y(), x_axis.x());
  }
};

}  // namespace

Eigen::Vector2d IrisInEyeFrame(const Eigen::Vector2d& iris, const std::array<Eigen::Vector2d, 6>& eye) {
  const EyeFrame f(eye);
  if (!(f.width > 0)) return Eigen::Vector2d::Zero();
  const Eigen::Vector2d d = iris - f.centre;
  return Eigen::Vector2d(d.dot(f.x_axis), d.dot(f.y_axis)) / f.width;
}

IrisObservation LocateIris(const cv::Mat& gray, const std::array<Eigen::Vector2d, 6>& eye,
                           const IrisLocatorOptions& o) {
  IrisObservation r;
  for (const auto& p : eye)
    if (!p.allFinite()) return r;
  const EyeFrame f(eye);
  // Below a few pixels there is no iris to see; beyond the image there is nothing.
  if (gray.empty() || gray.type() != CV_8U || !(f.width >= 4) || f.width > 4.0 * std::max(gray.cols, gray.rows))
    return r;
  r.opening = 0.5 * ((eye[1] - eye[5]).norm() + (eye[2] - eye[4]).norm()) / f.width;
  if (r.opening < o.min_opening) return r;
  const cv::Rect image_box(0, 0, gray.cols, gray.rows);
  if (!image_box.contains(cv::Point(static_cast<int>(f.centre.x()), static_cast<int>(f.centre.y())))) return r;

  // The upright patch: image -> patch is p = s [x_axis; y_axis] (x - centre) + patch centre.
  const double s = o.eye_width_px / f.width;
  const int pw = static_cast<int>(std::lround(1.6 * o.eye_width_px));
  const int ph = static_cast<int>(std::lround(0.9 * o.eye_width_px));
  const Eigen::Vector2d half(0.5 * pw, 0.5 * ph);
  cv::Mat to_patch(2, 3, CV_64F);
  for (int row = 0; row < 2; ++row) {
    const Eigen::Vector2d axis = s * (row == 0 ? f.x_axis : f.y_axis);
    to_patch.at<double>(row, 0) = axis.x();
    to_patch.at<double>(row, 1) = axis.y();
    to_patch.at<double>(row, 2) = half[row] - axis.dot(f.centre);
  }
  cv::Mat patch;
  cv::warpAffine(gray, patch, to_patch, cv::Size(pw, ph), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  auto to_patch_point = [&](const Eigen::Vector2d& x) {
    const Eigen::Vector2d d = x - f.centre;
    return cv::Point(static_cast<int>(std::lround(s * d.dot(f.x_axis) + half.x())),
                     static_cast<int>(std::lround(s * d.dot(f.y_axis) + half.y())));
  };
  std::vector<cv::Point> polygon;
  for (const auto& p : eye) polygon.push_back(to_patch_point(p));
  cv::Mat inside = cv::Mat::zeros(ph, pw, CV_8U);
  cv::fillPoly(inside, std::vector<std::vector<cv::Point>>{polygon}, cv::Scalar(255));
  // The lid margins themselves (dark lashes against skin) are edges that do
  // not point at the iris: gradients come from a band just inside the lids.
  // Lashes and eyeliner lie along the margins too, so the centre is looked for
  // a little further in.
  cv::Mat gradient_region, candidates;
  cv::erode(inside, gradient_region, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
  cv::erode(inside, candidates, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(7, 7)));
  if (cv::countNonZero(gradient_region) < 8) return r;
  if (cv::countNonZero(candidates) == 0) candidates = gradient_region;

  cv::Mat smooth, gx, gy, dark;
  cv::GaussianBlur(patch, smooth, cv::Size(0, 0), 0.025 * o.eye_width_px + 0.5);
  cv::Sobel(smooth, gx, CV_32F, 1, 0);
  cv::Sobel(smooth, gy, CV_32F, 0, 1);
  // The iris is the dark blob in the eye: the mean darkness of the eye's own
  // pixels around each point (a blur normalised by the lids' mask, so dark
  // lashes outside the lids do not count).
  {
    cv::Mat inverted, weight, mask_f;
    patch.convertTo(inverted, CV_32F, -1.0, 255.0);
    inside.convertTo(mask_f, CV_32F, 1.0 / 255);
    const double sigma = 0.04 * o.eye_width_px;
    cv::GaussianBlur(inverted.mul(mask_f), dark, cv::Size(0, 0), sigma);
    cv::GaussianBlur(mask_f, weight, cv::Size(0, 0), sigma);
    cv::divide(dark, cv::max(weight, 1e-3), dark);
  }

  struct Gradient {
    float x, y, gx, gy;
  };
  std::vector<Gradient> edges;
  float strongest = 0;
  for (int y = 0; y < ph; ++y)
    for (int x = 0; x < pw; ++x)
      if (gradient_region.at<uint8_t>(y, x))
        strongest = std::max(strongest, std::hypot(gx.at<float>(y, x), gy.at<float>(y, x)));
  if (!(strongest > 0)) return r;
  for (int y = 0; y < ph; ++y)
    for (int x = 0; x < pw; ++x) {
      if (!gradient_region.at<uint8_t>(y, x)) continue;
      const float m = std::hypot(gx.at<float>(y, x), gy.at<float>(y, x));
      if (m >= o.gradient_threshold * strongest)
        edges.push_back({static_cast<float>(x), static_cast<float>(y), gx.at<float>(y, x) / m, gy.at<float>(y, x) / m});
    }
  if (edges.size() < 4) return r;

  // Objective per candidate centre c: darkness(c) * mean over edges of
  // max(0, unit(x - c) . unit gradient)^2 (edges point away from a dark centre),
  // over the edges at an iris radius from c (0.5 to 1.6 of it).
  const float radius_px = static_cast<float>(o.iris_radius * o.eye_width_px);
  const float near2 = 0.25f * radius_px * radius_px, far2 = 2.56f * radius_px * radius_px;
  cv::Mat score = cv::Mat::zeros(ph, pw, CV_32F);
  float best = 0;
  cv::Point best_at(-1, -1);
  for (int y = 0; y < ph; ++y)
    for (int x = 0; x < pw; ++x) {
      if (!candidates.at<uint8_t>(y, x)) continue;
      float sum = 0;
      for (const Gradient& e : edges) {
        const float dx = e.x - x, dy = e.y - y;
        const float n2 = dx * dx + dy * dy;
        if (n2 < near2 || n2 > far2) continue;
        const float dot = (dx * e.gx + dy * e.gy) / std::sqrt(n2);
        if (dot > 0) sum += dot * dot;
      }
      const float v = dark.at<float>(y, x) * sum;
      score.at<float>(y, x) = v;
      if (v > best) best = v, best_at = {x, y};
    }
  if (best_at.x < 0) return r;
  // Sub-pixel: the vertex of a parabola through the best score and its neighbours.
  auto refine = [&](float minus, float centre, float plus) {
    const float curvature = minus - 2 * centre + plus;
    return curvature < 0 ? std::clamp(0.5f * (minus - plus) / curvature, -0.5f, 0.5f) : 0.f;
  };
  Eigen::Vector2d p(best_at.x, best_at.y);
  if (best_at.x > 0 && best_at.x + 1 < pw)
    p.x() += refine(score.at<float>(best_at.y, best_at.x - 1), best, score.at<float>(best_at.y, best_at.x + 1));
  if (best_at.y > 0 && best_at.y + 1 < ph)
    p.y() += refine(score.at<float>(best_at.y - 1, best_at.x), best, score.at<float>(best_at.y + 1, best_at.x));
  const Eigen::Vector2d d = (p - half) / s;
  r.center = f.centre + d.x() * f.x_axis + d.y() * f.y_axis;
  r.found = true;
  return r;
}

EyeIrises LocateIrises(const cv::Mat& gray, const Landmarks2d& landmarks, const IrisLocatorOptions& options) {
  EyeIrises irises;
  irises.right = LocateIris(gray, EyeLandmarks(landmarks, 36), options);
  irises.left = LocateIris(gray, EyeLandmarks(landmarks, 42), options);
  return irises;
}

}  // namespace headcast
