// The skin's colour: the region the landmarks give, its median, and what is refused.
#include "common/headmodel/skin_colour.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"

namespace headcast {
namespace {

// The built-in head's landmarks seen from the front at 256 x 256.
Landmarks2d FrontalLandmarks() {
  const HeadModel model = MakeBuiltinHead();
  const HeadModelOutput posed = model.Forward(HeadModelParams{});
  const PinholeCamera camera = PinholeCamera::FromFovY(256, 256, 24);
  const RigidTransform cam_from_head = FrontalCamFromHead(0.6);
  Landmarks2d l;
  for (int i = 0; i < kNumLandmarks; ++i)
    l[i] = camera.Project(cam_from_head.Apply(posed.landmarks.row(i).transpose().cast<double>()));
  return l;
}

TEST(SkinColour, TheRegionLiesBetweenTheFacesFeatures) {
  const Landmarks2d l = FrontalLandmarks();
  const cv::Mat region = SkinRegion(l, cv::Size(256, 256));
  const int inside = cv::countNonZero(region);
  EXPECT_GT(inside, 500);
  auto at = [&](const Eigen::Vector2d& p) { return region.at<uint8_t>(std::lround(p.y()), std::lround(p.x())); };
  EXPECT_EQ(at(0.5 * (l[3] + l[31])), 255);   // right cheek
  EXPECT_EQ(at(0.5 * (l[13] + l[35])), 255);  // left cheek
  EXPECT_EQ(at(0.5 * (l[37] + l[41])), 0);    // inside the right eye
  EXPECT_EQ(at(0.5 * (l[62] + l[66])), 0);    // between the lips
  EXPECT_EQ(at(0.5 * (l[19] + l[24])), 0);    // the forehead, where hair and glasses may be
}

TEST(SkinColour, TheMedianOfTheRegionInRgb) {
  const Landmarks2d l = FrontalLandmarks();
  cv::Mat image(256, 256, CV_8UC3, cv::Scalar(20, 200, 30));  // BGR: green everywhere else
  const cv::Mat region = SkinRegion(l, image.size());
  image.setTo(cv::Scalar(60, 110, 190), region);  // skin: R 190, G 110, B 60
  // A few dark pixels (a glasses frame across a cheek) do not move the median.
  cv::line(image, cv::Point2d(l[2].x(), l[2].y()), cv::Point2d(l[14].x(), l[14].y()), cv::Scalar(0, 0, 0), 1);
  const std::optional<Eigen::Vector3f> rgb = SkinColour(image, l);
  ASSERT_TRUE(rgb.has_value());
  EXPECT_NEAR((*rgb)[0], 190 / 255.f, 1e-6f);
  EXPECT_NEAR((*rgb)[1], 110 / 255.f, 1e-6f);
  EXPECT_NEAR((*rgb)[2], 60 / 255.f, 1e-6f);
}

TEST(SkinColour, NoneWhereTheRegionIsNotInThePictureAndBadInputRefused) {
  Landmarks2d l = FrontalLandmarks();
  const cv::Mat image(256, 256, CV_8UC3, cv::Scalar(60, 110, 190));
  Landmarks2d away = l;
  for (auto& p : away) p += Eigen::Vector2d(1000, 0);
  EXPECT_FALSE(SkinColour(image, away).has_value());
  Landmarks2d broken = l;
  broken[31].x() = std::nan("");
  EXPECT_FALSE(SkinColour(image, broken).has_value());
  EXPECT_EQ(cv::countNonZero(SkinRegion(broken, image.size())), 0);
  EXPECT_FALSE(SkinColour(image, l, 1 << 20).has_value());  // fewer pixels than asked for
  EXPECT_THROW(SkinColour(cv::Mat(256, 256, CV_8UC1, cv::Scalar(9)), l), std::invalid_argument);
  EXPECT_THROW(SkinRegion(l, cv::Size(0, 10)), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
