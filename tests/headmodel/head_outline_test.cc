// The top of a head's outline in a few numbers: measured on masks whose
// outline is known, carried by the frame's parameters, refused when malformed.
#include "common/headmodel/head_outline.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "common/headmodel/params.h"

namespace headcast {
namespace {

OutlineFrame At(double x, double y, double px_per_mm) {
  OutlineFrame f;
  f.centre_px = {x, y};
  f.px_per_mm = px_per_mm;
  return f;
}

TEST(HeadOutline, ADiscMeasuresItsRadiusInEveryArc) {
  cv::Mat disc(256, 256, CV_8U, cv::Scalar(0));
  cv::circle(disc, {128, 140}, 70, cv::Scalar(255), cv::FILLED);
  const OutlineOptions o;
  const std::vector<float> px = MeasureOutlinePx(disc, At(128, 140, 2), o);
  ASSERT_EQ(static_cast<int>(px.size()), o.bins);
  for (float r : px) EXPECT_NEAR(r, 70, 0.75);
  const std::vector<float> mm = MeasureOutline(disc, At(128, 140, 2), o);
  for (float r : mm) EXPECT_NEAR(r, 35, 0.4);  // 2 px a mm
  // A soft coverage: its half-way contour.
  cv::Mat soft;
  disc.convertTo(soft, CV_32F, 1.0 / 255);
  cv::GaussianBlur(soft, soft, {0, 0}, 3);
  for (float r : MeasureOutlinePx(soft, At(128, 140, 2), o)) EXPECT_NEAR(r, 70, 1.0);
}

TEST(HeadOutline, EachArcFollowsItsOwnPartOfTheOutline) {
  // A square's top edge is 40 px above the centre: straight up the arc reads
  // 40, an arc at 45 degrees reads about 40 * sqrt(2).
  cv::Mat square(256, 256, CV_8U, cv::Scalar(0));
  cv::rectangle(square, cv::Point(88, 88), cv::Point(168, 168), cv::Scalar(255), cv::FILLED);
  OutlineOptions o;
  o.bins = 4;
  o.rays_per_bin = 1;  // a ray through each arc's middle: 22.5, 67.5, 112.5, 157.5 degrees
  const std::vector<float> px = MeasureOutlinePx(square, At(128, 128, 1), o);
  EXPECT_NEAR(px[1], 40.5 / std::sin(67.5 * M_PI / 180), 1.0);
  EXPECT_NEAR(px[0], 40.5 / std::cos(22.5 * M_PI / 180), 1.0);
  EXPECT_NEAR(px[1], px[2], 0.5);  // symmetric
  EXPECT_NEAR(OutlineBinCentre(o, 1), 67.5 * M_PI / 180, 1e-12);
}

TEST(HeadOutline, ArcsWithoutTheHeadAreUnknown) {
  cv::Mat half(200, 200, CV_8U, cv::Scalar(0));
  cv::circle(half, {100, 100}, 50, cv::Scalar(255), cv::FILLED);
  half.colRange(100, 200).setTo(0);  // the right half gone: arcs 0..90 degrees meet nothing
  OutlineOptions o;
  o.bins = 4;
  const std::vector<float> px = MeasureOutlinePx(half, At(99.5, 100, 1), o);
  EXPECT_EQ(px[0], kOutlineUnknown);
  EXPECT_NE(px[2], kOutlineUnknown);
  EXPECT_NEAR(px[2], 50, 1.0);
  const cv::Mat empty(64, 64, CV_8U, cv::Scalar(0));
  for (float r : MeasureOutline(empty, At(32, 32, 1), o)) EXPECT_EQ(r, kOutlineUnknown);
}

TEST(HeadOutline, TheRaysStartAtTheHeadPointProjected) {
  PinholeCamera camera{300, 300, 127.5, 127.5, 256, 256};
  const RigidTransform cam_from_head{Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.01, 0.0, 0.5)};
  OutlineOptions o;
  o.centre_y_m = 0.04;
  const OutlineFrame f = OutlineFrame::Of(camera, cam_from_head, o);
  EXPECT_NEAR(f.centre_px.x(), 127.5 + 300 * 0.01 / 0.5, 1e-9);
  EXPECT_NEAR(f.centre_px.y(), 127.5 + 300 * 0.04 / 0.5, 1e-9);  // unrotated, the head's y is the camera's
  EXPECT_NEAR(f.px_per_mm, 300 / 0.5 / 1000, 1e-12);
}

TEST(HeadOutline, BadInputIsRefused) {
  const OutlineOptions o;
  EXPECT_THROW(MeasureOutlinePx(cv::Mat(), At(1, 1, 1), o), std::invalid_argument);
  EXPECT_THROW(MeasureOutlinePx(cv::Mat(8, 8, CV_16U, cv::Scalar(0)), At(1, 1, 1), o), std::invalid_argument);
  EXPECT_THROW(MeasureOutlinePx(cv::Mat(8, 8, CV_8U, cv::Scalar(0)), At(NAN, 1, 1), o), std::invalid_argument);
  EXPECT_THROW(MeasureOutline(cv::Mat(8, 8, CV_8U, cv::Scalar(0)), At(1, 1, 0), o), std::invalid_argument);
  OutlineOptions bad;
  bad.bins = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  std::string why;
  EXPECT_TRUE(OutlineIsValid({}, &why));
  EXPECT_TRUE(OutlineIsValid({0.f, 120.f}, &why));
  EXPECT_FALSE(OutlineIsValid({NAN}, &why));
  EXPECT_FALSE(OutlineIsValid({-1.f}, &why));
  EXPECT_FALSE(OutlineIsValid({kMaxOutlineMm + 1}, &why));
  EXPECT_FALSE(OutlineIsValid(std::vector<float>(kMaxOutlineBins + 1, 10.f), &why));
  EXPECT_NE(why.find("bins"), std::string::npos) << why;
}

TEST(HeadOutline, TheFrameCarriesItAndInterpolatesIt) {
  FrameParams a, b;
  a.cam_translation = b.cam_translation = Eigen::Vector3f(0, 0, 0.5f);
  a.outline = {100.f, 0.f, 80.f};
  b.outline = {110.f, 90.f, 90.f};
  const FrameParams m = InterpolateParams(a, b, 0.5);
  ASSERT_EQ(m.outline.size(), 3u);
  EXPECT_FLOAT_EQ(m.outline[0], 105.f);
  EXPECT_EQ(m.outline[1], kOutlineUnknown);  // unknown in one of the two
  b.outline.clear();
  EXPECT_TRUE(InterpolateParams(a, b, 0.3).outline.empty());
  std::string why;
  EXPECT_TRUE(a.IsValid(&why)) << why;
  a.outline[2] = NAN;
  EXPECT_FALSE(a.IsValid(&why));
  EXPECT_NE(why.find("outline"), std::string::npos) << why;
}

}  // namespace
}  // namespace headcast
