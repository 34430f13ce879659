// The head's image motion between frames and the picture smeared along it
// (AvatarConfig::motion_blur), alone and in the receiver's render path.
#include "common/avatar/motion_blur.h"

#include <gtest/gtest.h>

#include "common/avatar/avatar_pipeline.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "tests/testing/switched_avatars.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

PinholeCamera Camera() {
  PinholeCamera c;
  c.fx = c.fy = 200;
  c.cx = c.cy = 63.5;
  c.width = c.height = 128;
  return c;
}

// A grid of points on a plane at depth `z` in front of the camera, moved by `shift` (metres).
RasterVertices Plane(double z, const Eigen::Vector3f& shift = Eigen::Vector3f::Zero()) {
  RasterVertices v(21 * 21, 3);
  for (int i = 0; i < 21; ++i)
    for (int j = 0; j < 21; ++j)
      v.row(i * 21 + j) = Eigen::Vector3f(-0.1f + 0.01f * j, -0.1f + 0.01f * i, static_cast<float>(z)) + shift;
  return v;
}

TEST(MeasureImageMotion, FindsATranslationAndAZoomPerFrame) {
  const PinholeCamera camera = Camera();
  // 1 cm sideways at 0.5 m: fx * 0.01 / 0.5 = 4 pixels, everywhere.
  const std::optional<ImageMotion> side = MeasureImageMotion(Plane(0.5), Plane(0.5, {0.01f, 0, 0}), camera, 1, 1);
  ASSERT_TRUE(side);
  EXPECT_NEAR(side->At(10, 100).x(), 4.0, 1e-3);
  EXPECT_NEAR(side->At(10, 100).y(), 0.0, 1e-3);
  EXPECT_NEAR(side->Largest(128, 128), 4.0, 1e-3);
  // The same over two frames is half of it a frame.
  EXPECT_NEAR(MeasureImageMotion(Plane(0.5), Plane(0.5, {0.01f, 0, 0}), camera, 2, 1)->At(0, 0).x(), 2.0, 1e-3);
  // Closer to the camera: the picture grows about the principal point. The
  // field is where the picture is now: 30 pixels out now was 30 x 0.4 / 0.5 out before.
  const std::optional<ImageMotion> zoom = MeasureImageMotion(Plane(0.5), Plane(0.4), camera, 1, 1);
  ASSERT_TRUE(zoom);
  EXPECT_NEAR(zoom->At(63.5, 63.5).norm(), 0.0, 1e-3);
  EXPECT_NEAR(zoom->At(93.5, 63.5).x(), 30 * (1 - 0.4 / 0.5), 1e-3);
  EXPECT_NEAR(zoom->At(63.5, 33.5).y(), -30 * (1 - 0.4 / 0.5), 1e-3);
}

TEST(MeasureImageMotion, NoneWithoutEnoughPointsInThePicture) {
  const PinholeCamera camera = Camera();
  EXPECT_FALSE(MeasureImageMotion(Plane(0.5), Plane(0.5).topRows(10), camera));                  // counts differ
  EXPECT_FALSE(MeasureImageMotion(Plane(-0.5), Plane(-0.5), camera, 1, 1));                      // behind the camera
  EXPECT_FALSE(MeasureImageMotion(Plane(0.5, {5, 0, 0}), Plane(0.5, {5, 0, 0}), camera, 1, 1));  // beside the picture
  EXPECT_FALSE(MeasureImageMotion(Plane(0.5), Plane(0.5), camera, 0, 1));                        // no interval
}

// A picture with one bright column at x = 40.
torch::Tensor Column() {
  torch::Tensor image = torch::zeros({1, 1, 32, 64});
  image.select(3, 40).fill_(1);
  return image;
}

ImageMotion Moving(double dx, double dy) {
  ImageMotion m;
  m.a = {0, 0, dx, 0, 0, dy};
  return m;
}

TEST(BlurAlongMotion, SmearsAlongTheMotionOnlyAndKeepsTheLight) {
  const torch::Tensor column = Column();
  // Sideways by 4 pixels over the whole exposure: the column becomes a band about 4 pixels wide, as bright in sum.
  const torch::Tensor side = BlurAlongMotion(column, Moving(8, 0), 0.5);
  const torch::Tensor row = side[0][0][16];
  EXPECT_NEAR(row.sum().item<double>(), 1.0, 1e-4);
  EXPECT_LT(row[40].item<double>(), 0.35);
  EXPECT_GT(row[38].item<double>(), 0.1);
  EXPECT_GT(row[42].item<double>(), 0.1);
  EXPECT_EQ(row[35].item<double>(), 0);
  EXPECT_EQ(row[45].item<double>(), 0);
  // Symmetric about the column: the frame's instant is the exposure's middle.
  EXPECT_NEAR(row[38].item<double>(), row[42].item<double>(), 1e-5);
  // Along the column: nothing changes.
  EXPECT_TRUE(torch::allclose(BlurAlongMotion(column, Moving(0, 8), 0.5), column, 0, 1e-5));
}

TEST(BlurAlongMotion, AStillHeadOrNoExposureIsTheSamePicture) {
  const torch::Tensor column = Column();
  EXPECT_TRUE(BlurAlongMotion(column, Moving(0.2, 0.1), 1).is_same(column));  // under a quarter pixel of smear
  EXPECT_TRUE(BlurAlongMotion(column, Moving(8, 0), 0).is_same(column));
  ImageMotion nan = Moving(std::nan(""), 0);
  EXPECT_TRUE(BlurAlongMotion(column, nan, 1).is_same(column));
}

TEST(BlurAlongMotion, PassesGradientsToThePicture) {
  torch::Tensor image = Column().requires_grad_(true);
  BlurAlongMotion(image, Moving(6, 2), 1).select(3, 43).sum().backward();
  ASSERT_TRUE(image.grad().defined());
  EXPECT_GT(image.grad().select(3, 40).sum().item<double>(), 0);  // the column feeds the smear beside it
}

FrameParams Frame(std::shared_ptr<const HeadModel> model, uint64_t sequence, double x) {
  FrameParams p;
  p.sequence = sequence;
  p.expression = Eigen::VectorXf::Zero(model->num_expression());
  RigidTransform t = FrontalCamFromHead(0.62);
  t.translation.x() += x;
  p.SetCamFromHead(t);
  return p;
}

TEST(MotionBlurInTheRenderPath, AMovingHeadIsSmearedAStillOrNewOneIsNot) {
  AvatarConfig c = testing::TinyAvatarConfig();
  AvatarConfig blur = c;
  blur.motion_blur = 1;
  testing::SwitchedAvatars avatars(c, blur);
  const auto model = avatars.model();
  Avatar &sharp = avatars.base(), &blurred = avatars.switched();
  auto draw = [&](Avatar& a, AvatarFrameInputs* buffers, const FrameParams& f) { return avatars.Draw(a, buffers, f); };
  using testing::SamePicture;
  AvatarFrameInputs with, without;
  // The first frame has no frame before it: drawn sharp.
  EXPECT_TRUE(SamePicture(draw(blurred, &with, Frame(model, 10, 0)), draw(sharp, &without, Frame(model, 10, 0))));
  // The next, the head 2 cm to the side (~6 pixels at 128²): smeared.
  const cv::Mat moved = draw(blurred, &with, Frame(model, 11, 0.02));
  EXPECT_FALSE(SamePicture(moved, draw(sharp, &without, Frame(model, 11, 0.02))));
  // The head still since the frame before: sharp again.
  EXPECT_TRUE(SamePicture(draw(blurred, &with, Frame(model, 12, 0.02)), draw(sharp, &without, Frame(model, 12, 0.02))));
  // A jump in the sequence (a new session, a long loss) is no motion to smear.
  EXPECT_TRUE(SamePicture(draw(blurred, &with, Frame(model, 40, 0.05)), draw(sharp, &without, Frame(model, 40, 0.05))));
  EXPECT_TRUE(SamePicture(draw(blurred, &with, Frame(model, 3, 0.0)), draw(sharp, &without, Frame(model, 3, 0.0))));
}

TEST(MotionBlur, TheExposureTravelsWithTheAvatarAndIsChecked) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.motion_blur = 0.6;
  EXPECT_DOUBLE_EQ(AvatarConfig::FromJson(c.ToJson()).motion_blur, 0.6);
  nlohmann::json old = c.ToJson();
  old.erase("motion_blur");
  EXPECT_DOUBLE_EQ(AvatarConfig::FromJson(old).motion_blur, 0);  // files from before it: sharp
  c.motion_blur = -0.1;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c.motion_blur = std::nan("");
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
