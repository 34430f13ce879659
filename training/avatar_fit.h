// Fitting an avatar's networks to synthetic head-model renders (the first step
// of pretraining the general model, METHOD §5), and evaluating it.
#pragma once

#include <functional>
#include <vector>

#include "common/avatar/avatar.h"
#include "training/synthetic_data.h"

namespace headcast {

struct FitOptions {
  int iterations = 500;         // optimiser steps
  int batch = 4;                // samples per step (gradients accumulated)
  double learning_rate = 2e-3;  // Adam
  uint64_t seed = 1;            // ray jitter
  // Checkpoints: every `checkpoint_every` steps the weights, the optimiser
  // state and the step go to CHECKPOINT_DIR/step-N/, then CHECKPOINT_DIR/LATEST
  // is switched to it (a rename: a crash or kill -9 loses at most one interval).
  // With `resume`, training continues from LATEST: samples and ray jitter are
  // drawn per step, so the run continues as if never stopped.
  std::string checkpoint_dir;
  int checkpoint_every = 100;
  bool resume = false;
  void Check() const;
};

struct FitResult {
  int first_step = 0;       // where this run started (after a resume)
  std::vector<float> loss;  // per step from first_step, mean over the batch (MSE on RGB in [0, 1])
  double seconds = 0;
  double samples_per_s = 0;
};

// Trains every parameter of `avatar` on samples data.At(step * batch + b);
// `progress(step, loss)` after each step. Throws naming the file when a checkpoint
// to resume from is corrupt or made for another avatar.
FitResult FitOnSynthetic(Avatar& avatar, const HeadModel& model, SyntheticData& data, const FitOptions& options,
                         const std::function<void(int, float)>& progress = nullptr);

struct EvalResult {
  double psnr_mean = 0;  // dB, RGB in [0, 1]
  double mse_mean = 0;
  double ms_median = 0;  // inference per image (network part), ms
  int count = 0;
};

// PSNR of the avatar against held-out samples data.At(first .. first + count).
EvalResult EvaluateOnSynthetic(Avatar& avatar, const HeadModel& model, const SyntheticData& data, int count,
                               uint64_t first = uint64_t{1} << 40);  // far from the training indices

// The avatar's picture (BGR) for a sample's parameters, e.g. beside its ground truth.
cv::Mat RenderSampleBgr(Avatar& avatar, const HeadModel& model, const SyntheticSample& sample);

}  // namespace headcast
