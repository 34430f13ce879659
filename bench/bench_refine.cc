// Benchmark suite "refine": how much of an avatar's error on a dataset's
// held-out frames the conditioning could still take back. Offsets on each
// frame's conditioning are fitted to its own pixels through the avatar, the
// networks frozen (ConditioningRefiner), in two schedules:
//  - per frame: every `every`-th held-out frame alone, `iterations` steps
//    from zero offsets (an upper bound for what the tracker's motion and
//    lighting codes miss, at that offset weight);
//  - causal: the held-out frames in order, the running offsets refined on
//    every `causal_every`-th frame for `causal_iterations` steps, each frame
//    scored with the offsets as they were before it (what a sender refining
//    in the background, behind the frames it sends, could give); with
//    `causal_until` only the first frames are refined on and the offsets then
//    kept (a calibration at the start of a call), and the frames after that
//    window are scored apart too.
// Scored as evaluation scores (the picture as the receiver shows it, its skin
// colour matched to the frame's, against the masked target), before and
// after in the same run.
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "bench/bench.h"
#include "common/avatar/compute_threads.h"
#include "common/core/image_io.h"
#include "common/headmodel/head_model_io.h"
#include "training/conditioning_refiner.h"
#include "training/dataset.h"
#include "training/image_losses.h"

namespace headcast::bench {
namespace {

struct Scores {
  double psnr = 0, ssim = 0, mse = 0, last_psnr = 0;
  int count = 0;
  void Add(const torch::Tensor& image, const torch::Tensor& target) {
    const ImageScore s = ScoreImage(image, target);
    last_psnr = s.psnr;
    psnr += s.psnr;
    ssim += s.ssim;
    mse += s.mse;
    ++count;
  }
  nlohmann::json ToJson() const {
    return {{"psnr_db", psnr / count}, {"ssim", ssim / count}, {"psnr_of_mean_mse_db", PsnrOfMse(mse / count)}};
  }
};

// The `n` largest motion offsets (at most the nonzero ones), by name where
// the head model names its expression coefficients (the joints as neck, jaw,
// left_eye, right_eye axes). Beta takes none (OffsetMasks), so only the motion
// part of the conditioning is searched.
nlohmann::json LargestOffsets(const ConditioningRefiner& refiner, const AvatarConfig& config, const HeadModel& model,
                              int n) {
  torch::NoGradGuard no_grad;
  const torch::Tensor zero = torch::zeros({1, config.conditioning_dim()});
  const torch::Tensor motion = refiner.Offset({zero, torch::zeros({1, config.appearance_dim()})})
                                   .geometry[0]
                                   .narrow(0, config.pose_offset(), config.motion_dim());
  const torch::Tensor order = std::get<1>(motion.abs().topk(std::min<int64_t>(n, motion.size(0))));
  static const char* joints[] = {"neck", "jaw", "left_eye", "right_eye"};
  const std::vector<std::string>& names = model.data().expression_names;
  nlohmann::json out = nlohmann::json::array();
  for (int64_t j = 0; j < order.size(0); ++j) {
    const int p = order[j].item<int>(), e = p - (config.expression_offset() - config.pose_offset());
    const double value = motion[p].item<double>();
    if (value == 0) break;  // sorted by size: the rest are zero too
    const std::string name = e >= 0 ? (e < static_cast<int>(names.size()) ? names[e] : "psi" + std::to_string(e))
                                    : std::string(joints[p / 3]) + "_" + "xyz"[p % 3];
    out.push_back({name, value});
  }
  return out;
}

}  // namespace

void RefineBenchOptions::Check() const {
  OptionsCheck c("RefineBenchOptions");
  c.NotEmpty("avatar", avatar).NotEmpty("dataset", dataset);
  c.InRange("every", every, 1, 100000).InRange("iterations", iterations, 0, 100000);
  c.That(refine_size == 0 || (refine_size >= 64 && refine_size % 32 == 0),
         "refine_size must be 0 or a multiple of 32 from 64");
  c.InRange("causal_every", causal_every, 1, 100000).InRange("causal_iterations", causal_iterations, 0, 100000);
  c.InRange("causal_until", causal_until, 0, 100000);
  c.ThrowIfErrors();
  refine.Check();
}

nlohmann::json RunRefineSuite(const BenchOptions& o) {
  const RefineBenchOptions& r = o.refine;
  r.Check();
  if (!r.frames_dir.empty()) {
    std::filesystem::create_directories(r.frames_dir + "/before");
    std::filesystem::create_directories(r.frames_dir + "/after");
  }
  SetComputeThreads(o.threads);
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  Avatar avatar = Avatar::Load(r.avatar, model);
  const AvatarConfig& config = avatar.config();
  const PreparedDataset data = PreparedDataset::Load(r.dataset, model, config.output_size, /*interpolated=*/false);
  if (data.test().empty()) throw std::invalid_argument(r.dataset + ": the dataset has no held-out frames");
  // The dataset's person and camera, as evaluation draws its frames.
  const SubjectParams& subject = data.subject();
  const HeadIdentity identity = model.MakeIdentity(subject.shape.cast<double>());
  RaySampler sampler(config);
  // The refinement may draw a smaller picture than the one scored (a step
  // costs about the picture's area); its offsets are then applied to the
  // avatar's own size.
  std::optional<Avatar> small;
  if (r.refine_size > 0 && r.refine_size != config.output_size) {
    AvatarConfig c = config;
    c.output_size = r.refine_size;
    small = avatar.WithRuntimeSwitches(c);
  }
  Avatar& fitted = small ? *small : avatar;
  SubjectParams fit_subject = subject;
  fit_subject.intrinsics = subject.intrinsics.Resized(fitted.config().output_size, fitted.config().output_size);
  RaySampler fit_sampler(fitted.config());
  ConditioningRefiner refiner(fitted, r.refine);
  auto prepare = [&](int position, AvatarFrameInputs* in) {
    const RealSample& s = data.At(position);
    PrepareAvatarFrame(config, model, identity, subject, s.params, &sampler, nullptr, in);
    return MaskedTarget(s.image_bgr, s.mask);
  };
  // The frame and its target at the refinement's size.
  auto prepare_fit = [&](int position, const cv::Mat& target_bgr, AvatarFrameInputs* in) {
    PrepareAvatarFrame(fitted.config(), model, identity, fit_subject, data.At(position).params, &fit_sampler, nullptr,
                       in);
    if (!small) return BgrToImageTensor(target_bgr);
    cv::Mat resized;
    cv::resize(target_bgr, resized, {r.refine_size, r.refine_size}, 0, 0, cv::INTER_AREA);
    return BgrToImageTensor(resized);
  };
  // The picture as the receiver shows it (RenderAvatarFrame): 8-bit, its
  // skin colour matched to the frame's when the frame carries one.
  auto shown = [&](int position, const AvatarFrameInputs& in, bool offset) {
    torch::NoGradGuard no_grad;
    AvatarFrameInputs drawn = in;
    if (offset) drawn.conditioning = refiner.Offset(in.conditioning);
    const AvatarOutput out = RunAvatar(avatar.modules(), drawn);
    cv::Mat bgr;
    ImageTensorToBgr(out.image, &bgr);
    const std::optional<Eigen::Vector3f>& skin = data.At(position).params.skin_colour;
    if (skin) MatchSkinColour(out, *skin, ProjectLandmarks(in.posed, in.cam_from_head, subject.intrinsics), &bgr);
    return BgrToImageTensor(bgr);
  };
  nlohmann::json out = {{"suite", "refine"},
                        {"avatar", r.avatar},
                        {"dataset", r.dataset},
                        {"held_out_frames", data.test().size()},
                        {"learning_rate", r.refine.learning_rate},
                        {"offset_weight", r.refine.offset_weight},
                        {"ssim_weight", r.refine.ssim_weight},
                        {"codes", r.refine.codes},
                        {"output_size", config.output_size},
                        {"refine_size", fitted.config().output_size}};
  // Per frame.
  {
    Scores before, after;
    SampleStats step_ms;
    nlohmann::json frames = nlohmann::json::array();
    double norms = 0;
    for (size_t k = 0; k < data.test().size(); k += r.every) {
      const int position = data.test()[k];
      AvatarFrameInputs in, fit;
      const cv::Mat target_bgr = prepare(position, &in);
      const torch::Tensor target = BgrToImageTensor(target_bgr), fit_target = prepare_fit(position, target_bgr, &fit);
      refiner.Reset();
      const torch::Tensor drawn_before = shown(position, in, false);
      before.Add(drawn_before, target);
      Stopwatch watch;
      refiner.Refine(&fit, fit_target, r.iterations);
      if (r.iterations > 0) step_ms.Add(watch.ElapsedMs() / r.iterations);
      const torch::Tensor drawn_after = shown(position, in, true);
      after.Add(drawn_after, target);
      if (!r.frames_dir.empty()) {
        // As headcast-train eval --write-frames lays them out, for bench/outline_error.py and its kin.
        char name[32];
        std::snprintf(name, sizeof name, "_%05zu.png", k);
        for (const auto& [folder, drawn] : {std::pair{"/before/", drawn_before}, std::pair{"/after/", drawn_after}}) {
          cv::Mat bgr;
          ImageTensorToBgr(drawn, &bgr);
          WriteImage(r.frames_dir + folder + "avatar" + name, bgr);
          WriteImage(r.frames_dir + folder + "truth" + name, target_bgr);
        }
      }
      norms += refiner.OffsetNorm();
      frames.push_back({{"held_out_index", k},
                        {"dataset_frame", position},
                        {"psnr_before_db", before.last_psnr},
                        {"psnr_after_db", after.last_psnr},
                        {"largest_offsets", LargestOffsets(refiner, config, model, 6)}});
    }
    out["per_frame"] = {{"frames", before.count},
                        {"every", r.every},
                        {"iterations", r.iterations},
                        {"before", before.ToJson()},
                        {"after", after.ToJson()},
                        {"offset_norm_mean", norms / before.count},
                        {"ms_per_step_median", step_ms.count() > 0 ? step_ms.Median() : 0.0},
                        {"frames_refined", frames}};
  }
  // Causal.
  {
    Scores before, after, later_before, later_after;  // later: the frames past the calibration window
    refiner.Reset();
    double norms = 0;
    const size_t until = r.causal_until > 0 ? static_cast<size_t>(r.causal_until) : data.test().size();
    for (size_t k = 0; k < data.test().size(); ++k) {
      const int position = data.test()[k];
      AvatarFrameInputs in;
      const cv::Mat target_bgr = prepare(position, &in);
      const torch::Tensor target = BgrToImageTensor(target_bgr), drawn_before = shown(position, in, false),
                          drawn_after = shown(position, in, true);
      before.Add(drawn_before, target);
      after.Add(drawn_after, target);
      if (k >= until) {
        later_before.Add(drawn_before, target);
        later_after.Add(drawn_after, target);
      }
      norms += refiner.OffsetNorm();
      if (k < until && k % r.causal_every == 0) {
        AvatarFrameInputs fit;
        const torch::Tensor fit_target = prepare_fit(position, target_bgr, &fit);
        refiner.Refine(&fit, fit_target, r.causal_iterations);
      }
    }
    out["causal"] = {{"frames", before.count},
                     {"every", r.causal_every},
                     {"iterations", r.causal_iterations},
                     {"steps_per_frame", static_cast<double>(r.causal_iterations) / r.causal_every},
                     {"until", r.causal_until},
                     {"before", before.ToJson()},
                     {"after", after.ToJson()},
                     {"offset_norm_mean", norms / before.count},
                     {"largest_offsets_at_the_end", LargestOffsets(refiner, config, model, 8)}};
    if (later_before.count > 0)
      out["causal"]["after_the_window"] = {
          {"frames", later_before.count}, {"before", later_before.ToJson()}, {"after", later_after.ToJson()}};
  }
  out["threads"] = o.threads;
  return out;
}

}  // namespace headcast::bench
