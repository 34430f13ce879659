// The hair's outline holding the head's pitch, on the built-in head: its
// rendered silhouette raised by a fixed "hair" is the mask; the reference is
// that thickness, and a fit whose landmarks say another pitch is pulled back
// toward the one the outline shows.
#include "common/tracking/outline_hold.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/raster/rasterizer.h"
#include "tests/testing/frontal_head.h"

namespace headcast {
namespace {

const HeadModel& Builtin() { return testing::BuiltinModel(); }
const PinholeCamera& kCamera = testing::kFrontalCamera;
constexpr double kDistance = testing::kFrontalDistance;
FrameParams Posed(double yaw_deg, double pitch_deg) { return testing::FrontalPose(yaw_deg, pitch_deg); }

// The mask's top rows: the head rendered at `f`'s pose, its silhouette raised by `hair_px`.
std::vector<int> HairTops(const FrameParams& f, int hair_px) {
  const HeadModel& m = Builtin();
  HeadModelParams p;
  p.expression = f.expression.cast<double>();
  const HeadModelOutput out = m.Forward(p);
  RasterVertices in_cam;
  TransformToCamera(out.vertices, f.CamFromHead(), &in_cam);
  RasterBuffers buffers;
  Rasterize(in_cam, m.data().faces, kCamera, RasterOptions{}, &buffers);
  cv::Mat mask(kCamera.height, kCamera.width, CV_8U, cv::Scalar(0));
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      if (buffers.Covered(x, y)) mask.at<uint8_t>(y, x) = 255;
  std::vector<int> top = MaskTopRows(mask);
  for (int& t : top)
    if (t >= 0) t = std::clamp(t - hair_px, 1, mask.rows - 1);
  return top;
}

double PitchDeg(const FrameParams& f) {
  // The head's up axis in the camera (y down): its tilt toward the camera.
  const Eigen::Vector3d up = f.CamFromHead().rotation * Eigen::Vector3d::UnitY();
  return std::atan2(up.z(), -up.y()) * 180 / M_PI;
}

TEST(MaskTopRows, FirstRowSetPerColumn) {
  cv::Mat mask(5, 4, CV_8U, cv::Scalar(0));
  mask.at<uint8_t>(2, 0) = 255;
  mask.at<uint8_t>(4, 0) = 255;
  mask.at<uint8_t>(0, 2) = 1;
  mask.at<uint8_t>(3, 3) = 255;
  EXPECT_EQ(MaskTopRows(mask), (std::vector<int>{2, -1, 0, 3}));
}

TEST(OutlineHold, TheReferenceIsTheHairsThickness) {
  OutlineHoldOptions o;
  o.weight = 1;
  OutlineHold hold(Builtin(), Eigen::VectorXd::Zero(Builtin().num_shape()), o);
  ASSERT_GT(hold.num_points(), 50);
  EXPECT_FALSE(hold.Reference(1));  // nothing observed
  constexpr int kHair = 14;
  for (const auto& p : {std::array<double, 2>{0, 0}, {10, 3}, {-12, -4}, {5, 6}, {-4, -6}}) {
    const FrameParams f = Posed(p[0], p[1]);
    EXPECT_TRUE(hold.Observe(HairTops(f, kHair), f, kCamera));
  }
  EXPECT_FALSE(hold.Reference(6));  // fewer frames than asked for
  for (const auto& p : {std::array<double, 2>{0, 0}, {10, 3}, {-12, -4}, {5, 6}, {-4, -6}}) {
    const FrameParams f = Posed(p[0], p[1]);
    hold.Observe(HairTops(f, kHair), f, kCamera);
  }
  ASSERT_TRUE(hold.Reference(5));
  // 14 px at about the crown's depth (a little beyond the face's 0.45 m).
  const double px_m = kDistance / kCamera.fy;
  EXPECT_GT(hold.reference(), 0.8 * kHair * px_m);
  EXPECT_LT(hold.reference(), 1.5 * kHair * px_m);
  EXPECT_DOUBLE_EQ(hold.observed_median(), hold.reference());
  // Every frame shows the same 14 px (up to the rows' rounding): no spread.
  EXPECT_LT(hold.observed_spread(), 0.15 * kHair * px_m);
  EXPECT_GE(hold.observed_spread(), 0);

  // Half the frames' hair 10 px thicker: the median absolute deviation is
  // half those 10 px or all of them (at the crown's depth), as the median of an
  // even count falls between the two or on one side.
  for (const auto& p : {std::array<double, 2>{0, 0}, {10, 3}, {-12, -4}, {5, 6}, {-4, -6}, {2, -2}}) {
    const FrameParams f = Posed(p[0], p[1]);
    hold.Observe(HairTops(f, p[0] > 0 ? kHair + 10 : kHair), f, kCamera);
  }
  ASSERT_TRUE(hold.Reference(5));
  EXPECT_GT(hold.observed_spread(), 0.35 * 10 * px_m);
  EXPECT_LT(hold.observed_spread(), 1.5 * 10 * px_m);

  // A mask whose top lies 30 px below the skull's (its region cut the head):
  // seen, but no reference, so nothing is held.
  for (const auto& p : {std::array<double, 2>{0, 0}, {10, 3}, {-12, -4}, {5, 6}, {-4, -6}}) {
    const FrameParams f = Posed(p[0], p[1]);
    hold.Observe(HairTops(f, -30), f, kCamera);
  }
  EXPECT_FALSE(hold.Reference(5));
  EXPECT_LT(hold.observed_median(), OutlineHold::kLowestThickness);
  EXPECT_TRUE(std::isnan(hold.reference()));
  EXPECT_TRUE(hold.Observations(HairTops(Posed(0, 0), -30), Posed(0, 0), kCamera).head.empty());
}

TEST(OutlineHold, PullsAFitsPitchTowardTheOneTheOutlineShows) {
  OutlineHoldOptions o;
  o.weight = 2;
  OutlineHold hold(Builtin(), Eigen::VectorXd::Zero(Builtin().num_shape()), o);
  constexpr int kHair = 14;
  for (const auto& p : {std::array<double, 2>{0, 0}, {8, 2}, {-8, -2}, {4, 4}, {-4, -4}}) {
    const FrameParams f = Posed(p[0], p[1]);
    hold.Observe(HairTops(f, kHair), f, kCamera);
  }
  ASSERT_TRUE(hold.Reference(5));

  HeadFitter fitter(Builtin(), HeadFitterOptions{});
  // The picture shows the head upright; its landmarks say it is tipped 4
  // degrees about the eyes (what landmarks mixed with an expression can say).
  const FrameParams truth = Posed(3, 0), tipped = Posed(3, 4);
  const std::vector<int> tops = HairTops(truth, kHair);
  const Landmarks2d landmarks = fitter.Project(tipped, kCamera);

  FrameParams alone = tipped;
  ASSERT_TRUE(fitter.Fit(landmarks, kCamera, &alone).ok);
  // Held: the observations taken at the current fit, fitted again, twice (as the offline pass's rounds).
  FrameParams held = tipped;
  for (int round = 0; round < 2; ++round) {
    const RigidObservations outline = hold.Observations(tops, held, kCamera);
    ASSERT_GE(outline.head.size(), 8u);
    ASSERT_EQ(outline.weight.size(), outline.head.size());
    EXPECT_DOUBLE_EQ(outline.weight[0], 2);
    ASSERT_TRUE(fitter.Fit(landmarks, kCamera, &held, nullptr, &outline).ok);
  }
  const double truth_pitch = PitchDeg(truth);
  EXPECT_NEAR(PitchDeg(alone), PitchDeg(tipped), 0.5);
  EXPECT_LT(std::abs(PitchDeg(held) - truth_pitch), 0.6 * std::abs(PitchDeg(alone) - truth_pitch))
      << "alone " << PitchDeg(alone) << " held " << PitchDeg(held) << " truth " << truth_pitch;
}

TEST(OutlineHold, ColumnsFarFromTheReferenceAreNotHeld) {
  OutlineHoldOptions o;
  o.weight = 1;
  o.max_offset = 0.008;
  OutlineHold hold(Builtin(), Eigen::VectorXd::Zero(Builtin().num_shape()), o);
  const FrameParams f = Posed(0, 0);
  EXPECT_TRUE(hold.Observations(HairTops(f, 14), f, kCamera).head.empty());  // no reference yet
  hold.SetReference(14 * kDistance / kCamera.fy);
  EXPECT_GE(hold.Observations(HairTops(f, 14), f, kCamera).head.size(), 8u);
  // Hair 40 px taller than the reference (a hand on the head, the wall taken): nothing held.
  EXPECT_TRUE(hold.Observations(HairTops(f, 54), f, kCamera).head.empty());
  // A mask reaching the picture's top says nothing of where the hair ends.
  EXPECT_TRUE(hold.Observations(std::vector<int>(kCamera.width, 0), f, kCamera).head.empty());
}

TEST(OutlineHold, OptionsAreChecked) {
  EXPECT_NO_THROW(OutlineHoldOptions{}.Check());
  EXPECT_FALSE(OutlineHoldOptions{}.enabled());
  const std::vector<std::function<void(OutlineHoldOptions*)>> spoilt = {
      [](OutlineHoldOptions* o) { o->weight = -1; }, [](OutlineHoldOptions* o) { o->columns = 0; },
      [](OutlineHoldOptions* o) { o->span = 1.5; }, [](OutlineHoldOptions* o) { o->max_offset = 0; }};
  for (const auto& spoil : spoilt) {
    OutlineHoldOptions o;
    spoil(&o);
    EXPECT_THROW(o.Check(), std::invalid_argument);
  }
}

}  // namespace
}  // namespace headcast
