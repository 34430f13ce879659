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
  void Check() const;
};

struct FitResult {
  std::vector<float> loss;  // per step, mean over the batch (MSE on RGB in [0, 1])
  double seconds = 0;
  double samples_per_s = 0;
};

// Trains every parameter of `avatar` on samples from `data`; `progress(step, loss)` after each step.
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
                               uint64_t first = 1000000);

// The avatar's picture (BGR) for a sample's parameters, e.g. beside its ground truth.
cv::Mat RenderSampleBgr(Avatar& avatar, const HeadModel& model, const SyntheticSample& sample);

}  // namespace headcast
