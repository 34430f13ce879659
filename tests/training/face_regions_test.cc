// Loss weights around the eyes, brows and mouth.
#include "training/face_regions.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace headcast {
namespace {

// A frontal 68-point face in a 256 x 256 picture: eyes centred at x 90 and
// 166 (y 110), brows 20 px above them, the mouth centred at (128, 180), the
// jaw and nose where no region is.
Landmarks2d Face() {
  Landmarks2d l{};
  for (int i = 0; i < 17; ++i) l[i] = {40 + 11.0 * i, 220};          // jaw, below the mouth
  for (int i = 27; i < 36; ++i) l[i] = {128, 120 + 3.0 * (i - 27)};  // nose
  for (int side = 0; side < 2; ++side) {
    const double cx = side == 0 ? 90 : 166;
    const int brow = side == 0 ? 17 : 22, eye = side == 0 ? 36 : 42;
    for (int k = 0; k < 5; ++k) l[brow + k] = {cx - 16 + 8.0 * k, 90};
    for (int k = 0; k < 6; ++k) {
      const double a = 2 * M_PI * k / 6;
      l[eye + k] = {cx - 12 * std::cos(a), 110 - 5 * std::sin(a)};
    }
  }
  for (int k = 0; k < 12; ++k) {
    const double a = 2 * M_PI * k / 12;
    l[48 + k] = {128 - 22 * std::cos(a), 180 - 9 * std::sin(a)};
  }
  for (int k = 60; k < 68; ++k) l[k] = {128, 180};
  return l;
}

float At(const cv::Mat& w, int x, int y) { return w.at<float>(y, x); }

TEST(FaceRegionWeights, EyesBrowsAndMouthWeighUpElsewhereOne) {
  FaceRegionOptions o;
  o.weight = 4;
  const cv::Mat w = FaceRegionWeights(Face(), {256, 256}, o);
  ASSERT_EQ(w.type(), CV_32F);
  ASSERT_EQ(w.size(), cv::Size(256, 256));
  for (const cv::Point p : {cv::Point(90, 110), cv::Point(166, 110), cv::Point(90, 92), cv::Point(166, 100),
                            cv::Point(128, 180), cv::Point(107, 180)})
    EXPECT_FLOAT_EQ(At(w, p.x, p.y), 5.0f) << p;
  // Cheeks, the nose between the eyes, the forehead, the corners: 1.
  for (const cv::Point p :
       {cv::Point(60, 150), cv::Point(128, 140), cv::Point(128, 40), cv::Point(0, 0), cv::Point(255, 255)})
    EXPECT_FLOAT_EQ(At(w, p.x, p.y), 1.0f) << p;
  // The margin (0.15 of the 76 px eye distance: ~11 px) takes in the lids'
  // surroundings: 6 px below the lower lid is inside, 20 px is not.
  EXPECT_FLOAT_EQ(At(w, 90, 121), 5.0f);
  EXPECT_FLOAT_EQ(At(w, 90, 135), 1.0f);
  o.margin = 0;
  EXPECT_FLOAT_EQ(At(FaceRegionWeights(Face(), {256, 256}, o), 90, 121), 1.0f);
}

TEST(FaceRegionWeights, OffOrUnusableLandmarksGiveOnes) {
  FaceRegionOptions o;
  const auto all_ones = [](const cv::Mat& w) {
    double lo, hi;
    cv::minMaxLoc(w, &lo, &hi);
    return lo == 1 && hi == 1;
  };
  EXPECT_TRUE(all_ones(FaceRegionWeights(Face(), {64, 48}, o)));  // weight 0
  o.weight = 2;
  Landmarks2d nan = Face();
  nan[50].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(all_ones(FaceRegionWeights(nan, {256, 256}, o)));
  Landmarks2d same{};  // both eyes at the origin
  EXPECT_TRUE(all_ones(FaceRegionWeights(same, {256, 256}, o)));
  Landmarks2d far = Face();
  far[3] = {1e9, 1e9};
  EXPECT_TRUE(all_ones(FaceRegionWeights(far, {256, 256}, o)));
  // A face partly outside the picture is clipped, not refused.
  Landmarks2d shifted = Face();
  for (auto& p : shifted) p.x() -= 120;
  EXPECT_FLOAT_EQ(At(FaceRegionWeights(shifted, {256, 256}, o), 8, 180), 3.0f);
}

TEST(FaceRegionMask, TheWeightedRegionsWhateverTheWeight) {
  FaceRegionOptions o;  // weight 0: the mask does not depend on it
  const cv::Mat m = FaceRegionMask(Face(), {256, 256}, o);
  ASSERT_EQ(m.type(), CV_8U);
  o.weight = 4;
  const cv::Mat w = FaceRegionWeights(Face(), {256, 256}, o);
  EXPECT_EQ(cv::countNonZero(m != (w > 1.5f)), 0);
  EXPECT_GT(cv::countNonZero(m), 1000);
  Landmarks2d nan = Face();
  nan[40].y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(cv::countNonZero(FaceRegionMask(nan, {256, 256}, o)), 0);
}

TEST(FaceRegionWeights, OptionsAreChecked) {
  FaceRegionOptions o;
  o.weight = -1;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  o.weight = 1;
  o.margin = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(o.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
