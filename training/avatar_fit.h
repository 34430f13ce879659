// Training an avatar's networks (METHOD §4–§6): synthetic head-model renders
// made on the fly mixed with real frames of prepared datasets by the p(n)
// schedule of METHOD eq. 9; masked MSE + an SSIM or VGG16 perceptual term +
// learnable per-frame offsets on real samples; z-augmentation; Adam;
// checkpoints and resume. Evaluation on held-out synthetic samples or a test split.
#pragma once

#include <functional>
#include <vector>

#include "common/avatar/avatar.h"
#include "common/headmodel/head_outline.h"
#include "training/data_parallel.h"
#include "training/dataset.h"
#include "training/expression_balance.h"
#include "training/face_regions.h"
#include "training/synthetic_data.h"

namespace headcast {

// METHOD eq. 9: the probability that step n trains on a synthetic sample.
// 1 up to step m; then falls linearly from p_max at m to p_min at n_end.
// A subject fine-tune uses m = 0, n_end = iterations, p_min = 0 (decay to 0).
struct MixSchedule {
  int m = 0;
  int n_end = 1;
  double p_min = 0, p_max = 0.25;
  double SyntheticProbability(int step) const;
  void Check() const;
};

struct LossOptions {
  double mse_weight = 1;  // masked MSE (background replaced by the renders' background colour)
  // The perceptual term: VGG16 features from a TorchScript file when given,
  // otherwise 1 - SSIM as the substitute (the report says which).
  std::string vgg_path;
  double perceptual_weight = 0.1;
  double ssim_weight = 0.1;
  // With a matte: weight of the coverage's binary cross-entropy against the
  // target's mask, which teaches the outline where the head's colours are
  // close to the background's (dark hair) and the MSE says little.
  double matte_weight = 0.02;
  // sum_k w ||offset_k||^2 over the learnable per-frame offsets of real samples
  // (METHOD eq. 8); 0 on synthetic ones, which have exact parameters.
  double offset_weight = 1.0;
  // w |shift|^2 (pixels) of a real frame's learnt shift (FitOptions::frame_shift_rate).
  double frame_shift_weight = 1e-4;
  // The MSE weighted up around the fitted eyes, brows and mouth (their
  // projected landmarks): where expressions are read; weight 0: off.
  FaceRegionOptions regions;
  // Synthetic renders (the head model painted with the subject's texture)
  // teach the outline, hair and poses the video lacks, but their eyes and
  // mouth are painted: no real lids, irises or teeth. When set, their target
  // inside the same regions is the avatar's own output, so those regions
  // learn (up to the windowed terms' edges) from real frames only.
  bool blind_synthetic_face = false;
  void Check() const;
};

struct FitOptions {
  int iterations = 500;         // optimiser steps
  int batch = 4;                // samples per step (gradients accumulated)
  double learning_rate = 2e-3;  // Adam, at the first step
  // The rate may fall exponentially to learning_rate * final_lr_fraction at
  // the last step (NeRF's schedule), a function of the step alone, so a
  // resumed run continues on the same curve. Constant by default: on
  // talking_d9 (256², 2000 steps) a fall to 0.1 gave 24.73 dB against 24.97
  // constant — the fine-tune is still underfitting when it ends.
  double final_lr_fraction = 1;
  // The rate rises linearly over the first warmup_steps steps, from
  // 1/warmup_steps of the schedule's to all of it: Adam's moment estimates
  // start from one batch, and a fine-tune at 4e-3 diverged within its
  // first 60 steps without a warm-up (bench/DEFAULTS.md). 0: none.
  int warmup_steps = 0;
  double LearningRateAt(int step) const;
  // The surface texture's rate over the networks' (its texels each see a
  // small part of every picture; bench/DEFAULTS.md has the measurement).
  double surface_lr_scale = 20;
  // The texture's expression blendshapes' rate over the networks' (AvatarConfig::
  // surface_blend), a knob of its own: each blendshape is fitted to what differs
  // between frames, noise included, and a combination of coefficients no
  // training frame had adds up what each learnt, so a lower rate is the first
  // thing to try against that (bench/results/fidelity_ablation.md: 1 was no
  // better than the texture's 20).
  double blend_lr_scale = 20;
  // The per-frame offsets' rate over the networks' (their own group only
  // when not 1, so checkpoints from before resume). A fine-tune visits each
  // training frame about two dozen times, and Adam moves each offset by about
  // the rate at every visit whatever its gradient's size: at 1 the offsets
  // end as a per-frame jitter of that many steps (bench/results/fidelity_ablation.md).
  double offset_lr_scale = 1;
  // Consecutive real training frames (by position in their dataset) that
  // share one offset row, and one shift: meant for a slow drift of the
  // picture against the fit (the hair settling, the light changing over the
  // clip), which offsets visited many times could learn where a frame's own
  // offset is visited too few times to learn anything but Adam's jitter. On
  // the four clips they found none (bench/results/fidelity_ablation.md), so
  // the default is 1: per frame.
  int offset_segment = 1;
  // Each real training frame's picture may be moved by a learnt shift of its
  // own (pixels, x and y) before the loss: the fit places the head a pixel or
  // two off the picture in many frames, and networks made to draw every frame
  // where its fit says learn a blur of the misplaced detail, or tie the
  // misplacement to the frame's codes. The shifts take it instead; the
  // receiver draws with none. Their rate in pixels a step at the schedule's
  // peak (warm-up and fall as the networks'). 0: off.
  double frame_shift_rate = 0;
  // With AvatarConfig::motion_blur: the exposure's rate (frame intervals a
  // step at the schedule's peak); it starts at the configuration's value and
  // the avatar keeps what it learns.
  double exposure_rate = 1e-3;
  // Decoupled weight decay of the blendshapes alone (AdamW's: each step shrinks
  // them by rate * blend_decay, rate being theirs): a blendshape the frames do
  // not keep pushing the same way fades, so one fitted to noise or to what
  // another coefficient cancels on the training frames does not add up on a
  // combination no frame had. 0: off.
  double blend_decay = 0;
  // Polyak averaging: with a decay d in (0, 1) the run keeps an exponential
  // moving average of the weights (decay min(d, (1 + n) / (10 + n)) at step n,
  // so the start weights fade out early); the avatar holds the average in the
  // progress callback and at the end (checkpoints keep both, to resume
  // exactly). A constant rate's step-to-step noise averages out without
  // slowing the learning the way a falling rate does. 0: off.
  double weight_average = 0;
  double WeightAverageDecayAt(int step) const;
  uint64_t seed = 1;  // ray jitter, mixing, augmentation
  LossOptions loss;
  MixSchedule mix;               // used when both synthetic and real data are given
  bool learn_offsets = true;     // per-frame offsets on beta, theta, psi, tau, lambda of real frames
  bool freeze_identity = false;  // subject fine-tune: no offsets on beta and tau (frozen, METHOD §6)
  // Per-frame offsets on beta as the networks are told it even with
  // freeze_identity (the mesh's beta stays the subject's): a code of each
  // training frame's own that the networks read as they read a person's
  // shape, where what no code explains (the hair's outline as it fell, a
  // mask's error) can go instead of into the expression's; the receiver
  // tells them the subject's beta, the frames' average.
  bool identity_offsets = false;
  // Standard deviation of Gaussian noise added to a real frame's expression
  // coefficients as the networks see them (not to the mesh): a few hundred
  // frames span few of psi's combinations, and an avatar that keys detail to
  // exact ones draws unseen expressions badly. 0: off.
  double expression_noise = 0;
  // A pull of the networks' weights back toward those training started from
  // (the general model, for a fine-tune), applied after each step as
  // w -= rate x anchor_weight x (w - w0) (decoupled, as AdamW's decay is toward
  // zero): a few hundred frames then move the networks only as far as they must,
  // and an unseen expression is answered more as the general model answers it.
  // The surface texture (new to the fine-tune) and the offsets are not pulled. 0: off.
  double anchor_weight = 0;
  // Real training frames are drawn by how rare their expression is among
  // them (RareExpressionWeights); strength 0: uniformly.
  RareExpressionOptions rare_expressions;
  int freeze_cnerf_layers = 0;  // CNeRF layers not trained (METHOD §6 freezes 4; SubjectOptions::freeze_layers)
  // z-augmentation of real frames (METHOD §5): with this probability the head's
  // distance is changed by a factor drawn in [1/z_scale_max, 1/z_scale_min]
  // (the picture scaled about the head's centre, the translation with it).
  double z_augmentation = 0.5;
  double z_scale_min = 0.8, z_scale_max = 1.25;
  // Roll augmentation of real frames: with this probability the camera is
  // turned about its optical axis by an angle drawn in +-roll_max_degrees
  // (TurnCamera). A short video holds the head upright within a few degrees;
  // a head tilted further is a picture the 2D renderer never saw.
  double roll_augmentation = 0;
  double roll_max_degrees = 10;
  // Checkpoints: every `checkpoint_every` steps the weights, the optimiser
  // state, the offsets and the step go to CHECKPOINT_DIR/step-N/, then
  // CHECKPOINT_DIR/LATEST is switched to it (a rename: a crash or kill -9 loses
  // at most one interval). With `resume`, training continues from LATEST:
  // samples and random draws are made per step, so the run continues as if never stopped.
  std::string checkpoint_dir;
  int checkpoint_every = 100;
  bool resume = false;
  // Data parallel: the batch is shared out over the ranks (sample b on rank
  // b mod world_size); each sample's random draws depend only on (seed, step,
  // b), so any number of ranks trains exactly what one process would. Rank 0
  // writes the checkpoints; every rank resumes from the same folder.
  DistributedOptions distributed;
  int threads = 0;  // libtorch intra-op threads of this process (0: libtorch's choice)
  void Check() const;
};

// A fine-tune's default weight_average: an average over about the last eighth
// of the run (1 - 8/iterations, at most 0.999; off below 9 steps); what it
// gained is in bench/DEFAULTS.md.
double SubjectWeightAverage(int iterations);

// Where samples come from: synthetic renders, real frames, or both.
struct TrainingData {
  const SyntheticData* synthetic = nullptr;
  // The train() frames of every dataset, each with its own subject (beta,
  // tau, camera): several people teach networks that are then fine-tuned to
  // another. Drawn over their union, so a longer video gets more draws.
  std::vector<const PreparedDataset*> real;
};

struct StepInfo {
  int step = 0;
  float loss = 0;     // the whole objective, mean over the batch
  float mse = 0;      // the masked MSE part (RGB in [0, 1])
  int synthetic = 0;  // samples of the batch that were synthetic
};

struct TrainResult {
  int first_step = 0;  // where this run started (after a resume)
  std::vector<StepInfo> steps;
  std::string perceptual;  // "vgg16 PATH" or "ssim"
  // The real frames' learnt offsets (where OffsetMasks allows them) averaged
  // over the frames, conditioning_dim() and appearance_dim() values; empty
  // without offsets. `offset_rms`: their root mean square about that mean.
  std::vector<float> mean_offset_geometry, mean_offset_appearance;
  double offset_rms = 0;
  // With frame shifts: their mean (pixels, x and y) and root mean square
  // length about it over the training frames.
  double frame_shift_mean[2] = {0, 0};
  double frame_shift_rms = 0;
  // With motion blur: the exposure learnt (frame intervals); -1 without.
  double exposure = -1;
  double seconds = 0;
  double samples_per_s = 0;
};

// With AvatarConfig::surface_blend_components: sets the texture's blendshape
// directions to the principal directions of `data`'s training frames'
// expressions (resized to the avatar's coefficients) and returns the fraction
// of their variance those hold; otherwise does nothing and returns 0.
double SetBlendDirections(Avatar& avatar, const PreparedDataset& data);

// Trains `avatar` (every parameter not frozen). `progress(info)` after each
// step, with the avatar in its state after the step. Throws naming the file
// when a checkpoint to resume from is corrupt or made for another avatar, and
// for blendshapes over principal directions whose directions are unset.
TrainResult TrainAvatar(Avatar& avatar, const HeadModel& model, const TrainingData& data, const FitOptions& options,
                        const std::function<void(const StepInfo&)>& progress = nullptr);

// Synthetic only (the first stage of pretraining, benchmarks, tests).
TrainResult FitOnSynthetic(Avatar& avatar, const HeadModel& model, SyntheticData& data, const FitOptions& options,
                           const std::function<void(const StepInfo&)>& progress = nullptr);

struct EvalResult {
  double psnr_mean = 0;  // dB, RGB in [0, 1]
  double ssim_mean = 0;
  double mse_mean = 0;
  double ms_median = 0;  // inference per image (network part), ms
  int count = 0;
  std::vector<double> psnr, ssim;  // per image
};

// PSNR/SSIM of the avatar against held-out samples data.At(first .. first + count).
EvalResult EvaluateOnSynthetic(Avatar& avatar, const HeadModel& model, const SyntheticData& data, int count,
                               uint64_t first = uint64_t{1} << 40);  // far from the training indices

// PSNR/SSIM on dataset frames (positions; default its test split), the
// ground truth with its background replaced as in training. `render(i, avatar_bgr)` per frame if given.
// `skin_colour` false: the frames' skin colours are left out (the avatar's own colours, as a sender without them).
// With `outline`, each frame carries the top of its mask's outline measured so
// (FrameParams::outline: what a sender that cut the same mask would send);
// with `outline_every` N > 1 only every Nth frame is measured and the others
// carry the last measurement (a sender that measures at a lower rate).
EvalResult EvaluateOnDataset(Avatar& avatar, const HeadModel& model, const PreparedDataset& data,
                             const std::vector<int>& positions,
                             const std::function<void(int, const cv::Mat&, const cv::Mat&)>& render = nullptr,
                             bool skin_colour = true, const OutlineOptions* outline = nullptr, int outline_every = 1);

// PSNR/SSIM of the avatar rendered for `frames` (as the receiver shows them)
// against `target(k)` (BGR, the avatar's size; an empty Mat skips frame k).
// `each(k, target, avatar_bgr)` per scored frame if given.
EvalResult EvaluateOnFrames(Avatar& avatar, const HeadModel& model, const SubjectParams& subject,
                            const std::vector<FrameParams>& frames, const std::function<cv::Mat(int)>& target,
                            const std::function<void(int, const cv::Mat&, const cv::Mat&)>& each = nullptr);

// Where a frame's conditioning may take an offset (1 where it may, 0 where
// not), as (1, D) rows beside AvatarConditioning's: beta and tau stay the
// subject's when `freeze_identity`, and nothing the networks are not told
// (AvatarConfig::motion_conditioning) takes one either.
struct ConditioningMasks {
  torch::Tensor geometry, appearance;
};
ConditioningMasks OffsetMasks(const AvatarConfig& config, bool freeze_identity);

// `v` truncated or padded with zeros to `n` values (parameters of another count).
Eigen::VectorXf Resized(const Eigen::VectorXf& v, int n);

// The avatar's picture (BGR) for a subject and frame, e.g. beside its ground truth.
cv::Mat RenderAvatarBgr(Avatar& avatar, const HeadModel& model, const SubjectParams& subject, const FrameParams& frame);

// The frame as a camera turned by `angle` (radians) about its optical axis
// would see it: the image and mask (CV_8U) turned about the principal point,
// cam_from_head turned with them. Exact for a pinhole camera (no depth is
// needed); what comes in at the corners is background.
void TurnCamera(double angle, const PinholeCamera& camera, FrameParams* frame, cv::Mat* image, cv::Mat* mask);

// A real frame's target: the masked image on the renders' background colour (BGR).
cv::Mat MaskedTarget(const cv::Mat& image_bgr, const cv::Mat& mask);

}  // namespace headcast
