// Synthetic fitting and evaluation.
#include "training/avatar_fit.h"

#include "common/avatar/avatar_pipeline.h"
#include "common/core/options.h"
#include "common/core/timer.h"
#include "common/headmodel/head_render.h"

namespace headcast {
namespace {

struct PreparedSample {
  RayBatch rays;
  RigidTransform cam_from_head;
  AvatarConditioning conditioning;
  torch::Tensor target;
};

PreparedSample Prepare(const AvatarConfig& config, const HeadModel& model, const SyntheticSample& s,
                       RaySampler* sampler, std::mt19937* rng) {
  PreparedSample p;
  p.cam_from_head = s.frame.CamFromHead();
  HeadModelOutput posed;
  model.Forward(model.MakeIdentity(s.subject.shape.cast<double>()), s.frame.expression.cast<double>(),
                s.frame.HeadPose(), &posed);
  RasterVertices v;
  TransformToCamera(posed.vertices, p.cam_from_head, &v);
  const int f = config.feature_size();
  sampler->Sample(v, model.data().faces, s.subject.intrinsics.Resized(f, f), p.cam_from_head, rng, &p.rays);
  p.conditioning = MakeConditioning(config, s.subject, s.frame);
  p.target = BgrToImageTensor(s.image_bgr);
  return p;
}

}  // namespace

void FitOptions::Check() const {
  OptionsCheck c("FitOptions");
  c.InRange("iterations", iterations, 0, 100000000)
      .InRange("batch", batch, 1, 4096)
      .Positive("learning_rate", learning_rate);
  c.ThrowIfErrors();
}

FitResult FitOnSynthetic(Avatar& avatar, const HeadModel& model, SyntheticData& data, const FitOptions& options,
                         const std::function<void(int, float)>& progress) {
  options.Check();
  const AvatarConfig& config = avatar.config();
  AvatarModules& modules = avatar.modules();
  modules.train();
  std::vector<torch::Tensor> params;
  for (auto& p : modules.parameters())
    if (p.requires_grad()) params.push_back(p);
  torch::optim::Adam adam(params, torch::optim::AdamOptions(options.learning_rate));
  RaySampler sampler(config);
  std::mt19937 rng(static_cast<unsigned>(options.seed));
  FitResult result;
  Stopwatch watch;
  for (int step = 0; step < options.iterations; ++step) {
    adam.zero_grad();
    float total = 0;
    for (int b = 0; b < options.batch; ++b) {
      const SyntheticSample s = data.Next();
      const PreparedSample p = Prepare(config, model, s, &sampler, &rng);
      const AvatarOutput out = RunAvatar(modules, p.rays, p.cam_from_head, p.conditioning);
      const torch::Tensor loss = torch::mse_loss(out.image, p.target) / options.batch;
      loss.backward();
      total += loss.item<float>();
    }
    adam.step();
    result.loss.push_back(total);
    if (progress) progress(step, total);
  }
  result.seconds = watch.ElapsedSeconds();
  result.samples_per_s = result.seconds > 0 ? options.iterations * options.batch / result.seconds : 0;
  modules.eval();
  return result;
}

EvalResult EvaluateOnSynthetic(Avatar& avatar, const HeadModel& model, const SyntheticData& data, int count,
                               uint64_t first) {
  AvatarModules& modules = avatar.modules();
  modules.eval();
  torch::InferenceMode inference;
  RaySampler sampler(avatar.config());
  SampleStats ms;
  EvalResult r;
  for (int i = 0; i < count; ++i) {
    const SyntheticSample s = data.At(first + i);
    const PreparedSample p = Prepare(avatar.config(), model, s, &sampler, nullptr);
    Stopwatch watch;
    const AvatarOutput out = RunAvatar(modules, p.rays, p.cam_from_head, p.conditioning);
    ms.Add(watch.ElapsedMs());
    const double mse = torch::mse_loss(out.image, p.target).item<double>();
    r.mse_mean += mse / count;
    r.psnr_mean += 10 * std::log10(1.0 / std::max(mse, 1e-12)) / count;
  }
  r.ms_median = ms.Median();
  r.count = count;
  return r;
}

cv::Mat RenderSampleBgr(Avatar& avatar, const HeadModel& model, const SyntheticSample& sample) {
  avatar.modules().eval();
  torch::InferenceMode inference;
  RaySampler sampler(avatar.config());
  const PreparedSample p = Prepare(avatar.config(), model, sample, &sampler, nullptr);
  cv::Mat bgr;
  ImageTensorToBgr(RunAvatar(avatar.modules(), p.rays, p.cam_from_head, p.conditioning).image, &bgr);
  return bgr;
}

}  // namespace headcast
