// Synthetic data on the fly and fitting on tiny configurations.
#include <gtest/gtest.h>
#include <torch/script.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "common/avatar/avatar_pipeline.h"
#include "common/core/image_io.h"
#include "common/headmodel/builtin_head.h"
#include "proto/recording.h"
#include "tests/testing/test_data.h"
#include "tests/testing/tiny_avatar.h"
#include "training/avatar_fit.h"
#include "training/conditioning_refiner.h"
#include "training/dataset.h"
#include "training/image_losses.h"
#include "training/interpolation.h"

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
  const TrainResult r = FitOnSynthetic(avatar, Model(), data, f);
  ASSERT_EQ(r.steps.size(), 40u);
  const float first = (r.steps[0].loss + r.steps[1].loss + r.steps[2].loss) / 3,
              last = (r.steps[37].loss + r.steps[38].loss + r.steps[39].loss) / 3;
  EXPECT_LT(last, 0.7f * first);
  const EvalResult after = EvaluateOnSynthetic(avatar, Model(), data, 4);
  EXPECT_GT(after.psnr_mean, before.psnr_mean + 1.0);
  EXPECT_GT(r.samples_per_s, 0);
}

std::vector<torch::Tensor> Copy(const std::vector<torch::Tensor>& params) {
  std::vector<torch::Tensor> out;
  for (const auto& p : params) out.push_back(p.detach().clone());
  return out;
}

double MaxDifference(const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
  double diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff = std::max(diff, (a[i] - b[i]).abs().max().item<double>());
  return diff;
}

// The short runs of the resume and averaging tests.
FitOptions SixSingleSampleSteps() {
  FitOptions f;
  f.iterations = 6;
  f.batch = 1;
  return f;
}

// Stands for a crash (or kill -9) right after step n: the progress callback
// runs after that step's checkpoint was written.
struct Crash {};
std::function<void(const StepInfo&)> CrashAfter(int n) {
  return [n](const StepInfo& s) {
    if (s.step + 1 == n) throw Crash{};
  };
}

// Checkpoints: a run stopped after 3 steps and resumed (into an avatar with
// other random weights) continues exactly where the uninterrupted run goes.
TEST(FitOnSynthetic, ResumeContinuesTheLossCurve) {
  SyntheticData data(Model(), SyntheticDataOptions{}, DefaultSubject(Model(), 128), 2);
  FitOptions f = SixSingleSampleSteps();
  f.final_lr_fraction = 0.1;  // the falling rate resumes on its curve too
  f.checkpoint_every = 3;
  f.checkpoint_dir = testing::TempDir("ckpt_straight");
  Avatar straight = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  const TrainResult all = FitOnSynthetic(straight, Model(), data, f);
  ASSERT_EQ(all.steps.size(), 6u);

  f.checkpoint_dir = testing::TempDir("ckpt_resumed");
  Avatar first = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  EXPECT_THROW(FitOnSynthetic(first, Model(), data, f, CrashAfter(3)), Crash);
  f.resume = true;
  Avatar second = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 99);  // other weights
  const TrainResult rest = FitOnSynthetic(second, Model(), data, f);
  EXPECT_EQ(rest.first_step, 3);
  ASSERT_EQ(rest.steps.size(), 3u);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(rest.steps[i].loss, all.steps[3 + i].loss, 1e-4 * all.steps[3 + i].loss) << "step " << 3 + i;
  EXPECT_LT(MaxDifference(straight.modules().parameters(), second.modules().parameters()), 1e-5);
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

// Weight averaging leaves the training itself alone (the loss curve is the
// plain run's) and hands out, after every step and at the end, the moving
// average of the plain run's weights; a resumed run ends with the same average.
TEST(FitOnSynthetic, WeightAverageIsTheMovingAverageOfThePlainRunsWeights) {
  SyntheticData data(Model(), SyntheticDataOptions{}, DefaultSubject(Model(), 128), 2);
  FitOptions f = SixSingleSampleSteps();
  Avatar plain = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  std::vector<torch::Tensor> expected = Copy(plain.modules().parameters());
  std::vector<std::vector<torch::Tensor>> expected_after;  // the average after each step
  f.weight_average = 0.6;
  const FitOptions averaging = f;
  f.weight_average = 0;
  const TrainResult plain_run = FitOnSynthetic(plain, Model(), data, f, [&](const StepInfo& s) {
    const double d = averaging.WeightAverageDecayAt(s.step);
    const auto live = plain.modules().parameters();
    for (size_t i = 0; i < live.size(); ++i) expected[i] = d * expected[i] + (1 - d) * live[i].detach();
    expected_after.push_back(Copy(expected));
  });
  EXPECT_DOUBLE_EQ(averaging.WeightAverageDecayAt(0), 0.1);  // the start weights fade fast
  EXPECT_DOUBLE_EQ(averaging.WeightAverageDecayAt(1000), 0.6);
  EXPECT_DOUBLE_EQ(SubjectWeightAverage(8000), 0.999);  // a fine-tune averages over its last eighth
  EXPECT_DOUBLE_EQ(SubjectWeightAverage(1000), 0.992);
  EXPECT_DOUBLE_EQ(SubjectWeightAverage(20000), 0.999);
  EXPECT_EQ(SubjectWeightAverage(8), 0.0);
  ASSERT_GT(MaxDifference(expected, plain.modules().parameters()), 1e-4);  // the average is not the end point

  f = averaging;
  f.checkpoint_every = 3;
  f.checkpoint_dir = testing::TempDir("ckpt_average");
  Avatar averaged = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  std::vector<double> seen;
  const TrainResult run = FitOnSynthetic(averaged, Model(), data, f, [&](const StepInfo& s) {
    seen.push_back(MaxDifference(averaged.modules().parameters(), expected_after[s.step]));
  });
  ASSERT_EQ(run.steps.size(), 6u);
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(run.steps[i].loss, plain_run.steps[i].loss, 1e-5 * plain_run.steps[i].loss);
  for (size_t i = 0; i < seen.size(); ++i) EXPECT_LT(seen[i], 1e-5) << "after step " << i;
  EXPECT_LT(MaxDifference(averaged.modules().parameters(), expected), 1e-5);

  f.checkpoint_dir = testing::TempDir("ckpt_average_resumed");
  Avatar first = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  EXPECT_THROW(FitOnSynthetic(first, Model(), data, f, CrashAfter(3)), Crash);
  f.resume = true;
  Avatar second = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 99);
  FitOnSynthetic(second, Model(), data, f);
  EXPECT_LT(MaxDifference(second.modules().parameters(), expected), 1e-5);
  f.weight_average = 1;
  EXPECT_THROW(f.Check(), std::invalid_argument);
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

// The refiner fits offsets on a frame's conditioning, the networks frozen:
// on a target the avatar drew with a known offset of its expression and
// lighting, the picture comes closer to it; the weights, their flags and the
// frame's inputs are as before; beta and tau take no offset.
TEST(ConditioningRefiner, FitsTheFramesConditioningWithTheNetworksFrozen) {
  const SubjectParams subject = DefaultSubject(Model(), 128);
  Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), subject, 4);
  {
    // Weights drawn wider than the initialisation's, so that the codes move
    // the picture of an untrained avatar.
    torch::NoGradGuard no_grad;
    torch::manual_seed(3);
    for (torch::Tensor& p : avatar.modules().parameters()) p.add_(0.3 * torch::randn_like(p));
  }
  const AvatarConfig& c = avatar.config();
  FrameParams frame;
  frame.expression = Eigen::VectorXf::Zero(Model().num_expression());
  frame.SetCamFromHead(FrontalCamFromHead(0.62));
  RaySampler sampler(c);
  AvatarFrameInputs in;
  PrepareAvatarFrame(c, Model(), Model().MakeIdentity(subject.shape.cast<double>()), subject, frame, &sampler, nullptr,
                     &in);
  const AvatarConditioning told = in.conditioning;
  torch::Tensor target;
  {
    torch::NoGradGuard no_grad;
    AvatarFrameInputs moved = in;
    moved.conditioning.geometry = told.geometry.clone();
    moved.conditioning.geometry.narrow(1, c.expression_offset(), c.num_expression).add_(0.8);
    moved.conditioning.appearance = told.appearance.clone();
    moved.conditioning.appearance.narrow(1, 0, 3).add_(0.5);  // lambda's ambient term
    target = RunAvatar(avatar.modules(), moved).image;
  }
  auto error = [&](const AvatarConditioning& conditioning) {
    torch::NoGradGuard no_grad;
    AvatarFrameInputs shown = in;
    shown.conditioning = conditioning;
    return torch::mse_loss(RunAvatar(avatar.modules(), shown).image, target).item<double>();
  };
  RefineOptions o;
  o.learning_rate = 0.05;
  o.offset_weight = 0;
  ConditioningRefiner refiner(avatar, o);
  const double before = error(refiner.Offset(told));
  ASSERT_GT(before, 1e-6) << "the target differs from the told frame's picture";
  const std::vector<torch::Tensor> weights = Copy(avatar.modules().parameters());
  avatar.modules().parameters()[0].set_requires_grad(false);  // one weight frozen already: it stays so
  refiner.Refine(&in, target, 30);
  EXPECT_LT(error(refiner.Offset(told)), 0.5 * before);
  EXPECT_GT(refiner.OffsetNorm(), 0);
  const std::vector<torch::Tensor> after = avatar.modules().parameters();
  ASSERT_EQ(after.size(), weights.size());
  for (size_t i = 0; i < after.size(); ++i) {
    EXPECT_TRUE(torch::equal(after[i], weights[i])) << "weight " << i;
    EXPECT_EQ(after[i].requires_grad(), i != 0) << "weight " << i;
  }
  EXPECT_TRUE(torch::equal(in.conditioning.geometry, told.geometry));
  EXPECT_TRUE(torch::equal(in.conditioning.appearance, told.appearance));
  const AvatarConditioning offset = refiner.Offset(told);
  EXPECT_TRUE(torch::equal(offset.geometry.narrow(1, 0, c.num_shape), told.geometry.narrow(1, 0, c.num_shape)));
  EXPECT_TRUE(torch::equal(offset.appearance.narrow(1, c.appearance_dim() - c.num_texture, c.num_texture),
                           told.appearance.narrow(1, c.appearance_dim() - c.num_texture, c.num_texture)));
  refiner.Reset();
  EXPECT_EQ(refiner.OffsetNorm(), 0);
  EXPECT_THROW(refiner.Refine(&in, target.narrow(2, 0, 64), 1), std::invalid_argument);
  // Only the expression coefficients: the joints and the lighting keep the told codes.
  o.codes = "expression";
  ConditioningRefiner expression(avatar, o);
  expression.Refine(&in, target, 5);
  const AvatarConditioning moved = expression.Offset(told);
  EXPECT_GT(expression.OffsetNorm(), 0);
  EXPECT_TRUE(torch::equal(moved.geometry.narrow(1, 0, c.expression_offset()),
                           told.geometry.narrow(1, 0, c.expression_offset())));
  EXPECT_TRUE(torch::equal(moved.appearance, told.appearance));
  o.codes = "colour";
  EXPECT_THROW(ConditioningRefiner(avatar, o), std::invalid_argument);
  o.codes = "all";
  o.learning_rate = 0;
  EXPECT_THROW(ConditioningRefiner(avatar, o), std::invalid_argument);
}

TEST(MixSchedule, FollowsMethodEquation9) {
  const MixSchedule m{310000, 312500, 0.0, 0.25};  // METHOD §5's best general model
  EXPECT_EQ(m.SyntheticProbability(0), 1.0);
  EXPECT_EQ(m.SyntheticProbability(310000), 1.0);
  EXPECT_NEAR(m.SyntheticProbability(311250), 0.125, 1e-12);
  EXPECT_NEAR(m.SyntheticProbability(310001), 0.25 * (1 - 1.0 / 2500), 1e-12);
  EXPECT_EQ(m.SyntheticProbability(312500), 0.0);
  EXPECT_EQ(m.SyntheticProbability(400000), 0.0);
  const MixSchedule subject{0, 1000, 0.0, 0.5};  // METHOD §6: decays linearly to 0
  EXPECT_NEAR(subject.SyntheticProbability(500), 0.25, 1e-12);
  EXPECT_THROW((MixSchedule{10, 10, 0.0, 0.25}.Check()), std::invalid_argument);
  EXPECT_THROW((MixSchedule{0, 10, 0.5, 0.25}.Check()), std::invalid_argument);
}

TEST(FitOptions, LearningRateFallsExponentiallyToItsFinalFraction) {
  FitOptions f;
  f.iterations = 1001;
  f.learning_rate = 2e-3;
  f.final_lr_fraction = 0.01;
  EXPECT_DOUBLE_EQ(f.LearningRateAt(0), 2e-3);
  EXPECT_NEAR(f.LearningRateAt(500), 2e-4, 1e-12);  // half way: sqrt(0.01)
  EXPECT_NEAR(f.LearningRateAt(1000), 2e-5, 1e-12);
  f.final_lr_fraction = 1;
  EXPECT_DOUBLE_EQ(f.LearningRateAt(700), 2e-3);
  f.final_lr_fraction = 0;
  EXPECT_THROW(f.Check(), std::invalid_argument);
  f.final_lr_fraction = 1.5;
  EXPECT_THROW(f.Check(), std::invalid_argument);
}

TEST(FitOptions, AWarmUpRampsTheFirstStepsThenLeavesTheSchedule) {
  FitOptions f;
  f.iterations = 1001;
  f.learning_rate = 2e-3;
  f.warmup_steps = 100;
  EXPECT_NEAR(f.LearningRateAt(0), 2e-5, 1e-15);
  EXPECT_NEAR(f.LearningRateAt(49), 1e-3, 1e-15);
  EXPECT_DOUBLE_EQ(f.LearningRateAt(99), 2e-3);
  EXPECT_DOUBLE_EQ(f.LearningRateAt(700), 2e-3);
  f.final_lr_fraction = 0.01;
  EXPECT_NEAR(f.LearningRateAt(500), 2e-4, 1e-12);
  EXPECT_NO_THROW(f.Check());
  f.warmup_steps = -1;
  EXPECT_THROW(f.Check(), std::invalid_argument);
}

TEST(ImageLosses, SsimAndPsnr) {
  torch::manual_seed(3);
  const torch::Tensor a = torch::rand({1, 3, 32, 32});
  EXPECT_NEAR(Ssim(a, a).item<double>(), 1.0, 1e-5);
  torch::Tensor b = (a + 0.2 * torch::randn({1, 3, 32, 32})).clamp(0, 1).requires_grad_(true);
  const torch::Tensor s = Ssim(a, b);
  EXPECT_LT(s.item<double>(), 0.9);
  (1 - s).backward();
  EXPECT_GT(b.grad().abs().sum().item<double>(), 0);
  EXPECT_NEAR(Psnr(torch::full({1, 3, 8, 8}, 0.5), torch::full({1, 3, 8, 8}, 0.6)), 20.0, 1e-4);
}

TEST(ImageLosses, SeparableSsimEqualsTheFullWindowsValueAndGradient) {
  torch::manual_seed(5);
  const torch::Tensor target = torch::rand({2, 3, 40, 48});
  const torch::Tensor start = (target + 0.15 * torch::randn({2, 3, 40, 48})).clamp(0, 1);
  const torch::Tensor x = start.clone().requires_grad_(true), y = start.clone().requires_grad_(true);
  const torch::Tensor separable = Ssim(x, target), full = SsimFullWindow(y, target);
  EXPECT_LT(full.item<double>(), 0.9);
  EXPECT_NEAR(separable.item<double>(), full.item<double>(), 1e-5);
  separable.backward();
  full.backward();
  EXPECT_GT(y.grad().abs().max().item<double>(), 1e-6);
  EXPECT_LT((x.grad() - y.grad()).abs().max().item<double>(), 1e-4 * y.grad().abs().max().item<double>());
}

// A whole-number shift moves the picture's content by exactly that many
// pixels (x right, y down), the border's values carried in; a fractional one
// is differentiable in the shift.
TEST(ImageLosses, ShiftImageMovesTheContentByTheShift) {
  torch::Tensor image = torch::zeros({1, 2, 12, 16});
  image[0][0][5][7] = 1;
  image[0][1][2][3] = 0.5;
  const torch::Tensor moved = ShiftImage(image, torch::tensor({{3.0f, -2.0f}}));
  EXPECT_NEAR(moved[0][0][3][10].item<double>(), 1.0, 1e-5);
  EXPECT_NEAR(moved[0][1][0][6].item<double>(), 0.5, 1e-5);
  EXPECT_NEAR(moved.sum().item<double>(), 1.5, 1e-4);
  const torch::Tensor shift = torch::tensor({{0.25f, 0.0f}}).requires_grad_(true);
  const torch::Tensor half = ShiftImage(image, shift);
  EXPECT_NEAR(half[0][0][5][7].item<double>(), 0.75, 1e-5);
  EXPECT_NEAR(half[0][0][5][8].item<double>(), 0.25, 1e-5);
  half[0][0][5][8].backward();
  EXPECT_NEAR(shift.grad()[0][0].item<double>(), 1.0, 1e-4);  // d(value at x = 8)/d(shift) of a unit pixel at 7
}

TEST(ImageLosses, PerceptualLossReadsATorchScriptFeatureNetwork) {
  const std::string dir = testing::TempDir("vgg");
  torch::jit::Module net("Features");
  torch::manual_seed(4);
  net.register_parameter("weight", torch::randn({4, 3, 3, 3}), false);
  net.define(R"(
def forward(self, x):
    a = torch.relu(torch.conv2d(x, self.weight))
    return [a, torch.avg_pool2d(a, 2)]
)");
  net.save(dir + "/features.pt");
  PerceptualLoss loss(dir + "/features.pt");
  const torch::Tensor x = torch::rand({1, 3, 16, 16});
  torch::Tensor y = torch::rand({1, 3, 16, 16}).requires_grad_(true);
  EXPECT_NEAR(loss(x, x).item<double>(), 0.0, 1e-9);
  const torch::Tensor l = loss(x, y);
  EXPECT_GT(l.item<double>(), 0);
  l.backward();
  EXPECT_GT(y.grad().abs().sum().item<double>(), 0);
  std::ofstream(dir + "/garbage.pt") << "not a module";
  for (const auto& [file, expected] : std::vector<std::pair<std::string, std::string>>{
           {dir + "/garbage.pt", "not a TorchScript module"}, {dir + "/missing.pt", "no such file"}}) {
    try {
      PerceptualLoss bad(file);
      ADD_FAILURE() << file << " accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

TEST(Dataset, CropIntrinsicsMapTheCropBoxToTheImage) {
  const PinholeCamera full{600, 600, 320, 240, 640, 480};
  const PinholeCamera k = CropIntrinsics(full, 200, 100, 256, 128);
  // A point seen at pixel (u, v) in the frame is at ((u + 0.5 - x0) * s - 0.5, ...) in the crop.
  const Eigen::Vector3d p(0.03, -0.02, 0.6);
  const Eigen::Vector2d in_frame = full.Project(p), in_crop = k.Project(p);
  EXPECT_NEAR(in_crop.x(), (in_frame.x() + 0.5 - 200) * 0.5 - 0.5, 1e-9);
  EXPECT_NEAR(in_crop.y(), (in_frame.y() + 0.5 - 100) * 0.5 - 0.5, 1e-9);
  EXPECT_EQ(k.width, 128);
}

// A prepared dataset written in the documented format from renders with known
// parameters: `frames` frames, the last `test` of them the test split.
// `tau`: the person's skin and hair colours (the builtin head's texture coefficients), others than the default's.
std::string WriteRenderedDataset(const std::string& name, int frames, int test, const Eigen::VectorXf& tau = {}) {
  namespace fs = std::filesystem;
  const std::string dir = testing::TempDir(name);
  fs::create_directories(dir + "/128/images");
  fs::create_directories(dir + "/128/masks");
  SyntheticDataOptions o;
  o.vary_identity = false;
  o.neck_x_deg = o.neck_y_deg = o.neck_z_deg = 10;
  SubjectParams subject = DefaultSubject(Model(), 128);
  subject.shape[0] = 0.5f;
  if (tau.size() > 0) subject.texture = tau;
  SyntheticData data(Model(), o, subject, 7);
  RecordingInfo info;
  info.head_model_name = Model().data().name;
  info.head_model_fingerprint = Model().fingerprint();
  info.num_expression = Model().num_expression();
  info.subject = subject;
  RecordingWriter writer(dir + "/params.hcrec", info);
  PinholeCamera k;
  for (int i = 0; i < frames; ++i) {
    SyntheticSample s = data.At(static_cast<uint64_t>(i));
    k = s.subject.intrinsics;
    s.frame.sequence = static_cast<uint64_t>(i);
    writer.Write(s.frame);
    char file[32];
    std::snprintf(file, sizeof(file), "/%05d.png", i);
    WriteImage(dir + "/128/images" + file, s.image_bgr);
    WriteImage(dir + "/128/masks" + file, s.mask);
  }
  writer.Close();
  const std::vector<float> shape(subject.shape.data(), subject.shape.data() + subject.shape.size());
  const std::vector<float> texture(subject.texture.data(), subject.texture.data() + subject.texture.size());
  const nlohmann::json manifest = {
      {"format", "headcast-dataset"},
      {"format_version", kDatasetFormatVersion},
      {"head_model", {{"name", Model().data().name}, {"fingerprint", Model().fingerprint()}}},
      {"frames_fitted", frames},
      {"split", {{"train", frames - test}, {"test", test}}},
      {"resolutions", {128}},
      {"intrinsics", {{"128", {k.fx, k.fy, k.cx, k.cy}}}},
      {"subject", {{"shape", shape}, {"texture", texture}, {"light", subject.light}}}};
  std::ofstream(dir + "/dataset.json") << manifest.dump(2);
  return dir;
}

// Training masks stop at the fitted jaw line, upright or with the head rolled:
// below the chin is cleared, the face and the sides of the head are kept.
TEST(Dataset, MasksAreClearedBelowTheJawLineOnly) {
  const PinholeCamera camera = PinholeCamera::FromFovY(256, 256, 25);
  for (double roll_deg : {0.0, 30.0}) {
    FrameParams frame;
    frame.expression = Eigen::VectorXf::Zero(Model().num_expression());
    RigidTransform cam_from_head = FrontalCamFromHead(0.62);
    cam_from_head.rotation =
        Eigen::AngleAxisd(roll_deg * M_PI / 180, Eigen::Vector3d::UnitZ()) * cam_from_head.rotation;
    frame.SetCamFromHead(cam_from_head);
    HeadModelOutput posed;
    Model().Forward(Model().MakeIdentity(Eigen::VectorXd::Zero(Model().num_shape())),
                    Eigen::VectorXd::Zero(Model().num_expression()), frame.HeadPose(), &posed);
    std::array<Eigen::Vector2d, kNumLandmarks> lm;
    for (int l = 0; l < kNumLandmarks; ++l)
      lm[l] = camera.Project(cam_from_head.Apply(posed.landmarks.row(l).transpose().cast<double>()));
    cv::Mat mask(256, 256, CV_8U, cv::Scalar(255));
    ClearBelowJawLine(lm, &mask);
    auto at = [&](const Eigen::Vector2d& p) { return mask.at<uint8_t>(cvRound(p.y()), cvRound(p.x())); };
    const Eigen::Vector2d down = (lm[8] - 0.5 * (lm[19] + lm[24])).normalized();
    SCOPED_TRACE("roll " + std::to_string(roll_deg));
    EXPECT_EQ(at(lm[8] + 12 * down), 0) << "under the chin";
    EXPECT_EQ(at(lm[8] + 40 * down), 0) << "the neck";
    EXPECT_EQ(at(lm[30]), 255) << "the nose";
    EXPECT_EQ(at(lm[8] - 6 * down), 255) << "the chin itself";
    const Eigen::Vector2d out = (lm[0] - lm[16]).normalized();
    EXPECT_EQ(at(lm[0] + 10 * out), 255) << "beside the jaw (ear, hair)";
    EXPECT_EQ(at(lm[16] - 10 * out), 255) << "beside the jaw (ear, hair)";
  }
}

// Above the eye line a mask may reach hair_px beyond the model's silhouette,
// below it (cheeks, ears, where GrabCut picks up background) only side_px;
// the line follows a rolled head.
TEST(Dataset, MaskReachIsWideForHairAndNarrowBesideTheFace) {
  const Eigen::Vector2d centre(128, 128);
  for (double roll_deg : {0.0, 30.0}) {
    const Eigen::Rotation2Dd roll(roll_deg * M_PI / 180);
    auto place = [&](double x, double y) -> Eigen::Vector2d { return centre + roll * Eigen::Vector2d(x, y); };
    std::array<Eigen::Vector2d, kNumLandmarks> lm;
    lm.fill(centre);
    for (int l = 36; l <= 47; ++l) lm[l] = place(l < 42 ? -20 : 20, -28);  // eyes 28 px above the centre
    lm[19] = place(-20, -48);
    lm[24] = place(20, -48);
    lm[8] = place(0, 52);  // chin
    cv::Mat silhouette(256, 256, CV_8U, cv::Scalar(0));
    cv::circle(silhouette, cv::Point(128, 128), 60, cv::Scalar(255), cv::FILLED);
    const cv::Mat reach = MaskReach(silhouette, lm, 20, 5);
    auto at = [&](const Eigen::Vector2d& p) { return reach.at<uint8_t>(cvRound(p.y()), cvRound(p.x())); };
    SCOPED_TRACE("roll " + std::to_string(roll_deg));
    EXPECT_EQ(at(place(0, -75)), 255) << "hair 15 px above the head";
    EXPECT_EQ(at(place(0, -85)), 0) << "25 px above the head";
    EXPECT_EQ(at(place(-66, -36)), 255) << "hair beside the temple, above the eyes";
    EXPECT_EQ(at(place(63, 0)), 255) << "3 px beside the cheek";
    EXPECT_EQ(at(place(70, 0)), 0) << "10 px beside the cheek";
    EXPECT_EQ(at(place(-70, 10)), 0) << "10 px beside the other cheek";
    EXPECT_EQ(at(centre), 255) << "the face";
  }
}

// A notch GrabCut cuts into the top of the hair is filled; one below the brows
// (between an ear and the cheek, say) is not, nor is the background.
TEST(Dataset, HairNotchesAboveTheBrowsAreFilled) {
  std::array<Eigen::Vector2d, kNumLandmarks> lm;
  lm.fill(Eigen::Vector2d(128, 128));
  for (int l = 17; l <= 26; ++l) lm[l] = Eigen::Vector2d(100 + 6 * (l - 17), 110);  // brows at y = 110
  lm[8] = Eigen::Vector2d(128, 190);                                                // chin
  cv::Mat mask(256, 256, CV_8U, cv::Scalar(0));
  cv::circle(mask, cv::Point(128, 128), 70, cv::Scalar(255), cv::FILLED);
  const std::vector<cv::Point> top_notch = {{100, 50}, {140, 50}, {120, 80}};
  const std::vector<cv::Point> side_notch = {{190, 140}, {190, 170}, {175, 155}};
  cv::fillConvexPoly(mask, top_notch, cv::Scalar(0));
  cv::fillConvexPoly(mask, side_notch, cv::Scalar(0));
  ASSERT_EQ(mask.at<uint8_t>(65, 120), 0);
  FillHairNotches(lm, &mask);
  EXPECT_EQ(mask.at<uint8_t>(65, 120), 255) << "the notch in the hair";
  EXPECT_EQ(mask.at<uint8_t>(155, 185), 0) << "the notch below the brows";
  EXPECT_EQ(mask.at<uint8_t>(40, 128), 0) << "above the head";
  EXPECT_EQ(mask.at<uint8_t>(128, 128), 255) << "the face";
}

TEST(Dataset, LoadsAndRefusesWhatItCannotUse) {
  const std::string dir = WriteRenderedDataset("dataset_load", 6, 2);
  const PreparedDataset d = PreparedDataset::Load(dir, Model(), 128);
  EXPECT_EQ(d.size(), 6);
  EXPECT_EQ(d.train().size(), 4u);
  EXPECT_EQ(d.test(), (std::vector<int>{4, 5}));
  EXPECT_EQ(d.At(5).image_bgr.size(), cv::Size(128, 128));
  EXPECT_EQ(d.At(5).frame, 5);
  EXPECT_NEAR(d.subject().shape[0], 0.5f, 1e-6);
  auto refused = [&](const std::string& where, int resolution, const std::string& expected) {
    try {
      PreparedDataset::Load(where, Model(), resolution);
      ADD_FAILURE() << where << " accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  };
  refused(dir, 256, "no 256 crops");
  refused(testing::TempDir("dataset_empty"), 128, "not a prepared dataset");
  nlohmann::json m = nlohmann::json::parse(std::ifstream(dir + "/dataset.json"));
  m["head_model"]["fingerprint"] = "0123456789abcdef";
  std::ofstream(dir + "/dataset.json") << m.dump();
  refused(dir, 128, "prepared for head model");
}

// How a dataset's expressions were fitted, for the avatar to carry to the
// sender: as recorded, or (older datasets) the settings of then with the
// eyeLook prior they recorded; a malformed record is refused naming the file.
TEST(Dataset, TellsHowItsExpressionsWereFitted) {
  const std::string dir = WriteRenderedDataset("dataset_fit", 4, 1);
  const auto load = [&](const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json m = nlohmann::json::parse(std::ifstream(dir + "/dataset.json"));
    m.erase("tracking_fit");
    edit(m);
    std::ofstream(dir + "/dataset.json") << m.dump();
    return PreparedDataset::Load(dir, Model(), 128).expression_fit();
  };
  EXPECT_EQ(load([](nlohmann::json&) {}), ExpressionFitSettings::Legacy());
  ExpressionFitSettings legacy_prior = ExpressionFitSettings::Legacy();
  legacy_prior.eye_look_prior = 100;
  legacy_prior.eye_look_prior_shapes = "vertical";
  EXPECT_EQ(load([](nlohmann::json& m) {
              m["tracking"]["eye_look_prior"] = 100;
              m["tracking"]["eye_look_prior_shapes"] = "vertical";
            }),
            legacy_prior);
  const ExpressionFitSettings recorded{5, 100, 0, "all"};
  EXPECT_EQ(load([&](nlohmann::json& m) { m["tracking_fit"] = recorded.ToJson(); }), recorded);
  try {
    load([&](nlohmann::json& m) {
      m["tracking_fit"] = recorded.ToJson();
      m["tracking_fit"]["expression_prior"] = -1;
    });
    ADD_FAILURE() << "a negative prior accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("dataset.json: tracking_fit.expression_prior wants a finite"),
              std::string::npos)
        << e.what();
  }
}

// METHOD §6 on real frames: beta/tau frozen (no offsets there), the first
// CNeRF layers frozen, offsets learned; the test PSNR rises; resume continues exactly.
TEST(TrainAvatar, FineTunesOnRealFramesWithFrozenLayersOffsetsAndResume) {
  const std::string dir = WriteRenderedDataset("dataset_train", 12, 3);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
  const torch::Tensor first_layer = avatar.modules().cnerf->parameters()[0].clone();
  const EvalResult before = EvaluateOnDataset(avatar, Model(), real, real.test());
  FitOptions f;
  f.iterations = 40;
  f.batch = 2;
  f.learning_rate = 5e-3;
  f.freeze_identity = true;
  f.freeze_cnerf_layers = 1;
  f.checkpoint_dir = testing::TempDir("ckpt_real");
  f.checkpoint_every = 20;
  const TrainResult r = TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
  ASSERT_EQ(r.steps.size(), 40u);
  EXPECT_EQ(r.steps[0].synthetic, 0);
  const EvalResult after = EvaluateOnDataset(avatar, Model(), real, real.test());
  EXPECT_GT(after.psnr_mean, before.psnr_mean + 1.0);
  EXPECT_GT(after.ssim_mean, before.ssim_mean);
  EXPECT_EQ((avatar.modules().cnerf->parameters()[0] - first_layer).abs().max().item<double>(), 0.0);
  // Offsets: saved with the checkpoint, zero on beta (the first columns) and tau (the last).
  std::string latest;
  std::getline(std::ifstream(f.checkpoint_dir + "/LATEST"), latest);
  std::vector<torch::Tensor> offsets;
  torch::load(offsets, f.checkpoint_dir + "/" + latest + "/offsets.pt");
  ASSERT_EQ(offsets.size(), 2u);
  const AvatarConfig& c = avatar.config();
  EXPECT_GT(offsets[0].narrow(1, c.num_shape, c.conditioning_dim() - c.num_shape).abs().max().item<double>(), 0);
  // Masked out of the conditioning, beta's offsets get no gradient.
  EXPECT_EQ(offsets[0].narrow(1, 0, c.num_shape).abs().max().item<double>(), 0.0);
  EXPECT_EQ(offsets[1].narrow(1, c.appearance_dim() - c.num_texture, c.num_texture).abs().max().item<double>(), 0.0);
  // The fit reports their mean over the frames (what a subject run may keep as the avatar's conditioning bias).
  ASSERT_EQ(r.mean_offset_geometry.size(), static_cast<size_t>(c.conditioning_dim()));
  ASSERT_EQ(r.mean_offset_appearance.size(), static_cast<size_t>(c.appearance_dim()));
  // Over the training frames' rows: the held-out frames' stay zero and count for nothing.
  std::vector<int64_t> train_rows(real.train().begin(), real.train().end());
  ASSERT_LT(train_rows.size(), static_cast<size_t>(offsets[0].size(0)));
  const torch::Tensor rows = torch::tensor(train_rows);
  EXPECT_EQ(offsets[0]
                .index_select(0, torch::tensor(std::vector<int64_t>(real.test().begin(), real.test().end())))
                .abs()
                .max()
                .item<double>(),
            0.0);
  for (int i = 0; i < c.conditioning_dim(); ++i)
    EXPECT_NEAR(r.mean_offset_geometry[i], offsets[0].index_select(0, rows).select(1, i).mean().item<float>(), 1e-6)
        << i;
  for (int i = 0; i < c.appearance_dim(); ++i)
    EXPECT_NEAR(r.mean_offset_appearance[i], offsets[1].index_select(0, rows).select(1, i).mean().item<float>(), 1e-6)
        << i;
  EXPECT_GT(r.offset_rms, 0);

  // Resume: 6 steps straight against 3 + 3, with augmentation, offsets and mixing.
  SyntheticDataOptions so;
  SyntheticData synthetic(Model(), so, real.subject(), 2);
  FitOptions g;
  g.iterations = 6;
  g.batch = 2;
  g.mix = MixSchedule{0, 6, 0.0, 0.5};
  g.checkpoint_every = 3;
  g.checkpoint_dir = testing::TempDir("ckpt_real_straight");
  Avatar straight = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
  const TrainResult all = TrainAvatar(straight, Model(), TrainingData{&synthetic, {&real}}, g);
  int synthetic_samples = 0;
  for (const auto& s : all.steps) synthetic_samples += s.synthetic;
  EXPECT_GT(synthetic_samples, 0);
  EXPECT_LT(synthetic_samples, 12);
  g.checkpoint_dir = testing::TempDir("ckpt_real_split");
  Avatar first = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
  EXPECT_THROW(TrainAvatar(first, Model(), TrainingData{&synthetic, {&real}}, g, CrashAfter(3)), Crash);
  g.resume = true;
  Avatar second = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 9);
  const TrainResult rest = TrainAvatar(second, Model(), TrainingData{&synthetic, {&real}}, g);
  ASSERT_EQ(rest.steps.size(), 3u);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(rest.steps[i].loss, all.steps[3 + i].loss, 1e-4 * all.steps[3 + i].loss) << "step " << 3 + i;
  // A 256 avatar cannot train on 128 crops.
  AvatarConfig big = Tiny();
  big.output_size = 256;
  Avatar wrong = Avatar::CreateRandom(big, Model(), DefaultSubject(Model(), 256), 1);
  EXPECT_THROW(TrainAvatar(wrong, Model(), TrainingData{nullptr, {&real}}, f), std::invalid_argument);
}

// An avatar told only the neck's rotation: the per-frame offsets stay zero on
// what it is not told (jaw, eyes, expression), or the training frames would
// be memorised there; expression noise, which has nothing to act on, is refused.
TEST(TrainAvatar, OffsetsKeepOutOfWhatTheNetworksAreNotTold) {
  const std::string dir = WriteRenderedDataset("dataset_motion", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  AvatarConfig config = Tiny();
  config.motion_conditioning = MotionConditioning::kNeck;
  Avatar avatar = Avatar::CreateRandom(config, Model(), real.subject(), 4);
  FitOptions f;
  f.iterations = 8;
  f.batch = 2;
  f.freeze_identity = true;
  f.checkpoint_dir = testing::TempDir("ckpt_motion");
  f.checkpoint_every = 8;
  TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
  std::string latest;
  std::getline(std::ifstream(f.checkpoint_dir + "/LATEST"), latest);
  std::vector<torch::Tensor> offsets;
  torch::load(offsets, f.checkpoint_dir + "/" + latest + "/offsets.pt");
  const AvatarConfig& c = avatar.config();
  EXPECT_GT(offsets[0].narrow(1, c.num_shape, 3).abs().max().item<double>(), 0) << "the neck's offsets learn";
  EXPECT_EQ(offsets[0].narrow(1, c.num_shape + 3, c.conditioning_dim() - c.num_shape - 3).abs().max().item<double>(),
            0.0);
  f.expression_noise = 0.1;
  f.checkpoint_dir.clear();
  try {
    TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
    ADD_FAILURE() << "expression noise accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("expression_noise"), std::string::npos) << e.what();
  }
}

// An 8-step fine-tune of a tiny random avatar on `real` (batch 2, identity
// frozen, a checkpoint every 4 steps into `checkpoints` when given);
// `configure` sets what a test varies.
TrainResult ShortFineTune(const PreparedDataset& real, const std::function<void(FitOptions&)>& configure,
                          const std::string& checkpoints = "", bool resume = false,
                          std::function<void(const StepInfo&)> progress = nullptr) {
  Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
  FitOptions f;
  f.iterations = 8;
  f.batch = 2;
  f.freeze_identity = true;
  f.checkpoint_dir = checkpoints;
  f.checkpoint_every = 4;
  f.resume = resume;
  configure(f);
  return TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f, progress);
}

// The same run crashed after its 4th step and resumed from its checkpoint in
// the (empty) folder `checkpoints` takes the last 4 steps `whole` took;
// returns the resumed run.
TrainResult ExpectResumeContinues(const TrainResult& whole, const PreparedDataset& real,
                                  const std::function<void(FitOptions&)>& configure, const std::string& checkpoints) {
  EXPECT_THROW(ShortFineTune(real, configure, checkpoints, false, CrashAfter(4)), Crash);
  const TrainResult rest = ShortFineTune(real, configure, checkpoints, true);
  EXPECT_EQ(rest.steps.size(), 4u);
  for (size_t i = 0; i < 4 && i < rest.steps.size(); ++i)
    EXPECT_NEAR(rest.steps[i].loss, whole.steps[4 + i].loss, 1e-4 * whole.steps[4 + i].loss) << "step " << 4 + i;
  return rest;
}

// The offsets' rate is their own: Adam moves each by about its rate at each
// visit, so four times the rate leaves offsets several times larger, and a
// rate of zero leaves them at zero; a resume
// with their own group continues exactly. With identity offsets, beta as the
// networks are told it takes offsets too in a fine-tune.
TEST(TrainAvatar, TheOffsetsRateIsTheirOwn) {
  const std::string dir = WriteRenderedDataset("dataset_offset_rate", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  auto rate = [](double scale, bool identity_offsets = false) {
    return [=](FitOptions& f) {
      f.offset_lr_scale = scale;
      f.identity_offsets = identity_offsets;
    };
  };
  const TrainResult one = ShortFineTune(real, rate(1)), four = ShortFineTune(real, rate(4)),
                    none = ShortFineTune(real, rate(0));
  ASSERT_GT(one.offset_rms, 0);
  EXPECT_GT(four.offset_rms, 2 * one.offset_rms);
  EXPECT_LT(four.offset_rms, 8 * one.offset_rms);
  EXPECT_EQ(none.offset_rms, 0.0);
  for (float v : none.mean_offset_geometry) EXPECT_EQ(v, 0.f);
  const TrainResult rest = ExpectResumeContinues(four, real, rate(4), testing::TempDir("ckpt_offset_rate"));
  EXPECT_NEAR(rest.offset_rms, four.offset_rms, 1e-4 * four.offset_rms);

  const int shape = Model().num_shape();  // CreateRandom fits the conditioning to the model
  const TrainResult identity = ShortFineTune(real, rate(1, true));
  double beta_one = 0, beta_identity = 0;
  for (int i = 0; i < shape; ++i) {
    beta_one += std::abs(one.mean_offset_geometry.at(i));
    beta_identity += std::abs(identity.mean_offset_geometry.at(i));
  }
  EXPECT_EQ(beta_one, 0.0) << "frozen identity: no offsets on beta";
  EXPECT_GT(beta_identity, 0.0);
}

// Offset segments: consecutive training frames share one offset row and one
// shift; the checkpoint holds a row per segment of the dataset, the held-out
// frames' segment untouched; a resume continues exactly.
TEST(TrainAvatar, OffsetSegmentsShareARow) {
  const std::string dir = WriteRenderedDataset("dataset_offset_segment", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  auto segment = [](int frames) {
    return [=](FitOptions& f) {
      f.offset_segment = frames;
      f.frame_shift_rate = 0.2;
    };
  };
  const TrainResult whole = ShortFineTune(real, segment(2));
  ASSERT_GT(whole.offset_rms, 0);
  const std::string checkpoints = testing::TempDir("ckpt_offset_segment");
  ExpectResumeContinues(whole, real, segment(2), checkpoints);
  for (const std::string file : {"offsets.pt", "shifts.pt"}) {
    std::vector<torch::Tensor> saved;
    torch::load(saved, checkpoints + "/step-8/" + file);
    ASSERT_FALSE(saved.empty());
    ASSERT_EQ(saved[0].size(0), 3) << file << ": six frames, two to a row";
    EXPECT_GT(saved[0].narrow(0, 0, 2).abs().max().item<double>(), 0.0) << file;
    EXPECT_EQ(saved[0].narrow(0, 2, 1).abs().max().item<double>(), 0.0) << file << ": the held-out frames' row";
  }
  FitOptions bad;
  bad.offset_segment = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// Frame shifts: each real training frame's picture moved by a learnt shift
// of its own before the loss. Off, the run has none; on, the training frames'
// shifts move and the held-out frames' stay zero; a resume continues exactly
// (the checkpoint keeps them); the figures go to the fit report.
TEST(TrainAvatar, FrameShiftsAreLearntPerTrainingFrame) {
  const std::string dir = WriteRenderedDataset("dataset_frame_shift", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  auto rate = [](double r) { return [=](FitOptions& f) { f.frame_shift_rate = r; }; };
  const TrainResult off = ShortFineTune(real, rate(0)), on = ShortFineTune(real, rate(0.2));
  EXPECT_EQ(off.frame_shift_rms, 0.0);
  EXPECT_EQ(off.frame_shift_mean[0], 0.0);
  ASSERT_GT(on.frame_shift_rms, 0.01);
  // Adam moves a shift by about its rate at each visit: 16 draws over 4 frames.
  EXPECT_LT(on.frame_shift_rms, 0.2 * 16);
  const std::string checkpoints = testing::TempDir("ckpt_frame_shift");
  const TrainResult rest = ExpectResumeContinues(on, real, rate(0.2), checkpoints);
  EXPECT_NEAR(rest.frame_shift_rms, on.frame_shift_rms, 1e-4 * on.frame_shift_rms);
  std::vector<torch::Tensor> saved;
  torch::load(saved, checkpoints + "/step-8/shifts.pt");
  ASSERT_EQ(saved.size(), 1u);
  ASSERT_EQ(saved[0].size(0), 6);  // a row per frame of the dataset
  EXPECT_EQ(saved[0].narrow(0, 4, 2).abs().max().item<double>(), 0.0) << "held-out frames take no shift";
  EXPECT_GT(saved[0].narrow(0, 0, 4).abs().max().item<double>(), 0.0);
  FitOptions bad;
  bad.frame_shift_rate = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad.frame_shift_rate = 0.1;
  bad.loss.frame_shift_weight = std::nan("");
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// Motion blur: real frames drawn smeared along their motion since the frame
// before (the synthetic frames' poses jump from one to the next). The
// exposure is learnt from its start at its own rate and the avatar keeps it;
// at rate 0 it stays; a checkpoint keeps it, so a resume continues exactly.
TEST(TrainAvatar, MotionBlurLearnsTheCamerasExposure) {
  const std::string dir = WriteRenderedDataset("dataset_motion_blur", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  auto run = [&](double start, double rate, double* kept, const std::string& checkpoints = "", bool resume = false,
                 std::function<void(const StepInfo&)> progress = nullptr) {
    AvatarConfig c = Tiny();
    c.motion_blur = start;
    Avatar avatar = Avatar::CreateRandom(c, Model(), real.subject(), 4);
    FitOptions f;
    f.iterations = 8;
    f.batch = 2;
    f.freeze_identity = true;
    f.exposure_rate = rate;
    f.checkpoint_dir = checkpoints;
    f.checkpoint_every = 4;
    f.resume = resume;
    const TrainResult r = TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f, progress);
    *kept = avatar.config().motion_blur;
    return r;
  };
  double kept = -1;
  const TrainResult sharp = run(0, 0.05, &kept);
  EXPECT_EQ(sharp.exposure, -1.0);
  EXPECT_EQ(kept, 0.0);
  const TrainResult held = run(0.5, 0, &kept);
  EXPECT_EQ(held.exposure, 0.5);
  EXPECT_EQ(kept, 0.5);
  // The same draws (the first frame, with none before it, is drawn sharp).
  auto total = [](const TrainResult& r) {
    double sum = 0;
    for (const StepInfo& s : r.steps) sum += s.loss;
    return sum;
  };
  EXPECT_NE(total(held), total(sharp)) << "the frames drawn smeared";
  const TrainResult learnt = run(0.5, 0.05, &kept);
  EXPECT_NE(learnt.exposure, 0.5);
  EXPECT_GE(learnt.exposure, 0.0);
  EXPECT_LE(learnt.exposure, kMaxMotionBlur);
  EXPECT_EQ(kept, learnt.exposure);
  const std::string checkpoints = testing::TempDir("ckpt_motion_blur");
  EXPECT_THROW(run(0.5, 0.05, &kept, checkpoints, false, CrashAfter(4)), Crash);
  const TrainResult rest = run(0.5, 0.05, &kept, checkpoints, true);
  ASSERT_EQ(rest.steps.size(), 4u);
  for (size_t i = 0; i < 4; ++i)
    EXPECT_NEAR(rest.steps[i].loss, learnt.steps[4 + i].loss, 1e-4 * learnt.steps[4 + i].loss) << "step " << 4 + i;
  EXPECT_NEAR(rest.exposure, learnt.exposure, 1e-6);
  FitOptions bad;
  bad.exposure_rate = -0.1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// Several people's datasets: every frame drawn with its own dataset's subject,
// the offsets one row per frame of the datasets one after another. Networks
// that also saw the second person draw that person's held-out frames better
// than networks trained on the first person alone, from the same start and steps.
TEST(TrainAvatar, TrainsOnSeveralPeoplesDatasets) {
  Eigen::VectorXf other = Eigen::VectorXf::Zero(Model().num_texture());
  other[0] = 2.5f;   // skin tone
  other[3] = -2.5f;  // hair colour
  const PreparedDataset a = PreparedDataset::Load(WriteRenderedDataset("people_a", 8, 2), Model(), 128);
  const PreparedDataset b = PreparedDataset::Load(WriteRenderedDataset("people_b", 6, 2, other), Model(), 128);
  ASSERT_GT(cv::norm(a.At(0).image_bgr, b.At(0).image_bgr, cv::NORM_L1), 0);
  FitOptions f;
  f.iterations = 40;
  f.batch = 2;
  f.learning_rate = 5e-3;
  f.z_augmentation = 0;
  Avatar only_a = Avatar::CreateRandom(Tiny(), Model(), a.subject(), 4);
  TrainAvatar(only_a, Model(), TrainingData{nullptr, {&a}}, f);
  f.checkpoint_dir = testing::TempDir("ckpt_people");
  f.checkpoint_every = 40;
  Avatar both = Avatar::CreateRandom(Tiny(), Model(), a.subject(), 4);
  TrainAvatar(both, Model(), TrainingData{nullptr, {&a, &b}}, f);
  const double on_b_alone = EvaluateOnDataset(only_a, Model(), b, b.test()).psnr_mean,
               on_b_both = EvaluateOnDataset(both, Model(), b, b.test()).psnr_mean;
  EXPECT_GT(on_b_both, on_b_alone + 1.0);
  // And the first person's frames are still learned (fitted: six frames teach a tiny network little beyond them).
  Avatar untrained = Avatar::CreateRandom(Tiny(), Model(), a.subject(), 4);
  EXPECT_GT(EvaluateOnDataset(both, Model(), a, a.train()).psnr_mean,
            EvaluateOnDataset(untrained, Model(), a, a.train()).psnr_mean + 1.0);
  // Offsets: rows 0..7 are a's frames, 8..13 b's; only training frames are drawn.
  std::vector<torch::Tensor> offsets;
  torch::load(offsets, f.checkpoint_dir + "/step-40/offsets.pt");
  ASSERT_EQ(offsets[0].size(0), 14);
  const auto moved = [&](int row) { return offsets[0][row].abs().max().item<double>() > 0; };
  int moved_a = 0, moved_b = 0;
  for (int r = 0; r < 6; ++r) moved_a += moved(r);
  for (int r = 8; r < 12; ++r) moved_b += moved(r);
  EXPECT_GT(moved_a, 0);
  EXPECT_GT(moved_b, 0);
  for (int r : {6, 7, 12, 13}) EXPECT_FALSE(moved(r)) << "test frame " << r << " was trained on";
  // A missing dataset is named, not dereferenced.
  try {
    TrainAvatar(both, Model(), TrainingData{nullptr, {&a, nullptr}}, f);
    ADD_FAILURE() << "a null dataset accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("dataset 2"), std::string::npos) << e.what();
  }
}

// The region weights and the expression noise change what a step sees, from
// the same draws: the first step's loss with weights >= 1 around the eyes and
// mouth is above the plain run's, the noise moves it, and each repeats exactly.
TEST(TrainAvatar, RegionWeightsAndExpressionNoiseShapeTheLossRepeatably) {
  const std::string dir = WriteRenderedDataset("dataset_regions", 6, 2);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  const auto first_loss = [&](double region_weight, double noise) {
    Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
    FitOptions f;
    f.iterations = 1;
    f.batch = 2;
    f.loss.regions.weight = region_weight;
    f.expression_noise = noise;
    const TrainResult r = TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
    return std::make_pair(r.steps[0].loss, r.steps[0].mse);
  };
  const auto plain = first_loss(0, 0), weighted = first_loss(4, 0), noisy = first_loss(0, 0.5);
  EXPECT_GT(weighted.first, plain.first * 1.01);
  EXPECT_FLOAT_EQ(weighted.second, plain.second);  // the reported MSE is the plain one
  EXPECT_NE(noisy.first, plain.first);
  EXPECT_FLOAT_EQ(first_loss(4, 0).first, weighted.first);
  EXPECT_FLOAT_EQ(first_loss(0, 0.5).first, noisy.first);
  FitOptions bad;
  bad.expression_noise = -0.1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad.expression_noise = 0;
  bad.loss.regions.weight = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// The anchor pulls the networks' weights back toward where training started:
// a moderate pull leaves them nearer than no pull does, a pull of one whole
// step's worth (weight x rate = 1) puts them back exactly; bad weights refused.
TEST(TrainAvatar, TheAnchorPullsTheWeightsBackTowardTheStart) {
  const std::string dir = WriteRenderedDataset("dataset_anchor", 4, 1);
  const PreparedDataset real = PreparedDataset::Load(dir, Model(), 128);
  const auto moved = [&](double anchor_weight) {
    Avatar avatar = Avatar::CreateRandom(Tiny(), Model(), real.subject(), 4);
    std::vector<torch::Tensor> start;
    for (const torch::Tensor& p : avatar.modules().cnerf->parameters()) start.push_back(p.detach().clone());
    FitOptions f;
    f.iterations = 3;
    f.batch = 2;
    f.learning_rate = 1e-2;
    f.anchor_weight = anchor_weight;
    TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
    double d = 0;
    const std::vector<torch::Tensor> now = avatar.modules().cnerf->parameters();
    for (size_t i = 0; i < now.size(); ++i) d += (now[i] - start[i]).square().sum().item<double>();
    return std::sqrt(d);
  };
  const double free = moved(0), pulled = moved(20), back = moved(100);
  EXPECT_GT(free, 1e-3);
  EXPECT_LT(pulled, 0.9 * free);
  EXPECT_LT(back, 1e-6);
  FitOptions bad;
  bad.anchor_weight = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// One training step of a tiny avatar with a texture and blendshapes (at
// `start` everywhere) -> the texture's planes and blendshapes after it.
std::pair<torch::Tensor, torch::Tensor> OneBlendshapeStep(const PreparedDataset& real, double scale, double decay,
                                                          double start = 0) {
  AvatarConfig c = Tiny();
  c.surface_features = 4;
  c.surface_resolution = 32;
  c.surface_blend = 8;
  Avatar avatar = Avatar::CreateRandom(c, Model(), real.subject(), 4);
  {  // the texture's branch drawn, or the zero start would pass it no gradient
    torch::NoGradGuard no_grad;
    for (auto& p : avatar.modules().renderer->named_parameters())
      if (p.key().rfind("surface", 0) == 0) p.value().uniform_(-0.5, 0.5);
    avatar.modules().surface->named_parameters()["blend"].fill_(start);
  }
  FitOptions f;
  f.iterations = 1;
  f.batch = 2;
  f.learning_rate = 1e-3;
  f.surface_lr_scale = 5;
  f.blend_lr_scale = scale;
  f.blend_decay = decay;
  TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
  const auto p = avatar.modules().surface->named_parameters();
  return {p["planes"].detach().clone(), p["blend"].detach().clone()};
}

// The texture's expression blendshapes learn at their own rate: Adam's first
// step moves each weight by the group's rate, so after one step the largest
// change of the blendshapes is blend_lr_scale times the networks' rate (none at
// 0), while the texture moves at its own.
TEST(TrainAvatar, TheBlendshapesLearnAtTheirOwnRate) {
  const PreparedDataset real = PreparedDataset::Load(WriteRenderedDataset("dataset_blend", 4, 1), Model(), 128);
  const auto largest = [](const torch::Tensor& t) { return t.abs().max().item<double>(); };
  const auto [planes0, blend0] = OneBlendshapeStep(real, 0, 0);
  EXPECT_NEAR(largest(planes0), 5e-3, 5e-5) << "the texture at its own rate";
  EXPECT_EQ(largest(blend0), 0) << "a rate of zero leaves the blendshapes";
  const auto [planes3, blend3] = OneBlendshapeStep(real, 3, 0);
  EXPECT_NEAR(largest(planes3), 5e-3, 5e-5);
  EXPECT_NEAR(largest(blend3), 3e-3, 3e-5) << "the blendshapes at theirs";
  FitOptions bad;
  bad.blend_lr_scale = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// Their decay is AdamW's, decoupled from the gradient: after Adam's step the
// blendshapes are shrunk by their rate times the decay, and nothing else moves.
TEST(TrainAvatar, TheBlendshapesDecayByTheirRateTimesTheDecay) {
  const PreparedDataset real = PreparedDataset::Load(WriteRenderedDataset("dataset_blend_decay", 4, 1), Model(), 128);
  const double rate = 3e-3, decay = 50;
  const auto [planes, blend] = OneBlendshapeStep(real, 3, 0, 0.5);
  const auto [planes_decayed, blend_decayed] = OneBlendshapeStep(real, 3, decay, 0.5);
  EXPECT_GT((blend - 0.5).abs().max().item<double>(), 1e-3) << "the step itself moved them";
  EXPECT_TRUE(torch::allclose(blend_decayed, blend * (1 - rate * decay), 1e-5, 1e-7));
  EXPECT_TRUE(torch::allclose(planes_decayed, planes, 0, 1e-7)) << "the texture does not decay";
  FitOptions bad;
  bad.blend_decay = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad.blend_decay = 1 / (bad.learning_rate * bad.blend_lr_scale);
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a decay that would wipe them out in one step";
}

// Blendshapes over principal directions: a fine-tune refuses to start
// without the directions; SetBlendDirections takes them from the training
// frames' expressions (unit rows), and the run then trains them.
TEST(TrainAvatar, BlendshapesOverDirectionsTakeThemFromTheTrainingFrames) {
  const PreparedDataset real = PreparedDataset::Load(WriteRenderedDataset("dataset_blend_dirs", 6, 1), Model(), 128);
  AvatarConfig c = Tiny();
  c.surface_features = 4;
  c.surface_resolution = 32;
  c.surface_blend = 8;
  c.surface_blend_components = 2;
  Avatar avatar = Avatar::CreateRandom(c, Model(), real.subject(), 4);
  FitOptions f;
  f.iterations = 1;
  f.batch = 2;
  EXPECT_THROW(TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f), std::invalid_argument);
  const double explained = SetBlendDirections(avatar, real);
  EXPECT_GT(explained, 0);
  EXPECT_LE(explained, 1 + 1e-9);
  const torch::Tensor directions = avatar.modules().surface->named_buffers()["blend_directions"];
  ASSERT_EQ(directions.size(0), 2);
  EXPECT_TRUE(torch::allclose(directions.norm(2, 1), torch::ones({2}), 1e-4, 1e-5));
  TrainAvatar(avatar, Model(), TrainingData{nullptr, {&real}}, f);
  AvatarConfig per_coefficient = c;
  per_coefficient.surface_blend_components = 0;
  Avatar other = Avatar::CreateRandom(per_coefficient, Model(), real.subject(), 4);
  EXPECT_EQ(SetBlendDirections(other, real), 0) << "per coefficient: nothing to set";
}

// c10d scale-out: two ranks (threads here, each with its own Gloo endpoint over
// loopback TCP) end with the weights of one process running the whole batch.
TEST(TrainAvatar, TwoRanksTrainWhatOneProcessTrainsWithTheCombinedBatch) {
  SyntheticDataOptions so;
  so.neck_x_deg = so.neck_y_deg = so.neck_z_deg = 10;
  SyntheticData data(Model(), so, DefaultSubject(Model(), 128), 2);
  FitOptions f;
  f.iterations = 4;
  f.batch = 4;
  f.learning_rate = 5e-3;
  Avatar single = Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4);
  const TrainResult one = FitOnSynthetic(single, Model(), data, f);
  std::vector<Avatar> ranks;
  for (int r = 0; r < 2; ++r) ranks.push_back(Avatar::CreateRandom(Tiny(), Model(), DefaultSubject(Model(), 128), 4));
  std::vector<TrainResult> results(2);
  std::vector<std::string> errors(2);
  const int port = 20000 + static_cast<int>(getpid() % 20000);
  std::vector<std::thread> threads;
  for (int r = 0; r < 2; ++r)
    threads.emplace_back([&, r] {
      try {
        FitOptions g = f;
        g.distributed.rank = r;
        g.distributed.world_size = 2;
        g.distributed.master_port = port;
        g.distributed.timeout_s = 60;
        results[r] = TrainAvatar(ranks[r], Model(), TrainingData{&data, {}}, g);
      } catch (const std::exception& e) {
        errors[r] = e.what();
      }
    });
  for (auto& t : threads) t.join();
  ASSERT_EQ(errors[0] + errors[1], "");
  for (int r = 0; r < 2; ++r) {
    ASSERT_EQ(results[r].steps.size(), 4u);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(results[r].steps[i].loss, one.steps[i].loss, 1e-4 * one.steps[i].loss);
    const auto a = single.modules().parameters(), b = ranks[r].modules().parameters();
    double diff = 0, size = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      diff = std::max(diff, (a[i] - b[i]).abs().max().item<double>());
      size = std::max(size, a[i].abs().max().item<double>());
    }
    EXPECT_LT(diff, 1e-5 * std::max(1.0, size)) << "rank " << r;
  }
}

// Flow interpolation puts a moving picture half way, where a plain blend ghosts it.
TEST(Interpolation, FlowPutsAMovingHeadHalfWay) {
  SyntheticData data(Model(), SyntheticDataOptions{}, DefaultSubject(Model(), 128), 3);
  const cv::Mat base = data.At(0).image_bgr;
  auto shifted = [&](double dx) {
    cv::Mat out;
    cv::warpAffine(base, out, cv::Matx23d(1, 0, dx, 0, 1, 0), base.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    return out;
  };
  const cv::Mat a = shifted(-3), b = shifted(3), truth = shifted(0);
  const cv::Mat mid = InterpolateImage(a, b, DenseFlow(a, b), 0.5);
  cv::Mat blend;
  cv::addWeighted(a, 0.5, b, 0.5, 0, blend);
  const double flow_error = cv::norm(mid, truth, cv::NORM_L1), blend_error = cv::norm(blend, truth, cv::NORM_L1);
  EXPECT_LT(flow_error, 0.5 * blend_error) << flow_error << " vs " << blend_error;
  // The parameters: halfway too.
  FrameParams p = data.At(0).frame, q = p;
  q.cam_translation.x() += 0.02f;
  q.expression[0] += 1.f;
  const FrameParams h = InterpolateParams(p, q, 0.5);
  EXPECT_NEAR(h.cam_translation.x(), p.cam_translation.x() + 0.01f, 1e-6);
  EXPECT_NEAR(h.expression[0], p.expression[0] + 0.5f, 1e-6);
}

// A turned camera sees each point of the head where the turned picture moved
// it: a dot drawn at a point's projection lands on the point's projection
// through the turned cam_from_head, with unequal focal lengths too; the
// head's distance is unchanged, and what comes in at the corners is background.
TEST(TurnCamera, MovesThePictureAsTheTurnedCameraSeesTheHead) {
  PinholeCamera camera;
  camera.fx = 300;
  camera.fy = 330;
  camera.cx = 131;
  camera.cy = 122;
  camera.width = camera.height = 256;
  FrameParams f;
  f.cam_rotation = Eigen::Vector3f(0.1f, -0.2f, 0.05f);
  f.cam_translation = Eigen::Vector3f(0.04f, -0.03f, 0.5f);
  const std::vector<Eigen::Vector3d> points = {
      {0, 0, 0}, {0.05, 0.03, 0.02}, {-0.04, 0.06, -0.01}, {0.02, -0.07, 0.03}};
  for (double angle : {0.3, -0.2}) {
    for (const Eigen::Vector3d& point : points) {
      const Eigen::Vector2d at = camera.Project(f.CamFromHead().Apply(point));
      cv::Mat mask(256, 256, CV_8U, cv::Scalar(0)), image(256, 256, CV_8UC3, cv::Scalar(0, 0, 0));
      cv::circle(mask, cv::Point(std::lround(at.x()), std::lround(at.y())), 3, cv::Scalar(255), cv::FILLED);
      cv::circle(image, cv::Point(std::lround(at.x()), std::lround(at.y())), 3, cv::Scalar(255, 255, 255), cv::FILLED);
      FrameParams g = f;
      TurnCamera(angle, camera, &g, &image, &mask);
      const Eigen::Vector2d expected = camera.Project(g.CamFromHead().Apply(point));
      for (const cv::Mat& m : {mask, image}) {
        cv::Mat grey;
        if (m.channels() == 3)
          cv::cvtColor(m, grey, cv::COLOR_BGR2GRAY);
        else
          grey = m;
        const cv::Moments mo = cv::moments(grey);
        ASSERT_GT(mo.m00, 0) << "the dot left the picture";
        EXPECT_NEAR(mo.m10 / mo.m00, expected.x(), 1.0) << angle;
        EXPECT_NEAR(mo.m01 / mo.m00, expected.y(), 1.0) << angle;
      }
      EXPECT_GT((expected - at).norm(), 3.0) << "the turn moved nothing";
      EXPECT_NEAR(g.cam_translation.norm(), f.cam_translation.norm(), 1e-6);
      EXPECT_NEAR(g.CamFromHead().Apply(point).z(), f.CamFromHead().Apply(point).z(), 1e-6);
    }
  }
  cv::Mat full(256, 256, CV_8U, cv::Scalar(255)), image(256, 256, CV_8UC3, cv::Scalar(9, 9, 9));
  FrameParams g = f;
  TurnCamera(0.3, camera, &g, &image, &full);
  EXPECT_EQ(full.at<uint8_t>(0, 0), 0);
  EXPECT_EQ(full.at<uint8_t>(128, 128), 255);
}

}  // namespace
}  // namespace headcast
