#include "training/conditioning_refiner.h"

#include <stdexcept>
#include <string>

#include "common/core/options.h"
#include "training/image_losses.h"

namespace headcast {

void RefineOptions::Check() const {
  OptionsCheck c("RefineOptions");
  c.Positive("learning_rate", learning_rate).NonNegative("offset_weight", offset_weight);
  c.NonNegative("ssim_weight", ssim_weight);
  c.That(codes == "all" || codes == "expression" || codes == "joints" || codes == "lighting",
         "codes must be all, expression, joints or lighting, not '" + codes + "'");
  c.ThrowIfErrors();
}

ConditioningRefiner::ConditioningRefiner(Avatar& avatar, const RefineOptions& options)
    : avatar_(avatar), options_(options) {
  options_.Check();
  // A subject's identity is the tracker's and the avatar's: beta and tau stay.
  masks_ = OffsetMasks(avatar.config(), /*freeze_identity=*/true);
  const AvatarConfig& c = avatar.config();
  if (options_.codes != "all") {
    torch::Tensor keep = torch::zeros_like(masks_.geometry);
    if (options_.codes == "expression") keep.narrow(1, c.expression_offset(), c.num_expression).fill_(1);
    if (options_.codes == "joints") keep.narrow(1, c.pose_offset(), c.expression_offset() - c.pose_offset()).fill_(1);
    masks_.geometry = masks_.geometry * keep;
    if (options_.codes != "lighting") masks_.appearance = torch::zeros_like(masks_.appearance);
  }
  Reset();
}

void ConditioningRefiner::Reset() {
  geometry_ = torch::zeros_like(masks_.geometry).requires_grad_(true);
  appearance_ = torch::zeros_like(masks_.appearance).requires_grad_(true);
  adam_ = std::make_unique<torch::optim::Adam>(std::vector<torch::Tensor>{geometry_, appearance_},
                                               torch::optim::AdamOptions(options_.learning_rate));
}

AvatarConditioning ConditioningRefiner::Offset(const AvatarConditioning& c) const {
  return {c.geometry + geometry_ * masks_.geometry, c.appearance + appearance_ * masks_.appearance};
}

double ConditioningRefiner::OffsetNorm() const {
  torch::NoGradGuard no_grad;
  return std::sqrt((geometry_ * masks_.geometry).square().sum().item<double>() +
                   (appearance_ * masks_.appearance).square().sum().item<double>());
}

double ConditioningRefiner::Refine(AvatarFrameInputs* inputs, const torch::Tensor& target, int steps) {
  const int64_t size = avatar_.config().output_size;
  if (target.dim() != 4 || target.size(0) != 1 || target.size(1) != 3 || target.size(2) != size ||
      target.size(3) != size)
    throw std::invalid_argument("ConditioningRefiner: the target must be (1, 3, " + std::to_string(size) + ", " +
                                std::to_string(size) + ") RGB, the avatar's size");
  if (steps < 0) throw std::invalid_argument("ConditioningRefiner: steps must be >= 0");
  AvatarModules& modules = avatar_.modules();
  // The networks frozen for the refinement (no gradients kept for their
  // weights), each weight's own flag back afterwards, whatever happens.
  struct Frozen {
    std::vector<std::pair<torch::Tensor, bool>> flags;
    ~Frozen() {
      for (auto& [p, flag] : flags) p.set_requires_grad(flag);
    }
  } frozen;
  for (torch::Tensor& p : modules.parameters()) {
    frozen.flags.emplace_back(p, p.requires_grad());
    p.set_requires_grad(false);
  }
  const AvatarConditioning told = inputs->conditioning;
  double objective = 0;
  try {
    for (int step = 0; step < steps; ++step) {
      adam_->zero_grad();
      inputs->conditioning = Offset(told);
      const torch::Tensor image = RunAvatar(modules, *inputs).image;
      torch::Tensor loss =
          torch::mse_loss(image, target) + options_.offset_weight * ((geometry_ * masks_.geometry).square().sum() +
                                                                     (appearance_ * masks_.appearance).square().sum());
      if (options_.ssim_weight > 0) loss = loss + options_.ssim_weight * (1 - Ssim(image, target));
      objective = loss.item<double>();
      loss.backward();
      adam_->step();
    }
  } catch (...) {
    inputs->conditioning = told;
    throw;
  }
  inputs->conditioning = told;
  return objective;
}

}  // namespace headcast
