// The neural avatar on tiny configurations: shapes, equivalences, gradients,
// a few optimisation steps, sampling, the avatar file and the renderer.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "common/avatar/avatar_pipeline.h"
#include "common/avatar/compute_threads.h"
#include "common/avatar/shuffle_blur.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/skin_colour.h"
#include "tests/testing/test_data.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

namespace F = torch::nn::functional;

AvatarConfig Tiny() { return testing::TinyAvatarConfig(); }

std::shared_ptr<const HeadModel> Builtin() {
  static auto model = std::make_shared<const HeadModel>(MakeBuiltinHead());
  return model;
}

FrameParams Frontal(float jaw = 0.f) {
  FrameParams p;
  p.expression = Eigen::VectorXf::Zero(Builtin()->num_expression());
  p.jaw = Eigen::Vector3f(jaw, 0, 0);
  p.SetCamFromHead(FrontalCamFromHead(0.62));
  return p;
}

TEST(ComputeThreads, LibtorchGetsTheCountAndOpenBlasOne) {
  SetComputeThreads(2);
  EXPECT_EQ(torch::get_num_threads(), 2);
  // Debian's libtorch links OpenBLAS (setup.sh installs it): its pool must be one thread.
  using GetThreads = int (*)();
  auto get = reinterpret_cast<GetThreads>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  ASSERT_NE(get, nullptr) << "libtorch does not multiply in OpenBLAS here";
  EXPECT_EQ(get(), 1);
  SetComputeThreads(1);
  EXPECT_EQ(torch::get_num_threads(), 1);
  EXPECT_EQ(get(), 1);
}

TEST(ComputeThreads, TasksRunAtOnceOnLibtorchsThreadsInTheCallersModes) {
  SetComputeThreads(2);
  const ParallelTasks parallel = TorchParallelTasks();
  // Each task waits until the other has begun: they must run at the same time.
  std::atomic<int> begun{0};
  std::array<std::thread::id, 2> ids;
  std::array<bool, 2> inference{}, grad{true, true};
  {
    const c10::InferenceMode mode;
    parallel(2, [&](int k) {
      ++begun;
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
      while (begun.load() < 2 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
      ids[k] = std::this_thread::get_id();
      inference[k] = c10::InferenceMode::is_enabled();
      grad[k] = at::GradMode::is_enabled();
    });
  }
  EXPECT_EQ(begun.load(), 2);
  EXPECT_NE(ids[0], ids[1]);
  EXPECT_TRUE(inference[0] && inference[1]);
  EXPECT_FALSE(grad[0] || grad[1]);
  // A task's error reaches the caller.
  EXPECT_THROW(parallel(2,
                        [](int k) {
                          if (k == 1) throw std::runtime_error("task");
                        }),
               std::runtime_error);
  // One thread: in order, on the caller's thread.
  SetComputeThreads(1);
  std::vector<int> order;
  std::vector<std::thread::id> where;
  parallel(3, [&](int k) {
    order.push_back(k);
    where.push_back(std::this_thread::get_id());
  });
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(where, std::vector<std::thread::id>(3, std::this_thread::get_id()));
}

TEST(PositionalEncoding, ShapeAndValues) {
  const torch::Tensor x = torch::tensor({0.25f, -0.5f, 0.f}).view({1, 3});
  const torch::Tensor e = PositionalEncoding(x, 2, 0.25);
  ASSERT_EQ(e.sizes(), (std::vector<int64_t>{1, 3 + 12}));
  EXPECT_NEAR(e[0][0].item<float>(), 1.0f, 1e-6);                              // x / scale
  EXPECT_NEAR(e[0][3].item<float>(), std::sin(M_PI * 1.0), 1e-5);              // sin(pi * x0)
  EXPECT_NEAR(e[0][3 + 6 + 1].item<float>(), std::cos(2 * M_PI * 1.0), 1e-5);  // cos(2 pi x0)
}

TEST(CNeRF, ShapesAndPrecomputedConditioningMatchesConcatenation) {
  AvatarConfig c = Tiny();
  torch::manual_seed(3);
  CNeRF fast(c);
  c.precompute_conditioning = false;
  CNeRF slow(c);
  // Same weights in both.
  auto src = fast->named_parameters();
  for (auto& p : slow->named_parameters()) p.value().data().copy_(src[p.key()].data());
  const torch::Tensor points = torch::randn({50, 3}) * 0.1;
  const AvatarConditioning cond{torch::randn({1, c.conditioning_dim()}), torch::randn({1, c.appearance_dim()})};
  auto [d1, f1] = fast->forward(points, cond);
  auto [d2, f2] = slow->forward(points, cond);
  ASSERT_EQ(d1.sizes(), (std::vector<int64_t>{50}));
  ASSERT_EQ(f1.sizes(), (std::vector<int64_t>{50, c.feature_channels}));
  EXPECT_LT((d1 - d2).abs().max().item<float>(), 1e-5);
  EXPECT_LT((f1 - f2).abs().max().item<float>(), 1e-5);
  EXPECT_GE(d1.min().item<float>(), 0.f);  // densities are non-negative
}

TEST(CNeRF, FreezingStopsGradients) {
  CNeRF net(Tiny());
  net->FreezeFirstLayers(2);
  const AvatarConditioning cond{torch::randn({1, Tiny().conditioning_dim()}),
                                torch::randn({1, Tiny().appearance_dim()})};
  auto [d, f] = net->forward(torch::randn({10, 3}) * 0.1, cond);
  (d.sum() + f.sum()).backward();
  int frozen = 0, trained = 0;
  for (auto& p : net->named_parameters()) {
    if (p.key().rfind("layers.0", 0) == 0 || p.key().rfind("layers.1", 0) == 0) {
      EXPECT_FALSE(p.value().grad().defined()) << p.key();
      ++frozen;
    } else {
      EXPECT_TRUE(p.value().grad().defined()) << p.key();
      ++trained;
    }
  }
  EXPECT_EQ(frozen, 4);
  EXPECT_GT(trained, 4);
}

TEST(VolumeRender, OpaqueSampleWinsAndEmptySpaceIsTransparent) {
  const torch::Tensor z = torch::tensor({1.0f, 1.1f, 1.2f, 1.3f}).view({1, 4});
  const torch::Tensor feats = torch::arange(4, torch::kFloat).view({1, 4, 1});
  const torch::Tensor len = torch::ones({1});
  torch::Tensor density = torch::zeros({1, 4});
  auto r = VolumeRender(density, feats, z, len);
  EXPECT_NEAR(r.opacity.item<float>(), 0.f, 1e-6);
  density = torch::tensor({0.f, 1e4f, 1e4f, 0.f}).view({1, 4});
  r = VolumeRender(density, feats, z, len);
  EXPECT_NEAR(r.opacity.item<float>(), 1.f, 1e-4);
  EXPECT_NEAR(r.features.item<float>(), 1.f, 1e-3);  // the first opaque sample's feature
  EXPECT_NEAR(r.depth.item<float>(), 1.1f, 1e-3);
  // Constant density: weights follow 1 - exp(-sigma delta) per step.
  density = torch::full({1, 4}, 2.f);
  r = VolumeRender(density, torch::ones({1, 4, 1}), z, len);
  EXPECT_NEAR(r.opacity.item<float>(), 1 - std::exp(-2.f * 0.4f), 1e-5);
}

TEST(NeuralRenderer, UpsamplesEightTimesAndEveryParameterLearns) {
  NeuralRenderer net(Tiny());
  const torch::Tensor x = torch::randn({2, 8, 16, 16});
  const torch::Tensor y = net->forward(x);
  ASSERT_EQ(y.sizes(), (std::vector<int64_t>{2, 3, 128, 128}));
  EXPECT_GE(y.min().item<float>(), 0.f);
  EXPECT_LE(y.max().item<float>(), 1.f);
  y.mean().backward();
  for (auto& p : net->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_TRUE(torch::isfinite(p.value().grad()).all().item<bool>()) << p.key();
    EXPECT_GT(p.value().grad().abs().sum().item<float>(), 0.f) << p.key();
  }
  for (const auto& b : net->named_buffers()) EXPECT_FALSE(b.value().requires_grad());
}

TEST(NeuralRenderer, AWindowOrChannelsLastDrawTheSamePixels) {
  AvatarConfig c = Tiny();
  c.matte = MatteMode::kLearned;
  c.surface_features = 4;
  c.surface_levels = 3;  // the texture into every level: the averaged terms must land where the whole picture's do
  NeuralRenderer net(c);
  torch::manual_seed(3);
  {  // a matte and a surface branch that start at zero would hide a misplaced window: make them speak
    torch::NoGradGuard no_grad;
    for (auto& p : net->parameters()) p.copy_(0.3 * torch::randn_like(p));
  }
  const torch::Tensor x = torch::randn({1, 8, 16, 16}), surface = torch::randn({1, 4, 128, 128});
  torch::Tensor whole_alpha;
  const torch::Tensor whole = net->forward(x, surface, &whole_alpha);
  for (const ImageWindow w : {ImageWindow{0, 128, 0, 128}, ImageWindow{0, 2, 126, 128}, ImageWindow{10, 64, 0, 50},
                              ImageWindow{36, 128, 82, 128}, ImageWindow{2, 4, 6, 8}}) {
    torch::Tensor alpha;
    const torch::Tensor part = net->forward(x, surface, &alpha, &w);
    ASSERT_EQ(part.sizes(), (std::vector<int64_t>{1, 3, w.height(), w.width()}));
    ASSERT_EQ(alpha.sizes(), (std::vector<int64_t>{1, 1, w.height(), w.width()}));
    const auto same = [&](const torch::Tensor& a, const torch::Tensor& b) {
      return (a - b.slice(2, w.y0, w.y1).slice(3, w.x0, w.x1)).abs().max().item<float>();
    };
    EXPECT_LT(same(part, whole), 1e-5) << w.y0 << " " << w.x0;
    EXPECT_LT(same(alpha, whole_alpha), 1e-4) << w.y0 << " " << w.x0;
  }
  for (const ImageWindow bad : {ImageWindow{1, 8, 0, 8}, ImageWindow{0, 130, 0, 8}, ImageWindow{4, 4, 0, 8}}) {
    torch::Tensor alpha;
    EXPECT_THROW(net->forward(x, surface, &alpha, &bad), std::invalid_argument);
  }
  // Channels-last (the receiver's layout): the same picture, and the surface term
  // built from texture features lands on the same pixels.
  const torch::Tensor features = torch::randn({50, 4}), pixels = torch::randperm(128 * 128).narrow(0, 0, 50);
  const torch::Tensor term = net->SurfaceTerm(features, pixels, 128, 128);
  torch::Tensor alpha_before;
  const torch::Tensor before = net->forward(x, term, &alpha_before);
  net->UseChannelsLast();
  const torch::Tensor term_last = net->SurfaceTerm(features, pixels, 128, 128);
  EXPECT_TRUE(term_last.is_contiguous(torch::MemoryFormat::ChannelsLast));
  EXPECT_LT((term_last - term).abs().max().item<float>(), 1e-6);
  torch::Tensor alpha_after;
  const torch::Tensor after = net->forward(x, term_last, &alpha_after);
  EXPECT_LT((after - before).abs().max().item<float>(), 1e-5);
  EXPECT_LT((alpha_after - alpha_before).abs().max().item<float>(), 1e-4);
}

// The receiver's path, channels-last without gradients, where each upsampling
// block ends in one pass (ShuffleBlur): the pixels the layers draw.
TEST(NeuralRenderer, TheReceiversOnePassUpsamplingDrawsWhatTheLayersDraw) {
  AvatarConfig c = Tiny();
  c.matte = MatteMode::kLearned;
  NeuralRenderer net(c);
  torch::manual_seed(7);
  {
    torch::NoGradGuard no_grad;
    for (auto& p : net->parameters()) p.copy_(0.3 * torch::randn_like(p));
  }
  const torch::Tensor x = torch::randn({1, 8, 16, 16});
  const std::vector<ImageWindow> windows = {ImageWindow{0, 128, 0, 128}, ImageWindow{0, 2, 126, 128},
                                            ImageWindow{10, 64, 0, 50}, ImageWindow{2, 4, 6, 8}};
  std::vector<torch::Tensor> layers, layers_alpha;
  for (const ImageWindow& w : windows) {  // gradients on: libtorch's layers
    layers_alpha.emplace_back();
    layers.push_back(net->forward(x, {}, &layers_alpha.back(), &w).detach());
    layers_alpha.back() = layers_alpha.back().detach();
  }
  net->UseChannelsLast();
  torch::NoGradGuard no_grad;
  for (size_t i = 0; i < windows.size(); ++i) {
    torch::Tensor alpha;
    const torch::Tensor one_pass = net->forward(x, {}, &alpha, &windows[i]);
    EXPECT_LT((one_pass - layers[i]).abs().max().item<float>(), 1e-5) << i;
    EXPECT_LT((alpha - layers_alpha[i]).abs().max().item<float>(), 1e-4) << i;
  }
}

// A (1, C, H, W) float tensor with its channels side by side, as the one-pass kernels read it.
ChannelsLastView View(const torch::Tensor& t) {
  return {t.data_ptr<float>(), t.size(2), t.size(3), t.size(1), t.stride(2), t.stride(3)};
}

void ShuffleBlurAgainstTheLayers(int64_t c) {
  const int64_t h = 6, w = 7, height = 2 * h, width = 2 * w;
  const auto last = torch::MemoryFormat::ChannelsLast;
  const torch::Tensor global_picture = torch::randn({1, 4 * c, h + 2, w + 3}).contiguous(last);
  const torch::Tensor local_picture = torch::randn({1, 4 * c, h + 3, w + 2}).contiguous(last);
  const torch::Tensor global = global_picture.slice(2, 1, 1 + h).slice(3, 2, 2 + w);
  const torch::Tensor local = local_picture.slice(2, 2, 2 + h).slice(3, 1, 1 + w);
  const auto leaky = F::LeakyReLUFuncOptions().negative_slope(0.2);
  const torch::Tensor shuffled = F::pixel_shuffle(F::leaky_relu(global, leaky) + F::leaky_relu(local, leaky), 2);
  const torch::Tensor k1 = torch::tensor({1.f, 2.f, 1.f});
  const torch::Tensor blur = (torch::outer(k1, k1) / 16).view({1, 1, 3, 3}).repeat({c, 1, 1, 1});
  const torch::Tensor want = F::conv2d(F::pad(shuffled, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate)), blur,
                                       F::Conv2dFuncOptions().groups(c));
  struct Case {
    int64_t y0, y1, x0, x1;
  };
  for (const Case& k :
       {Case{0, height, 0, width}, Case{0, 1, 0, 1}, Case{3, 8, 5, 6}, Case{11, 12, 13, 14}, Case{4, 10, 0, width}}) {
    for (const bool just_enough : {false, true}) {
      // All the branches' pixels, or only the rows and columns under the window and the blur's reach.
      const int64_t r0 = just_enough ? std::max<int64_t>(k.y0 - 1, 0) / 2 : 0;
      const int64_t r1 = just_enough ? (std::min(k.y1 + 1, height) + 1) / 2 : h;
      const int64_t c0 = just_enough ? std::max<int64_t>(k.x0 - 1, 0) / 2 : 0;
      const int64_t c1 = just_enough ? (std::min(k.x1 + 1, width) + 1) / 2 : w;
      const torch::Tensor g = global.slice(2, r0, r1).slice(3, c0, c1), l = local.slice(2, r0, r1).slice(3, c0, c1);
      std::vector<float> out((k.y1 - k.y0) * (k.x1 - k.x0) * c, -1.f);
      ShuffleBlur(View(g), View(l), 0.2f, {r0, c0, height, width, k.y0, k.y1, k.x0, k.x1}, out.data());
      const torch::Tensor got = torch::from_blob(out.data(), {1, k.y1 - k.y0, k.x1 - k.x0, c}).permute({0, 3, 1, 2});
      const torch::Tensor expected = want.slice(2, k.y0, k.y1).slice(3, k.x0, k.x1);
      EXPECT_LT((got - expected).abs().max().item<float>(), 1e-6)
          << c << " channels, " << k.y0 << " " << k.x0 << " " << just_enough;
    }
  }
}

// ShuffleBlur against the layers it stands for: leaky ReLUs, sum, PixelShuffle,
// edge-replicating pad and the binomial blur; on views into larger pictures,
// for windows anywhere, from the branches' pixels the window needs or more.
TEST(ShuffleBlur, IsTheUpsamplingBlocksTailInOnePass) {
  torch::manual_seed(11);
  for (const int64_t c : {4, 8, 12, 24})  // the kernel's unrolled widths and another
    ShuffleBlurAgainstTheLayers(c);
  const int64_t c = 4, h = 6, w = 7, height = 2 * h, width = 2 * w;
  const auto last = torch::MemoryFormat::ChannelsLast;
  const torch::Tensor global = torch::randn({1, 4 * c, h, w}).contiguous(last);
  const torch::Tensor local = torch::randn({1, 4 * c, h, w}).contiguous(last);
  // A window whose blur reaches beyond the pixels given, or branches that differ, are refused.
  std::vector<float> out(64 * c);
  const torch::Tensor top = global.slice(2, 0, 2);
  EXPECT_THROW(ShuffleBlur(View(top), View(local.slice(2, 0, 2)), 0.2f, {0, 0, height, width, 2, 4, 0, 2}, out.data()),
               std::invalid_argument);
  EXPECT_NO_THROW(
      ShuffleBlur(View(top), View(local.slice(2, 0, 2)), 0.2f, {0, 0, height, width, 2, 3, 0, 2}, out.data()));
  EXPECT_THROW(
      ShuffleBlur(View(global), View(local.slice(1, 0, 8)), 0.2f, {0, 0, height, width, 0, 2, 0, 2}, out.data()),
      std::invalid_argument);
  EXPECT_THROW(ShuffleBlur(View(global), View(local), 0.2f, {0, 0, height, width, 0, height + 2, 0, 2}, out.data()),
               std::invalid_argument);
}

TEST(NeuralRenderer, TwoLevelsUpsampleFourTimesAndAWindowDrawsTheSamePixels) {
  AvatarConfig c = Tiny();
  c.renderer_channels = {8, 8, 4};  // two x2 levels: a feature map of output/4
  c.matte = MatteMode::kLearned;
  c.surface_features = 4;
  c.surface_levels = 2;
  ASSERT_NO_THROW(c.Check());
  EXPECT_EQ(c.renderer_levels(), 2);
  EXPECT_EQ(c.feature_size(), 32);
  NeuralRenderer net(c);
  torch::manual_seed(5);
  {
    torch::NoGradGuard no_grad;
    for (auto& p : net->parameters()) p.copy_(0.3 * torch::randn_like(p));
  }
  const torch::Tensor x = torch::randn({1, 8, 32, 32}), surface = torch::randn({1, 4, 128, 128});
  torch::Tensor whole_alpha;
  const torch::Tensor whole = net->forward(x, surface, &whole_alpha);
  ASSERT_EQ(whole.sizes(), (std::vector<int64_t>{1, 3, 128, 128}));
  ASSERT_EQ(whole_alpha.sizes(), (std::vector<int64_t>{1, 1, 128, 128}));
  for (const ImageWindow w : {ImageWindow{0, 128, 0, 128}, ImageWindow{10, 64, 0, 50}, ImageWindow{36, 128, 82, 128}}) {
    torch::Tensor alpha;
    const torch::Tensor part = net->forward(x, surface, &alpha, &w);
    ASSERT_EQ(part.sizes(), (std::vector<int64_t>{1, 3, w.height(), w.width()}));
    EXPECT_LT((part - whole.slice(2, w.y0, w.y1).slice(3, w.x0, w.x1)).abs().max().item<float>(), 1e-5);
    EXPECT_LT((alpha - whole_alpha.slice(2, w.y0, w.y1).slice(3, w.x0, w.x1)).abs().max().item<float>(), 1e-4);
  }
  // As made: every level's layers learn (the texture's branch and the matte's
  // layers start at zero, so only their output layers do at first; a tiny
  // squeeze-excitation's single hidden unit may start dead).
  NeuralRenderer fresh(c);
  const torch::Tensor features = torch::randn({50, 4}), pixels = torch::randperm(128 * 128).narrow(0, 0, 50);
  torch::Tensor alpha;
  const torch::Tensor rgb = fresh->forward(x, fresh->SurfaceTerm(features, pixels, 128, 128), &alpha);
  (rgb.mean() + alpha.mean()).backward();
  int learning = 0;
  for (auto& p : fresh->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_TRUE(torch::isfinite(p.value().grad()).all().item<bool>()) << p.key();
    const bool must_learn = p.key().find("_branch") != std::string::npos || p.key().rfind("post.", 0) == 0 ||
                            p.key().rfind("to_", 0) == 0 || p.key().rfind("input_", 0) == 0 ||
                            p.key().rfind("surface_out", 0) == 0;
    if (must_learn) {
      EXPECT_GT(p.value().grad().abs().sum().item<float>(), 0.f) << p.key();
    }
    learning += must_learn;
  }
  EXPECT_EQ(learning, 2 * 10 + 4 + 2) << "per level two branches, post, to_rgb, to_alpha; the inputs; surface_out";
  // The level count is the channel list's: two entries or a texture in more
  // levels than there are are refused by name.
  AvatarConfig bad = c;
  bad.renderer_channels = {8, 4};
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = c;
  bad.surface_levels = 3;
  try {
    bad.Check();
    ADD_FAILURE() << "three texture levels in a two-level renderer passed";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("surface_levels"), std::string::npos) << e.what();
  }
}

TEST(RaySampler, MeshGuidedRaysCoverTheHeadAndSkipTheRest) {
  AvatarConfig c = Tiny();
  const HeadModel& m = *Builtin();
  const FrameParams p = Frontal();
  const RigidTransform cam_from_head = p.CamFromHead();
  const HeadModelOutput posed = m.Forward(HeadModelParams{});
  RasterVertices v;
  TransformToCamera(posed.vertices, cam_from_head, &v);
  const PinholeCamera cam = DefaultSubject(m, c.output_size).intrinsics.Resized(16, 16);
  RayBatch guided, uniform;
  RaySampler(c).Sample(v, m.data().faces, cam, cam_from_head, nullptr, &guided);
  c.sampling = SamplingMode::kUniform;
  RaySampler(c).Sample(v, m.data().faces, cam, cam_from_head, nullptr, &uniform);
  EXPECT_EQ(uniform.num_rays(), 256);
  EXPECT_GT(guided.num_rays(), 40);
  EXPECT_LT(guided.num_rays(), 256);
  RasterBuffers buf;
  Rasterize(v, m.data().faces, cam, RasterOptions{}, &buf);
  // Every pixel the head covers has a ray whose samples bracket its depth.
  int covered = 0;
  for (int i = 0; i < guided.num_rays(); ++i) {
    const int px = guided.pixel[i];
    if (buf.face[px] < 0) continue;
    ++covered;
    const float d = buf.depth[px];
    EXPECT_LT(guided.depths[i * 4], d);
    EXPECT_GT(guided.depths[i * 4 + 3], d);
  }
  EXPECT_EQ(covered, buf.CoveredPixels());
  // Depths increase along each ray; jitter stays in the shell.
  std::mt19937 rng(1);
  c.sampling = SamplingMode::kMeshGuided;
  RaySampler(c).Sample(v, m.data().faces, cam, cam_from_head, &rng, &guided);
  for (int i = 0; i < guided.num_rays(); ++i)
    for (int k = 1; k < 4; ++k) EXPECT_GT(guided.depths[i * 4 + k], guided.depths[i * 4 + k - 1]);
}

TEST(AvatarPipeline, AFewStepsReduceTheLossOnAFixedTarget) {
  const AvatarConfig c = Tiny();
  const HeadModel& m = *Builtin();
  Avatar avatar = Avatar::CreateRandom(c, m, DefaultSubject(m, c.output_size), 5);
  const FrameParams p = Frontal(0.1f);
  const RigidTransform cam_from_head = p.CamFromHead();
  const HeadModelOutput posed = m.Forward(HeadModelParams{});
  RasterVertices v;
  TransformToCamera(posed.vertices, cam_from_head, &v);
  AvatarFrameInputs inputs;
  inputs.cam_from_head = cam_from_head;
  RaySampler(c).Sample(v, m.data().faces, avatar.subject().intrinsics.Resized(16, 16), cam_from_head, nullptr,
                       &inputs.rays);
  // Target: the head model's own render (what the general model learns from).
  const HeadRender target_render =
      RenderHead(m, posed.vertices, cam_from_head, avatar.subject().intrinsics, AlbedoTexture(m));
  const torch::Tensor target = BgrToImageTensor(target_render.image_bgr);
  inputs.conditioning = MakeConditioning(c, avatar.subject(), p);
  torch::optim::Adam adam(avatar.modules().parameters(), torch::optim::AdamOptions(5e-3));
  std::vector<float> losses;
  for (int step = 0; step < 25; ++step) {
    adam.zero_grad();
    const AvatarOutput out = RunAvatar(avatar.modules(), inputs);
    const torch::Tensor loss = torch::mse_loss(out.image, target);
    loss.backward();
    adam.step();
    losses.push_back(loss.item<float>());
  }

  EXPECT_LT(losses.back(), 0.8f * losses.front()) << "first " << losses.front() << " last " << losses.back();
}

class AvatarFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TempDir("avatar");
    path_ = dir_ + "/a.hcavatar";
    Avatar a = Avatar::CreateRandom(Tiny(), *Builtin(), DefaultSubject(*Builtin(), 128), 9);
    a.training_summary()["note"] = "test";
    a.Save(path_, cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)));
  }
  std::string LoadError(const std::string& path, const HeadModel& model) {
    try {
      Avatar::Load(path, model);
    } catch (const std::exception& e) {
      return e.what();
    }
    return "loaded";
  }
  std::string WithManifest(const std::string& name, const std::function<void(nlohmann::json*)>& edit) {
    ZipEntries entries = ReadZip(path_);
    nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
    edit(&manifest);
    entries["manifest.json"] = manifest.dump();
    const std::string out = dir_ + "/" + name + ".hcavatar";
    WriteZip(out, entries);
    return out;
  }
  std::string dir_, path_;
};

TEST_F(AvatarFileTest, RoundTripRendersIdentically) {
  Avatar a = Avatar::Load(path_, *Builtin());
  EXPECT_EQ(a.training_summary()["note"], "test");
  EXPECT_EQ(a.config().ToJson(), Tiny().ToJson());
  Avatar b = Avatar::CreateRandom(Tiny(), *Builtin(), DefaultSubject(*Builtin(), 128), 9);
  AvatarRenderer ra(Builtin(), std::move(a)), rb(Builtin(), std::move(b));
  cv::Mat ia, ib;
  ASSERT_TRUE(ra.Render(Frontal(), &ia));
  ASSERT_TRUE(rb.Render(Frontal(), &ib));
  EXPECT_EQ(cv::norm(ia, ib, cv::NORM_INF), 0);
  EXPECT_EQ(Avatar::ReadManifest(path_)["output_resolution"], 128);
  EXPECT_TRUE(ReadZip(path_).count("preview.png"));
}

// An avatar switched to another output size (a general model continued or
// fine-tuned at 256) keeps its field of view, and what it saves loads again.
TEST_F(AvatarFileTest, AnotherOutputSizeKeepsTheFieldOfViewAndLoadsAgain) {
  const Avatar a = Avatar::Load(path_, *Builtin());
  AvatarConfig bigger = a.config();
  bigger.output_size = 256;
  const Avatar b = a.WithRuntimeSwitches(bigger);
  const PinholeCamera &k128 = a.subject().intrinsics, &k256 = b.subject().intrinsics;
  EXPECT_EQ(k256.width, 256);
  EXPECT_EQ(k256.height, 256);
  EXPECT_NEAR(k256.fy, 2 * k128.fy, 1e-9);
  EXPECT_NEAR(k256.cx, (k128.cx + 0.5) * 2 - 0.5, 1e-9);  // pixel centres
  const std::string out = dir_ + "/b256.hcavatar";
  b.Save(out);
  EXPECT_EQ(LoadError(out, *Builtin()), "loaded");
  EXPECT_EQ(Avatar::ReadManifest(out)["output_resolution"], 256);
}

TEST_F(AvatarFileTest, RefusesOtherVersionsHeadModelsAndBrokenFiles) {
  std::string e = LoadError(WithManifest("v2", [](nlohmann::json* m) { (*m)["format_version"] = 2; }), *Builtin());
  EXPECT_NE(e.find("format version 2"), std::string::npos) << e;
  BuiltinHeadOptions other;
  other.columns = 64;
  e = LoadError(path_, MakeBuiltinHead(other));
  EXPECT_NE(e.find("made for head model"), std::string::npos) << e;
  e = LoadError(WithManifest("wider", [](nlohmann::json* m) { (*m)["config"]["mlp_width"] = 32; }), *Builtin());
  EXPECT_NE(e.find("weights do not match"), std::string::npos) << e;
  e = LoadError(WithManifest("badcfg", [](nlohmann::json* m) { (*m)["config"]["output_size"] = 300; }), *Builtin());
  EXPECT_NE(e.find("output_size"), std::string::npos) << e;
  const std::string cut = dir_ + "/cut.hcavatar";
  std::filesystem::copy_file(path_, cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(path_) / 2);
  e = LoadError(cut, *Builtin());
  EXPECT_NE(e.find("cut.hcavatar"), std::string::npos) << e;
  WriteZip(dir_ + "/foreign.hcavatar", {{"hello.txt", "hi"}});
  e = LoadError(dir_ + "/foreign.hcavatar", *Builtin());
  EXPECT_NE(e.find("not a headcast avatar"), std::string::npos) << e;
  e = LoadError(dir_ + "/none.hcavatar", *Builtin());
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
}

TEST_F(AvatarFileTest, TheBackendIsChosenByTheManifestsKind) {
  const std::shared_ptr<const HeadModel> builtin = Builtin();
  EXPECT_EQ(Avatar::ReadManifest(path_)["kind"], "cnerf");
  std::unique_ptr<AvatarBackend> backend = OpenAvatarBackend(path_, builtin);
  EXPECT_EQ(backend->kind(), "cnerf");
  EXPECT_EQ(backend->output_size(), 128);
  EXPECT_FALSE(backend->camera_contract());
  cv::Mat image;
  ASSERT_TRUE(backend->Render(Frontal(), &image));
  EXPECT_EQ(image.size(), cv::Size(128, 128));
  // Files written before the kind existed are CNeRF avatars.
  const std::string old = WithManifest("old", [](nlohmann::json* m) { m->erase("kind"); });
  EXPECT_EQ(OpenAvatarBackend(old, builtin)->kind(), "cnerf");
  const std::string gaussian = WithManifest("gaussian", [](nlohmann::json* m) { (*m)["kind"] = "gaussians"; });
  try {
    OpenAvatarBackend(gaussian, builtin);
    ADD_FAILURE() << "an unknown backend was opened";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'gaussians' is not in this build (it has: cnerf)"), std::string::npos)
        << e.what();
  }
  EXPECT_NE(LoadError(gaussian, *Builtin()).find("not a CNeRF one"), std::string::npos);
}

TEST_F(AvatarFileTest, TheCameraContractTravelsWithTheAvatar) {
  Avatar a = Avatar::Load(path_, *Builtin());
  CameraContract c;
  c.source = PinholeCamera{640, 640, 319.5, 239.5, 640, 480};
  c.crop_x0 = 120;
  c.crop_y0 = 10;
  c.crop_side = 380;
  a.set_camera_contract(c);
  const std::string with = dir_ + "/contract.hcavatar";
  a.Save(with);
  const Avatar back = Avatar::Load(with, *Builtin());
  ASSERT_TRUE(back.camera_contract());
  EXPECT_EQ(back.camera_contract()->source.fx, 640);
  EXPECT_EQ(back.camera_contract()->crop_side, 380);
  const std::string broken = WithManifest("badcam", [&](nlohmann::json* m) {
    (*m)["camera"] = {{"crop", {{"x0", 1}}}};
  });
  EXPECT_NE(LoadError(broken, *Builtin()).find("camera contract"), std::string::npos) << LoadError(broken, *Builtin());
}

// A model with many blendshapes (ICT-FaceKit has 53, named, not ordered by
// variance): the avatar must be conditioned on all of them, so that the last
// one (a mouth shape in ICT) still changes what it renders.
TEST(AvatarRenderer, EveryExpressionComponentOfTheModelConditionsTheAvatar) {
  HeadModelData d = Builtin()->data();
  const int e0 = static_cast<int>(d.expressiondirs.cols()), e = 40;
  d.expressiondirs.conservativeResize(Eigen::NoChange, e);
  for (int k = e0; k < e; ++k) d.expressiondirs.col(k) = d.expressiondirs.col(k % e0) * 0.5f;
  d.expression_names.clear();
  auto many = std::make_shared<const HeadModel>(std::move(d));
  AvatarConfig c = Tiny();
  c.num_expression = AvatarConfig().num_expression;  // the default bound, above 40
  Avatar avatar = Avatar::CreateRandom(c, *many, DefaultSubject(*many, 128), 4);
  EXPECT_EQ(avatar.config().num_expression, e);
  AvatarRenderer r(many, std::move(avatar));
  FrameParams p;
  p.expression = Eigen::VectorXf::Zero(e);
  p.SetCamFromHead(FrontalCamFromHead(0.62));
  cv::Mat neutral, last;
  ASSERT_TRUE(r.Render(p, &neutral));
  p.expression[e - 1] = 3.f;
  ASSERT_TRUE(r.Render(p, &last));
  EXPECT_GT(cv::norm(neutral, last, cv::NORM_L1), 0) << "the last expression component did not reach the network";
}

TEST(AvatarRenderer, TheParallelStagesDrawTheSamePicture) {
  // A subject's avatar (surface texture, bounded matte with a core, canonical
  // samples): everything the helper prepares is used.
  AvatarConfig c = Tiny();
  ApplySubjectDefaults(&c);
  c.matte_core = 0.02;
  c.canonical_samples = true;
  auto make = [&] { return Avatar::CreateRandom(c, *Builtin(), DefaultSubject(*Builtin(), 128), 4); };
  AvatarRendererOptions with, without;
  with.threads = without.threads = 2;
  without.parallel_stages = false;
  AvatarRenderer helped(Builtin(), make(), with), alone(Builtin(), make(), without);
  for (float jaw : {0.f, 0.2f, 0.05f}) {
    FrameParams p = Frontal(jaw);
    p.neck = Eigen::Vector3f(0.1f * jaw, 0.3f * jaw, 0);
    cv::Mat a, b;
    AvatarTimings t;
    ASSERT_TRUE(helped.Render(p, &a, &t));
    ASSERT_TRUE(alone.Render(p, &b));
    EXPECT_GT(t.surface_ms, 0);
    EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0) << "jaw " << jaw;
  }
}

TEST(AvatarRenderer, ATwoLevelAvatarCastsRaysAtAQuarterOfTheOutputAndRoundTrips) {
  AvatarConfig three = Tiny();
  ApplySubjectDefaults(&three);
  AvatarConfig two = three;
  ApplyTwoLevelRenderer(&two);
  EXPECT_EQ(two.renderer_channels, (std::vector<int>{three.feature_channels, 24, 8}));
  EXPECT_EQ(two.hair_margin_px, 2 * three.hair_margin_px);  // the same reach in output pixels
  EXPECT_EQ(two.samples_per_ray, 4);
  const SubjectParams subject = DefaultSubject(*Builtin(), 128);
  AvatarRenderer coarse(Builtin(), Avatar::CreateRandom(three, *Builtin(), subject, 4));
  const std::string path = (std::filesystem::temp_directory_path() / "two_levels_test.hcavatar").string();
  Avatar::CreateRandom(two, *Builtin(), subject, 4).Save(path);
  Avatar loaded = Avatar::Load(path, *Builtin());
  std::filesystem::remove(path);
  EXPECT_EQ(loaded.config().ToJson(), two.ToJson());
  AvatarRenderer fine(Builtin(), std::move(loaded));
  AvatarRenderer again(Builtin(), Avatar::CreateRandom(two, *Builtin(), subject, 4));
  cv::Mat a, b, c;
  AvatarTimings ta, tb;
  ASSERT_TRUE(coarse.Render(Frontal(0.1f), &a, &ta));
  ASSERT_TRUE(fine.Render(Frontal(0.1f), &b, &tb));
  ASSERT_TRUE(again.Render(Frontal(0.1f), &c));
  EXPECT_EQ(b.size(), cv::Size(128, 128));
  EXPECT_EQ(cv::norm(b, c, cv::NORM_INF), 0) << "the file changed the two-level avatar's picture";
  // A feature pixel a quarter of the area: about four times the rays.
  EXPECT_GT(tb.rays, 3 * ta.rays);
  EXPECT_LT(tb.rays, 5 * ta.rays);
}

// A frame that carries the camera's skin colour: the picture's skin is
// brought to it (within the 8-bit rounding), the background stays, and a frame
// without one draws what the avatar draws.
TEST(AvatarRenderer, TheSkinColourOfTheFrameIsMatched) {
  AvatarConfig c = Tiny();
  ApplySubjectDefaults(&c);  // a bounded matte: the background is the renders' colour
  const SubjectParams subject = DefaultSubject(*Builtin(), 128);
  AvatarRenderer r(Builtin(), Avatar::CreateRandom(c, *Builtin(), subject, 4));
  FrameParams p = Frontal();
  cv::Mat own, matched;
  ASSERT_TRUE(r.Render(p, &own));
  HeadModelOutput posed;
  Builtin()->Forward(Builtin()->MakeIdentity(subject.shape.cast<double>()), p.expression.cast<double>(), p.HeadPose(),
                     &posed);
  const Landmarks2d landmarks = ProjectLandmarks(posed, p.CamFromHead(), subject.intrinsics);
  const std::optional<Eigen::Vector3f> drawn = SkinColour(own, landmarks);
  ASSERT_TRUE(drawn.has_value());
  const Eigen::Vector3f target = (drawn->array() * Eigen::Array3f(1.25f, 0.8f, 1.1f)).min(1.f).matrix();
  p.skin_colour = target;
  ASSERT_TRUE(r.Render(p, &matched));
  const std::optional<Eigen::Vector3f> now = SkinColour(matched, landmarks);
  ASSERT_TRUE(now.has_value());
  for (int k = 0; k < 3; ++k)
    if ((*drawn)[k] > 0.1f) {
      EXPECT_NEAR((*now)[k], target[k], 2.5f / 255) << "channel " << k;
    }
  EXPECT_EQ(matched.at<cv::Vec3b>(0, 0), own.at<cv::Vec3b>(0, 0));  // the background
  EXPECT_GT(cv::norm(own, matched, cv::NORM_L1), 0);
  p.skin_colour.reset();
  cv::Mat again;
  ASSERT_TRUE(r.Render(p, &again));
  EXPECT_EQ(cv::norm(own, again, cv::NORM_INF), 0);
  p.skin_colour = Eigen::Vector3f(2, 0.5f, 0.5f);  // outside 0..1: refused like any bad value
  std::string why;
  EXPECT_FALSE(r.Render(p, &again, nullptr, &why));
  EXPECT_NE(why.find("skin colour"), std::string::npos) << why;
}

TEST(AvatarRenderer, RendersAndRefusesBadParameters) {
  AvatarRenderer r(Builtin(), Avatar::CreateRandom(Tiny(), *Builtin(), DefaultSubject(*Builtin(), 128)));
  cv::Mat image;
  AvatarTimings t;
  ASSERT_TRUE(r.Render(Frontal(), &image, &t));
  EXPECT_EQ(image.size(), cv::Size(128, 128));
  EXPECT_EQ(image.type(), CV_8UC3);
  EXPECT_GT(t.rays, 0);
  EXPECT_EQ(t.samples, 4 * t.rays);
  EXPECT_GT(t.total_ms, 0);
  FrameParams bad = Frontal();
  bad.expression[2] = std::nanf("");
  std::string why;
  cv::Mat untouched = image.clone();
  EXPECT_FALSE(r.Render(bad, &image, nullptr, &why));
  EXPECT_NE(why.find("expression"), std::string::npos);
  EXPECT_EQ(cv::norm(image, untouched, cv::NORM_INF), 0);
  bad = Frontal();
  bad.cam_translation.z() = -1;
  EXPECT_FALSE(r.Render(bad, &image, nullptr, &why));
  // Another head model is refused at construction.
  BuiltinHeadOptions other;
  other.columns = 64;
  auto other_model = std::make_shared<const HeadModel>(MakeBuiltinHead(other));
  EXPECT_THROW(AvatarRenderer(other_model, Avatar::CreateRandom(Tiny(), *Builtin(), DefaultSubject(*Builtin(), 128))),
               std::invalid_argument);
}

}  // namespace
}  // namespace headcast
