// The skin's colour from the landmarks' regions.
#include "common/headmodel/skin_colour.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

namespace headcast {
namespace {

// Polygons of dlib's 68 points (the subject's right side first): each cheek
// from the jaw line up to its eye's outer corner and lower lid, across to the
// nose's wing and down to the mouth's corner; the nose from the bridge's top to
// its wings; the chin below the lower lip.
const std::vector<std::vector<int>> kSkinPolygons = {
    {1, 2, 3, 4, 48, 31, 40, 41, 36},
    {15, 14, 13, 12, 54, 35, 47, 46, 45},
    {27, 31, 33, 35},
    {6, 7, 8, 9, 10, 56, 57, 58},
};

// The polygons drawn into `region`, whose top left corner is `origin` in the picture.
void DrawSkinRegion(const Landmarks2d& landmarks, const cv::Point& origin, cv::Mat* region) {
  constexpr int kShift = 4;  // sub-pixel vertices (fillPoly's fixed point)
  // One polygon at a time: a cheek folded over itself on a turned head is still filled.
  for (const auto& polygon : kSkinPolygons) {
    std::vector<cv::Point> points;
    for (int l : polygon)
      points.emplace_back(static_cast<int>(std::lround((landmarks[l].x() - origin.x) * (1 << kShift))),
                          static_cast<int>(std::lround((landmarks[l].y() - origin.y) * (1 << kShift))));
    cv::fillPoly(*region, std::vector<std::vector<cv::Point>>{points}, cv::Scalar(255), cv::LINE_8, kShift);
  }
}

bool Drawable(const Landmarks2d& landmarks) {
  for (const auto& p : landmarks)
    if (!p.allFinite() || std::abs(p.x()) > 1e6 || std::abs(p.y()) > 1e6) return false;
  return true;
}

}  // namespace

cv::Mat SkinRegion(const Landmarks2d& landmarks, cv::Size size) {
  if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("SkinRegion: an empty picture");
  cv::Mat region = cv::Mat::zeros(size, CV_8U);
  if (Drawable(landmarks)) DrawSkinRegion(landmarks, cv::Point(0, 0), &region);
  return region;
}

std::optional<Eigen::Vector3f> SkinColour(const cv::Mat& image_bgr, const Landmarks2d& landmarks, int min_pixels) {
  if (image_bgr.empty() || image_bgr.type() != CV_8UC3)
    throw std::invalid_argument("SkinColour: needs an 8-bit BGR picture");
  if (!Drawable(landmarks)) return std::nullopt;
  // Only the polygons' box of the picture is drawn and read (a live frame is
  // many times the face).
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (const auto& polygon : kSkinPolygons)
    for (int l : polygon) {
      x0 = std::min(x0, landmarks[l].x()), y0 = std::min(y0, landmarks[l].y());
      x1 = std::max(x1, landmarks[l].x()), y1 = std::max(y1, landmarks[l].y());
    }
  const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(std::floor(x0)) - 1, static_cast<int>(std::floor(y0)) - 1),
                                cv::Point(static_cast<int>(std::ceil(x1)) + 2, static_cast<int>(std::ceil(y1)) + 2)) &
                       cv::Rect(0, 0, image_bgr.cols, image_bgr.rows);
  if (box.empty()) return std::nullopt;
  cv::Mat region = cv::Mat::zeros(box.size(), CV_8U);
  DrawSkinRegion(landmarks, box.tl(), &region);
  const cv::Mat pixels = image_bgr(box);
  // A histogram per channel: the median without sorting the pixels.
  std::array<std::array<int, 256>, 3> histogram{};
  int count = 0;
  for (int y = 0; y < region.rows; ++y) {
    const uint8_t* inside = region.ptr<uint8_t>(y);
    const cv::Vec3b* pixel = pixels.ptr<cv::Vec3b>(y);
    for (int x = 0; x < region.cols; ++x)
      if (inside[x]) {
        for (int c = 0; c < 3; ++c) ++histogram[c][pixel[x][c]];
        ++count;
      }
  }
  if (count < std::max(min_pixels, 1)) return std::nullopt;
  Eigen::Vector3f rgb;
  for (int c = 0; c < 3; ++c) {
    int seen = 0, value = 0;
    while (value < 255 && (seen += histogram[c][value]) * 2 < count) ++value;
    rgb[2 - c] = value / 255.f;  // BGR to RGB
  }
  return rgb;
}

}  // namespace headcast
