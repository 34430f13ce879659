// Landmark repair by pyramidal Lucas-Kanade flow.
#include "common/tracking/landmark_repair.h"

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <vector>

#include "common/core/options.h"

namespace headcast {
namespace {

struct Range {
  int first, last;  // dlib's 68-point indices, inclusive
};
constexpr std::array<Range, kNumRepairRegions> kRegions = {{{17, 21}, {22, 26}, {36, 41}, {42, 47}, {48, 67}}};

cv::Point2f ToCv(const Eigen::Vector2d& p) { return {static_cast<float>(p.x()), static_cast<float>(p.y())}; }

}  // namespace

const char* LandmarkRegionName(LandmarkRegion region) {
  switch (region) {
    case LandmarkRegion::kRightBrow:
      return "right_brow";
    case LandmarkRegion::kLeftBrow:
      return "left_brow";
    case LandmarkRegion::kRightEye:
      return "right_eye";
    case LandmarkRegion::kLeftEye:
      return "left_eye";
    case LandmarkRegion::kMouth:
      return "mouth";
  }
  return "?";
}

void LandmarkRepairOptions::Check() const {
  OptionsCheck c("LandmarkRepairOptions");
  c.InRange("max_disagreement", max_disagreement, 0.001, 10.0).Positive("max_flow_error_px", max_flow_error_px);
  c.InRange("min_sure_share", min_sure_share, 0.0, 1.0).InRange("max_frames", max_frames, 0, 100000);
  c.ThrowIfErrors();
}

LandmarkRepair::LandmarkRepair(const LandmarkRepairOptions& options) : options_((options.Check(), options)) {}

LandmarkRepair::Regions LandmarkRepair::Check(const cv::Mat& previous_gray, const Landmarks2d& previous,
                                              const cv::Mat& gray, Landmarks2d* landmarks) {
  if (!options_.enabled || previous_gray.empty() || previous_gray.size() != gray.size() ||
      previous_gray.type() != CV_8UC1 || gray.type() != CV_8UC1)
    return {};
  const double eye_distance = (previous[36] - previous[45]).norm();
  if (!(eye_distance > 4)) return {};
  auto checked = [&](int r) {
    return options_.eyes ||
           (r != static_cast<int>(LandmarkRegion::kRightEye) && r != static_cast<int>(LandmarkRegion::kLeftEye));
  };
  std::vector<cv::Point2f> from, to, back;
  std::vector<int> index;
  for (int r = 0; r < kNumRepairRegions; ++r) {
    if (!checked(r)) continue;
    for (int i = kRegions[r].first; i <= kRegions[r].last; ++i) {
      from.push_back(ToCv(previous[i]));
      index.push_back(i);
    }
  }
  // The flow runs in the landmarks' box with a margin (the pyramids of a
  // whole frame cost more than the flow itself).
  const int window = std::max(9, static_cast<int>(eye_distance / 5) | 1);
  cv::Rect2f around = cv::boundingRect(from);
  const float margin = 2.0f * window + 8;
  const cv::Rect box =
      cv::Rect(cv::Point(static_cast<int>(around.x - margin), static_cast<int>(around.y - margin)),
               cv::Point(static_cast<int>(around.br().x + margin), static_cast<int>(around.br().y + margin))) &
      cv::Rect(0, 0, gray.cols, gray.rows);
  if (box.width < window || box.height < window) return {};
  const cv::Point2f offset(static_cast<float>(box.x), static_cast<float>(box.y));
  for (auto& p : from) p -= offset;
  std::vector<uchar> ok_forward, ok_back;
  std::vector<float> error;
  // Windows of a fifth of the eye distance (at least 9 px): the size of a lip
  // or a brow, with three pyramid levels for a fast-moving head.
  const cv::Size size(window, window);
  cv::calcOpticalFlowPyrLK(previous_gray(box), gray(box), from, to, ok_forward, error, size, 3);
  cv::calcOpticalFlowPyrLK(gray(box), previous_gray(box), to, back, ok_back, error, size, 3);
  for (auto& p : to) p += offset;
  for (auto& p : back) p += offset;
  for (auto& p : from) p += offset;
  std::array<Eigen::Vector2d, kNumLandmarks> carried;
  std::array<bool, kNumLandmarks> sure{};
  for (size_t k = 0; k < from.size(); ++k) {
    const int i = index[k];
    carried[i] = Eigen::Vector2d(to[k].x, to[k].y);
    sure[i] = ok_forward[k] && ok_back[k] && cv::norm(back[k] - from[k]) <= options_.max_flow_error_px;
  }
  Regions regions;
  for (int r = 0; r < kNumRepairRegions; ++r) {
    if (!checked(r)) continue;
    const Range range = kRegions[r];
    int n = 0, n_sure = 0;
    double disagreement = 0;
    Eigen::Vector2d motion = Eigen::Vector2d::Zero();  // the sure points' mean motion
    for (int i = range.first; i <= range.last; ++i, ++n) {
      if (!sure[i]) continue;
      ++n_sure;
      disagreement += ((*landmarks)[i] - carried[i]).norm();
      motion += carried[i] - previous[i];
    }
    const bool disputed = n_sure >= options_.min_sure_share * n && n_sure > 0 &&
                          disagreement / n_sure > options_.max_disagreement * eye_distance;
    if (disputed) regions.disputed |= 1u << r;
    if (!disputed || !options_.repair || runs_[r] >= options_.max_frames) {
      runs_[r] = 0;
      continue;
    }
    ++runs_[r];
    motion /= n_sure;
    for (int i = range.first; i <= range.last; ++i) (*landmarks)[i] = sure[i] ? carried[i] : previous[i] + motion;
    regions.repaired |= 1u << r;
  }
  return regions;
}

}  // namespace headcast
