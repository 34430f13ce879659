// The differentiable avatar pipeline in libtorch, shared by the receiver's
// AvatarRenderer (inference) and the trainer.
#pragma once

#include "common/avatar/avatar_model.h"
#include "common/avatar/avatar_renderer.h"
#include "common/avatar/ray_sampler.h"

namespace headcast {

// (1, D) conditioning tensors from the subject and one frame's parameters.
AvatarConditioning MakeConditioning(const AvatarConfig& config, const SubjectParams& subject, const FrameParams& frame);

struct AvatarOutput {
  torch::Tensor image;        // (1, 3, H, W) RGB in [0, 1]
  torch::Tensor feature_map;  // (1, F, h, w)
  torch::Tensor opacity;      // (1, 1, h, w)
};

// (1, 3, H, W) RGB in [0, 1] <-> H x W BGR bytes (CV_8UC3); `out` is reused.
void ImageTensorToBgr(const torch::Tensor& image, cv::Mat* out);
torch::Tensor BgrToImageTensor(const cv::Mat& image_bgr);

// Runs CNeRF on the batch's samples, composites the feature map and upsamples it.
AvatarOutput RunAvatar(AvatarModules& modules, const RayBatch& rays, const RigidTransform& cam_from_head,
                       const AvatarConditioning& conditioning, AvatarTimings* timings = nullptr);

}  // namespace headcast
