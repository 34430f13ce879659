// Analysis by synthesis through the avatar: offsets on a frame's conditioning
// fitted to that frame's own pixels with the networks frozen.
#pragma once

#include "common/avatar/avatar.h"
#include "common/avatar/avatar_pipeline.h"
#include "training/avatar_fit.h"
#include "training/refine_options.h"

namespace headcast {

// What training's per-frame offsets (METHOD eq. 8) are to the training
// frames, for a frame training never saw: the motion and lighting the
// networks are told move, the mesh, beta and tau do not. One step is a
// forward and backward pass of the whole avatar, so this measures how much
// of a held-out frame's error the conditioning could still take back
// (headcast-bench refine); it is not a sender's per-frame cost.
class ConditioningRefiner {
 public:
  // `avatar` must outlive the refiner; its weights are never changed.
  ConditioningRefiner(Avatar& avatar, const RefineOptions& options);

  // `steps` Adam steps from the current offsets, the networks frozen, on the
  // frame `inputs` were prepared for against `target` ((1, 3, H, W) RGB in
  // [0, 1], the avatar's size). `inputs` is left as it came. Returns the
  // objective before the last step.
  double Refine(AvatarFrameInputs* inputs, const torch::Tensor& target, int steps);
  // `c` with the offsets added (where OffsetMasks allows them).
  AvatarConditioning Offset(const AvatarConditioning& c) const;
  // The offsets back to zero, Adam's moments with them.
  void Reset();
  double OffsetNorm() const;  // Euclidean, geometry and appearance together

 private:
  Avatar& avatar_;
  RefineOptions options_;
  ConditioningMasks masks_;
  torch::Tensor geometry_, appearance_;
  std::unique_ptr<torch::optim::Adam> adam_;
};

}  // namespace headcast
