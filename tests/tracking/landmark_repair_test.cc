// Landmark checks on a textured picture moved by a known shift: the flow
// carries the previous landmarks to where they went; a region the "predictor"
// put far off is disputed and (by default) replaced by the carried points;
// agreeing regions are left alone, and a run of repairs ends after max_frames.
#include "common/tracking/landmark_repair.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

namespace headcast {
namespace {

struct MovingPicture {
  cv::Mat before, after;
  Eigen::Vector2d shift{2.0, 1.0};
  Landmarks2d previous{};
  MovingPicture() {
    cv::Mat noise(240, 320, CV_8UC1);
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> grey(0, 255);
    for (int y = 0; y < noise.rows; ++y)
      for (int x = 0; x < noise.cols; ++x) noise.at<uchar>(y, x) = static_cast<uchar>(grey(rng));
    cv::GaussianBlur(noise, before, cv::Size(0, 0), 2.0);
    cv::Mat move = (cv::Mat_<double>(2, 3) << 1, 0, shift.x(), 0, 1, shift.y());
    cv::warpAffine(before, after, move, before.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    // 68 points spread over the middle of the picture; the outer eye corners 100 px apart.
    for (int i = 0; i < 68; ++i) previous[i] = Eigen::Vector2d(70 + (i % 12) * 16, 60 + (i / 12) * 22);
    previous[36] = Eigen::Vector2d(110, 80);
    previous[45] = Eigen::Vector2d(210, 80);
  }
  Landmarks2d Moved() const {
    Landmarks2d l = previous;
    for (auto& p : l) p += shift;
    return l;
  }
};

LandmarkRepairOptions Repairing() {
  LandmarkRepairOptions o;
  o.repair = true;
  return o;
}

TEST(LandmarkRepair, AJumpingRegionIsDisputedAndCarriedByTheFlowWhenAsked) {
  const MovingPicture m;
  Landmarks2d predicted = m.Moved();
  for (int i = 48; i <= 67; ++i) predicted[i].y() += 25;  // the mouth put a quarter eye-distance low
  const unsigned mouth = 1u << static_cast<int>(LandmarkRegion::kMouth);
  Landmarks2d used = predicted;
  LandmarkRepairOptions counting;
  counting.repair = false;  // disputes are counted, the predictor's points kept
  LandmarkRepair check(counting);
  LandmarkRepair::Regions regions = check.Check(m.before, m.previous, m.after, &used);
  EXPECT_EQ(regions.disputed, mouth);
  EXPECT_EQ(regions.repaired, 0u);
  for (int i = 0; i < 68; ++i) EXPECT_EQ(used[i], predicted[i]);
  LandmarkRepair repair(Repairing());
  regions = repair.Check(m.before, m.previous, m.after, &used);
  EXPECT_EQ(regions.disputed, mouth);
  EXPECT_EQ(regions.repaired, mouth);
  for (int i = 48; i <= 67; ++i) EXPECT_LT((used[i] - (m.previous[i] + m.shift)).norm(), 0.3) << "point " << i;
  for (int i = 0; i < 48; ++i) EXPECT_EQ(used[i], predicted[i]) << "point " << i;
}

TEST(LandmarkRepair, AgreeingLandmarksStayAsPredicted) {
  const MovingPicture m;
  LandmarkRepair repair(Repairing());
  Landmarks2d predicted = m.Moved();
  for (int i = 48; i <= 67; ++i) predicted[i].y() += 3;  // within the predictor's jitter
  Landmarks2d used = predicted;
  const LandmarkRepair::Regions regions = repair.Check(m.before, m.previous, m.after, &used);
  EXPECT_EQ(regions.disputed, 0u);
  EXPECT_EQ(regions.repaired, 0u);
  for (int i = 0; i < 68; ++i) EXPECT_EQ(used[i], predicted[i]);
}

TEST(LandmarkRepair, ARunOfRepairsEndsAndNothingIsCheckedWithoutAPreviousFrame) {
  const MovingPicture m;
  LandmarkRepairOptions o = Repairing();
  o.max_frames = 2;
  LandmarkRepair repair(o);
  Landmarks2d predicted = m.Moved();
  for (int i = 17; i <= 21; ++i) predicted[i].y() -= 30;  // a brow far off
  const unsigned brow = 1u << static_cast<int>(LandmarkRegion::kRightBrow);
  for (int k = 0; k < 2; ++k) {
    Landmarks2d used = predicted;
    EXPECT_EQ(repair.Check(m.before, m.previous, m.after, &used).repaired, brow) << "repair " << k;
  }
  Landmarks2d used = predicted;
  LandmarkRepair::Regions regions = repair.Check(m.before, m.previous, m.after, &used);
  EXPECT_EQ(regions.repaired, 0u) << "the predictor is trusted again";
  EXPECT_EQ(regions.disputed, brow);
  EXPECT_EQ(used[19], predicted[19]);
  EXPECT_EQ(repair.Check(m.before, m.previous, m.after, &used).repaired, brow) << "and a new run may start";
  // No previous frame, another size, or off: nothing to compare with.
  EXPECT_EQ(repair.Check(cv::Mat(), m.previous, m.after, &used).disputed, 0u);
  cv::Mat small;
  cv::resize(m.before, small, cv::Size(160, 120));
  EXPECT_EQ(repair.Check(small, m.previous, m.after, &used).disputed, 0u);
  o.enabled = false;
  LandmarkRepair off(o);
  used = predicted;
  EXPECT_EQ(off.Check(m.before, m.previous, m.after, &used).disputed, 0u);
  o.enabled = true;
  o.max_disagreement = 0;
  EXPECT_THROW(LandmarkRepair{o}, std::invalid_argument);
}

}  // namespace
}  // namespace headcast
