// The avatar's outline moved to the one the sender measured
// (AvatarConfig::outline_ramp), alone and in the receiver's render path.
#include "common/avatar/outline_warp.h"

#include <gtest/gtest.h>

#include "common/avatar/avatar_pipeline.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "tests/testing/switched_avatars.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

constexpr int kSize = 128;

// A disc of coverage (radius `r` about (64, 70)) and its picture, red over grey.
void Disc(double r, torch::Tensor* image, torch::Tensor* coverage) {
  const torch::Tensor ys = torch::arange(kSize, torch::kFloat32).view({1, 1, kSize, 1});
  const torch::Tensor xs = torch::arange(kSize, torch::kFloat32).view({1, 1, 1, kSize});
  const torch::Tensor dist = torch::sqrt((xs - 64).pow(2) + (ys - 70).pow(2));
  *coverage = torch::clamp(r + 0.5 - dist, 0, 1);
  const torch::Tensor red = torch::tensor({0.9f, 0.1f, 0.1f}).view({1, 3, 1, 1});
  *image = *coverage * red + (1 - *coverage) * 0.2f;
}

OutlineFrame Centre() {
  OutlineFrame f;
  f.centre_px = {64, 70};
  f.px_per_mm = 1;  // a millimetre a pixel: the values read as pixels
  return f;
}

std::vector<float> Drawn(const torch::Tensor& coverage, const OutlineOptions& o) {
  const torch::Tensor c = coverage.contiguous();
  return MeasureOutlinePx(cv::Mat(kSize, kSize, CV_32F, c.data_ptr<float>()), Centre(), o);
}

TEST(WarpToOutline, TheTopOfTheOutlineMovesWhereTheSenderMeasuredIt) {
  torch::Tensor image, coverage;
  Disc(40, &image, &coverage);
  const torch::Tensor before = image.clone();
  const OutlineOptions o;
  OutlineWarpOptions w;
  w.ramp_px = 10;
  // Inward on the right, outward on the left; between arcs the move is
  // linear, so each arc's median meets its target where its neighbours' are near.
  std::vector<float> target(o.bins);
  for (int k = 0; k < o.bins; ++k) target[k] = 36.f + 0.6f * k;
  ASSERT_TRUE(WarpToOutline(target, Centre(), o, w, &image, &coverage));
  const std::vector<float> drawn = Drawn(coverage, o);
  for (int k = 1; k + 1 < o.bins; ++k) EXPECT_NEAR(drawn[k], target[k], 1.0) << k;
  // The end arcs fade to nothing below the head point: half-way moved at their outer edge.
  EXPECT_NEAR(drawn[0], target[0], 2.0);
  EXPECT_NEAR(drawn[o.bins - 1], target[o.bins - 1], 2.0);
  // Below the head point and well inside the outline nothing moved.
  EXPECT_TRUE(torch::allclose(image.narrow(2, 80, kSize - 80), before.narrow(2, 80, kSize - 80), 0, 1e-4));
  EXPECT_TRUE(
      torch::allclose(image.narrow(2, 60, 10).narrow(3, 54, 20), before.narrow(2, 60, 10).narrow(3, 54, 20), 0, 1e-4));
  // The picture moved with the coverage: red where it covers, grey beyond.
  EXPECT_NEAR(image[0][0][70 - 30][64].item<float>(), 0.9f, 1e-3);
  // (95, 47) lies 38.6 px out at 37 degrees, inside the disc before, beyond the
  // arc's new edge (about 37.2) after.
  EXPECT_NEAR(before[0][0][47][95].item<float>(), 0.9f, 1e-3);
  EXPECT_NEAR(image[0][0][47][95].item<float>(), 0.2f, 0.05);
}

TEST(WarpToOutline, AShiftIsBoundedAndUnknownArcsStay) {
  torch::Tensor image, coverage;
  Disc(40, &image, &coverage);
  const OutlineOptions o;
  OutlineWarpOptions w;
  w.ramp_px = 10;
  w.max_shift_px = 3;
  std::vector<float> target(o.bins, 20.f);  // far inside: a measurement gone wrong
  target[5] = kOutlineUnknown;
  ASSERT_TRUE(WarpToOutline(target, Centre(), o, w, &image, &coverage));
  const std::vector<float> drawn = Drawn(coverage, o);
  EXPECT_NEAR(drawn[0], 37, 1.0);  // 40 - 3
  EXPECT_NEAR(drawn[5], 40, 1.0);  // unknown: where the avatar drew it (the neighbours pull a little)
}

TEST(WarpToOutline, NothingToMoveLeavesThePicture) {
  torch::Tensor image, coverage;
  Disc(40, &image, &coverage);
  const torch::Tensor before = image.clone();
  const OutlineOptions o;
  const std::vector<float> same = Drawn(coverage, o);
  EXPECT_FALSE(WarpToOutline(same, Centre(), o, {}, &image, &coverage));
  EXPECT_FALSE(WarpToOutline(std::vector<float>(o.bins, kOutlineUnknown), Centre(), o, {}, &image, &coverage));
  EXPECT_TRUE(torch::equal(image, before));
  EXPECT_THROW(WarpToOutline({30.f, 30.f}, Centre(), o, {}, &image, &coverage), std::invalid_argument);
  OutlineWarpOptions bad;
  bad.ramp_px = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

FrameParams Frontal(std::shared_ptr<const HeadModel> model) {
  FrameParams p;
  p.expression = Eigen::VectorXf::Zero(model->num_expression());
  p.SetCamFromHead(FrontalCamFromHead(0.62));
  return p;
}

TEST(OutlineInTheRenderPath, AFrameWithAnOutlineMovesTheAvatarsEdge) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.matte = MatteMode::kLearned;
  AvatarConfig ignore = c;
  ignore.outline_ramp = 0;
  testing::SwitchedAvatars avatars(c, ignore);
  Avatar &avatar = avatars.base(), &ignoring = avatars.switched();
  auto draw = [&](Avatar& a, const FrameParams& f) { return avatars.Draw(a, f); };
  using testing::SamePicture;
  const FrameParams plain = Frontal(avatars.model());
  FrameParams outlined = plain;
  outlined.outline.assign(OutlineOptions{}.bins,
                          60.f);  // 6 cm above the head point: the untrained matte's edge is elsewhere
  EXPECT_TRUE(SamePicture(draw(avatar, plain), draw(ignoring, plain)));
  EXPECT_FALSE(SamePicture(draw(avatar, outlined), draw(avatar, plain)));
  EXPECT_TRUE(SamePicture(draw(ignoring, outlined), draw(ignoring, plain)));  // ramp 0: outlines ignored
}

// A frame whose outline is moved there is drawn at outline_matte_scale, the
// others at matte_scale.
TEST(OutlineInTheRenderPath, AFrameWithAnOutlineIsDrawnAtTheOutlinesMatteScale) {
  AvatarConfig sharp = testing::TinyAvatarConfig();
  sharp.matte = MatteMode::kLearned;
  sharp.matte_scale = 2;
  sharp.outline_matte_scale = 2;
  AvatarConfig soft = sharp;
  soft.matte_scale = 0.5;
  testing::SwitchedAvatars avatars(sharp, soft);
  using testing::SamePicture;
  const FrameParams plain = Frontal(avatars.model());
  FrameParams outlined = plain;
  outlined.outline.assign(OutlineOptions{}.bins, 60.f);
  EXPECT_FALSE(SamePicture(avatars.Draw(avatars.base(), plain), avatars.Draw(avatars.switched(), plain)));
  EXPECT_TRUE(SamePicture(avatars.Draw(avatars.base(), outlined), avatars.Draw(avatars.switched(), outlined)));
}

TEST(OutlineInTheRenderPath, TheSettingTravelsWithTheAvatarAndIsChecked) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.outline_ramp = 0.05;
  c.outline_centre_y = 0.03;
  c.outline_matte_scale = 1.5;
  const AvatarConfig back = AvatarConfig::FromJson(c.ToJson());
  EXPECT_DOUBLE_EQ(back.outline_ramp, 0.05);
  EXPECT_DOUBLE_EQ(back.outline_centre_y, 0.03);
  EXPECT_DOUBLE_EQ(back.outline_matte_scale, 1.5);
  nlohmann::json old = c.ToJson();
  old.erase("outline_ramp");
  old.erase("outline_centre_y");
  old.erase("outline_matte_scale");
  // Files from before it: moved like any avatar (only frames that carry an outline change).
  EXPECT_DOUBLE_EQ(AvatarConfig::FromJson(old).outline_ramp, AvatarConfig{}.outline_ramp);
  EXPECT_DOUBLE_EQ(AvatarConfig::FromJson(old).outline_centre_y, OutlineOptions{}.centre_y_m);
  EXPECT_DOUBLE_EQ(AvatarConfig::FromJson(old).outline_matte_scale, AvatarConfig{}.outline_matte_scale);
  c.outline_matte_scale = 0;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c.outline_matte_scale = 1;
  c.outline_ramp = -0.1;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c.outline_ramp = std::nan("");
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
