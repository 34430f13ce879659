// A random tiny avatar over the built-in head and the same networks with
// other run-time switches, each drawn through the receiver's render path:
// what a switch changes in the picture, and what it leaves.
#pragma once

#include <memory>

#include "common/avatar/avatar.h"
#include "common/avatar/avatar_pipeline.h"
#include "common/headmodel/builtin_head.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast::testing {

class SwitchedAvatars {
 public:
  // `base` drawn as it is; `switched` its networks under `switches` (run-time switches only).
  SwitchedAvatars(const AvatarConfig& base, const AvatarConfig& switches)
      : model_(std::make_shared<const HeadModel>(MakeBuiltinHead())),
        subject_(DefaultSubject(*model_, base.output_size)),
        identity_(model_->MakeIdentity(subject_.shape.cast<double>())),
        base_(Avatar::CreateRandom(base, *model_, subject_, 3)),
        switched_(base_.WithRuntimeSwitches(switches)) {
    base_.modules().eval();
    switched_.modules().eval();
  }
  std::shared_ptr<const HeadModel> model() const { return model_; }
  Avatar& base() { return base_; }
  Avatar& switched() { return switched_; }
  // `frame` as `avatar` draws it; `buffers` carry what a receiver keeps from frame to frame.
  cv::Mat Draw(Avatar& avatar, AvatarFrameInputs* buffers, const FrameParams& frame) {
    torch::InferenceMode inference;
    RaySampler sampler(avatar.config());
    cv::Mat bgr;
    RenderAvatarFrame(avatar.modules(), avatar.config(), *model_, identity_, avatar.subject(), frame, &sampler, buffers,
                      &bgr);
    return bgr;
  }
  cv::Mat Draw(Avatar& avatar, const FrameParams& frame) {
    AvatarFrameInputs buffers;
    return Draw(avatar, &buffers, frame);
  }

 private:
  std::shared_ptr<const HeadModel> model_;
  SubjectParams subject_;
  HeadIdentity identity_;
  Avatar base_, switched_;
};

inline bool SamePicture(const cv::Mat& a, const cv::Mat& b) { return cv::norm(a, b, cv::NORM_INF) == 0; }

}  // namespace headcast::testing
