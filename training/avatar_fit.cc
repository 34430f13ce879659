// Synthetic fitting and evaluation.
#include "training/avatar_fit.h"

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

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
      .Positive("learning_rate", learning_rate)
      .InRange("checkpoint_every", checkpoint_every, 1, 100000000);
  c.That(!resume || !checkpoint_dir.empty(), "resume needs a checkpoint_dir");
  c.ThrowIfErrors();
}

namespace {

namespace fs = std::filesystem;

// Writes `text` to `path` through a temporary file and a rename (atomic on POSIX).
void WriteAtomically(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp);
    out << text;
    if (!out) throw std::runtime_error(tmp.string() + ": cannot write");
  }
  fs::rename(tmp, path);
}

void SaveCheckpoint(const fs::path& dir, int next_step, const Avatar& avatar, torch::optim::Adam& adam) {
  const fs::path staging = dir / ("staging-" + std::to_string(next_step));
  fs::remove_all(staging);
  fs::create_directories(staging);
  avatar.Save((staging / "avatar.hcavatar").string());
  torch::serialize::OutputArchive archive;
  adam.save(archive);
  archive.save_to((staging / "optimizer.pt").string());
  WriteAtomically(staging / "state.json", nlohmann::json{{"next_step", next_step}}.dump() + "\n");
  const fs::path final_dir = dir / ("step-" + std::to_string(next_step));
  fs::remove_all(final_dir);
  fs::rename(staging, final_dir);
  std::string previous;
  if (std::ifstream latest(dir / "LATEST"); latest) std::getline(latest, previous);
  WriteAtomically(dir / "LATEST", final_dir.filename().string() + "\n");
  if (!previous.empty() && previous != final_dir.filename().string()) fs::remove_all(dir / previous);
}

// Restores weights and optimiser state; returns the step to continue from (0 without a checkpoint).
int LoadCheckpoint(const fs::path& dir, Avatar& avatar, const HeadModel& model, torch::optim::Adam& adam,
                   const std::vector<torch::Tensor>& params) {
  std::ifstream latest(dir / "LATEST");
  if (!latest) return 0;
  std::string name;
  std::getline(latest, name);
  const fs::path ckpt = dir / name;
  try {
    const nlohmann::json state = nlohmann::json::parse(std::ifstream(ckpt / "state.json"));
    const int next_step = state.at("next_step").get<int>();
    const Avatar saved = Avatar::Load((ckpt / "avatar.hcavatar").string(), model);
    const std::vector<torch::Tensor> from = saved.modules().parameters();
    if (from.size() != params.size()) throw std::runtime_error("the checkpoint's networks differ from this avatar's");
    torch::NoGradGuard no_grad;
    for (size_t i = 0; i < params.size(); ++i) {
      if (!from[i].sizes().equals(params[i].sizes()))
        throw std::runtime_error("the checkpoint's networks differ from this avatar's");
      params[i].copy_(from[i]);
    }
    torch::serialize::InputArchive archive;
    archive.load_from((ckpt / "optimizer.pt").string());
    adam.load(archive);
    return next_step;
  } catch (const std::exception& e) {
    throw std::runtime_error(ckpt.string() + ": cannot resume from this checkpoint (" + e.what() + ")");
  }
}

}  // namespace

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
  FitResult result;
  if (options.resume) result.first_step = LoadCheckpoint(options.checkpoint_dir, avatar, model, adam, params);
  if (!options.checkpoint_dir.empty()) fs::create_directories(options.checkpoint_dir);
  Stopwatch watch;
  for (int step = result.first_step; step < options.iterations; ++step) {
    // Samples and jitter drawn per step, so a resumed run sees what the uninterrupted one would.
    std::mt19937 rng(static_cast<unsigned>(options.seed * 1000003u + static_cast<uint64_t>(step)));
    adam.zero_grad();
    float total = 0;
    for (int b = 0; b < options.batch; ++b) {
      const SyntheticSample s = data.At(static_cast<uint64_t>(step) * options.batch + b);
      const PreparedSample p = Prepare(config, model, s, &sampler, &rng);
      const AvatarOutput out = RunAvatar(modules, p.rays, p.cam_from_head, p.conditioning);
      const torch::Tensor loss = torch::mse_loss(out.image, p.target) / options.batch;
      loss.backward();
      total += loss.item<float>();
    }
    adam.step();
    result.loss.push_back(total);
    if (progress) progress(step, total);
    if (!options.checkpoint_dir.empty() &&
        ((step + 1) % options.checkpoint_every == 0 || step + 1 == options.iterations)) {
      modules.eval();
      SaveCheckpoint(options.checkpoint_dir, step + 1, avatar, adam);
      modules.train();
    }
  }
  result.seconds = watch.ElapsedSeconds();
  const int steps = options.iterations - result.first_step;
  result.samples_per_s = result.seconds > 0 ? steps * options.batch / result.seconds : 0;
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
