// The options of ConditioningRefiner (training/conditioning_refiner.h), apart
// so that option parsers need not include libtorch.
#pragma once

#include <string>

namespace headcast {

struct RefineOptions {
  double learning_rate = 0.03;  // Adam
  // Sum of squares of the offsets, weighted as training's offset_weight is:
  // a frame's pixels alone can be matched by codes far from any the networks
  // were trained on (the picture then fits the frame as an autoencoder would),
  // which says nothing of what the tracker's parameters miss.
  double offset_weight = 0.01;
  double ssim_weight = 0.1;  // 1 - SSIM beside the MSE, as in training
  // Which codes take offsets: "all" (the motion and lighting codes), or only
  // "expression" (the coefficients), "joints" (neck, jaw, eyes) or "lighting".
  std::string codes = "all";
  void Check() const;
};

}  // namespace headcast
