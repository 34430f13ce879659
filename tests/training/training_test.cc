// Synthetic data on the fly and fitting on tiny configurations.
#include <gtest/gtest.h>

#include <fstream>

#include "tests/testing/tiny_avatar.h"
#include "common/avatar/avatar_pipeline.h"
#include "common/headmodel/builtin_head.h"
#include "tests/testing/test_data.h"
#include "training/avatar_fit.h"

namespace headcast {
namespace {

AvatarConfig Tiny() { return testing::TinyAvatarConfig(); }

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

TEST(SyntheticData, DrawsValidVariedRendersAndRepeatsByIndex) {
  SyntheticDataOptions o;
  SyntheticData data(Model(), o, DefaultSubject(Model(), 128), 5);
  const SyntheticSample a = data.Next(), b = data.Next();
  EXPECT_EQ(a.image_bgr.size(), cv::Size(128, 128));
  EXPECT_GT(cv::countNonZero(a.mask), 128 * 128 / 20);
  EXPECT_GT(cv::norm(a.image_bgr, b.image_bgr, cv::NORM_L1), 0);
  std::string why;
  EXPECT_TRUE(a.frame.IsValid(&why)) << why;
  for (int i = 0; i < a.subject.shape.size(); ++i) EXPECT_LE(std::abs(a.subject.shape[i]), o.coefficient_limit);
  // METHOD §5 ranges: neck within +-80/60/80 degrees.
  EXPECT_LE(std::abs(a.frame.neck.x()), 80 * M_PI / 180 + 1e-6);
  EXPECT_LE(std::abs(a.frame.neck.y()), 60 * M_PI / 180 + 1e-6);
  EXPECT_EQ(cv::norm(data.At(3).image_bgr, data.At(3).image_bgr, cv::NORM_INF), 0);
  EXPECT_GT(cv::norm(data.At(3).image_bgr, data.At(4).image_bgr, cv::NORM_L1), 0);
  o.distance_max = 0.1;
  EXPECT_THROW(SyntheticData(Model(), o, DefaultSubject(Model(), 128), 1), std::invalid_argument);
}

TEST(FitOnSynthetic, ReducesTheLossAndImprovesHeldOutPsnr) {
  SyntheticDataOptions o;
  o.neck_x_deg = o.neck_y_deg = o.neck_z_deg = 10;
  SyntheticData data(Model(), o, DefaultSubject(Model(), 128), 2);
  Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  const EvalResult before = EvaluateOnSynthetic(avatar, Model(), data, 4);
  FitOptions f;
  f.iterations = 40;
  f.batch = 2;
  f.learning_rate = 5e-3;
  const FitResult r = FitOnSynthetic(avatar, Model(), data, f);
  ASSERT_EQ(r.steps.size(), 40u);
  const float first = (r.steps[0].loss + r.steps[1].loss + r.steps[2].loss) / 3, last = (r.steps[37].loss + r.steps[38].loss + r.steps[39].loss) / 3;
  EXPECT_LT(last, 0.7f * first);
  const EvalResult after = EvaluateOnSynthetic(avatar, Model(), data, 4);
  EXPECT_GT(after.psnr_mean, before.psnr_mean + 1.0);
  EXPECT_GT(r.samples_per_s, 0);
}

// Checkpoints: a run stopped after 3 steps and resumed (into an avatar with
// other random weights) continues exactly where the uninterrupted run goes.
TEST(FitOnSynthetic, ResumeContinuesTheLossCurve) {
  SyntheticDataOptions o;
  SyntheticData data(Model(), o, DefaultSubject(Model(), 128), 2);
  FitOptions f;
  f.iterations = 6;
  f.batch = 1;
  f.checkpoint_every = 3;
  f.checkpoint_dir = testing::TempDir("ckpt_straight");
  Avatar straight = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  const FitResult all = FitOnSynthetic(straight, Model(), data, f);
  ASSERT_EQ(all.steps.size(), 6u);

  f.checkpoint_dir = testing::TempDir("ckpt_resumed");
  f.iterations = 3;
  Avatar first = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  FitOnSynthetic(first, Model(), data, f);
  f.iterations = 6;
  f.resume = true;
  Avatar second = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 99);  // other weights
  const FitResult rest = FitOnSynthetic(second, Model(), data, f);
  EXPECT_EQ(rest.first_step, 3);
  ASSERT_EQ(rest.steps.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(rest.steps[i].loss, all.steps[3 + i].loss, 1e-4 * all.steps[3 + i].loss) << "step " << 3 + i;
  const auto a = straight.modules().parameters(), b = second.modules().parameters();
  double diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff = std::max(diff, (a[i] - b[i]).abs().max().item<double>());
  EXPECT_LT(diff, 1e-5);
  // A corrupt checkpoint is refused by name.
  std::string latest;
  std::getline(std::ifstream(f.checkpoint_dir + "/LATEST"), latest);
  std::ofstream(f.checkpoint_dir + "/" + latest + "/optimizer.pt") << "garbage";
  f.iterations = 9;
  Avatar third = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  try {
    FitOnSynthetic(third, Model(), data, f);
    ADD_FAILURE() << "a corrupt checkpoint was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot resume"), std::string::npos) << e.what();
  }
}

TEST(Avatar, RuntimeSwitchesKeepTheWeights) {
  Avatar a = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  AvatarConfig c = Tiny();
  c.precompute_conditioning = false;
  Avatar b = a.WithRuntimeSwitches(c);
  SyntheticData data(Model(), SyntheticDataOptions{}, DefaultSubject(Model(), 128), 2);
  EXPECT_NEAR(EvaluateOnSynthetic(a, Model(), data, 2).psnr_mean, EvaluateOnSynthetic(b, Model(), data, 2).psnr_mean,
              1e-3);
  c.mlp_width = 32;
  EXPECT_THROW(a.WithRuntimeSwitches(c), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
