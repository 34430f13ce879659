#include "training/face_regions.h"

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "common/core/options.h"

namespace headcast {

void FaceRegionOptions::Check() const {
  OptionsCheck c("FaceRegionOptions");
  c.InRange("weight", weight, 0.0, 100.0).InRange("margin", margin, 0.0, 2.0);
  c.ThrowIfErrors();
}

namespace {

Eigen::Vector2d Mean(const Landmarks2d& l, int first, int last) {
  Eigen::Vector2d m = Eigen::Vector2d::Zero();
  for (int i = first; i <= last; ++i) m += l[i];
  return m / (last - first + 1);
}

// The hull of landmarks [first, last] and [first2, last2], each point pushed
// out from the region's centre by `grow` pixels.
std::vector<cv::Point> GrownHull(const Landmarks2d& l, std::initializer_list<std::pair<int, int>> ranges, double grow) {
  std::vector<cv::Point2f> points;
  for (const auto& [first, last] : ranges)
    for (int i = first; i <= last; ++i) points.emplace_back(l[i].x(), l[i].y());
  cv::Point2f centre(0, 0);
  for (const auto& p : points) centre += p;
  centre *= 1.0f / points.size();
  std::vector<cv::Point2f> grown;
  for (const auto& p : points) {
    const cv::Point2f d = p - centre;
    const float n = std::hypot(d.x, d.y);
    grown.push_back(n > 1e-3f ? p + d * static_cast<float>(grow / n) : p);
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(grown, hull);
  std::vector<cv::Point> out;
  for (const auto& p : hull) out.emplace_back(std::lround(p.x), std::lround(p.y));
  return out;
}

// The three regions (each eye with its brow, the mouth) as grown hulls; none
// when the landmarks are not finite or the eyes coincide.
std::vector<std::vector<cv::Point>> RegionHulls(const Landmarks2d& landmarks, double margin) {
  for (const auto& p : landmarks)
    if (!p.allFinite() || p.cwiseAbs().maxCoeff() > 1e6) return {};
  const double eye_distance = (Mean(landmarks, 42, 47) - Mean(landmarks, 36, 41)).norm();
  if (eye_distance < 1) return {};
  const double grow = margin * eye_distance;
  // dlib's order: brows 17-21 (right) and 22-26 (left), eyes 36-41 and 42-47, mouth 48-59.
  return {GrownHull(landmarks, {{17, 21}, {36, 41}}, grow), GrownHull(landmarks, {{22, 26}, {42, 47}}, grow),
          GrownHull(landmarks, {{48, 59}}, grow)};
}

}  // namespace

cv::Mat FaceRegionWeights(const Landmarks2d& landmarks, cv::Size size, const FaceRegionOptions& options) {
  options.Check();
  cv::Mat weights(size, CV_32F, cv::Scalar(1.0f));
  if (options.weight == 0) return weights;
  for (const auto& r : RegionHulls(landmarks, options.margin))
    cv::fillConvexPoly(weights, r, cv::Scalar(1.0 + options.weight), cv::LINE_8);
  return weights;
}

cv::Mat FaceRegionMask(const Landmarks2d& landmarks, cv::Size size, const FaceRegionOptions& options) {
  options.Check();
  cv::Mat mask(size, CV_8U, cv::Scalar(0));
  for (const auto& r : RegionHulls(landmarks, options.margin)) cv::fillConvexPoly(mask, r, cv::Scalar(255), cv::LINE_8);
  return mask;
}

}  // namespace headcast
