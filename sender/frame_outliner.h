// The top of the head's outline on a tracked live frame (FrameParams::outline):
// the frame's head mask cut as the avatar's training masks were
// (CutFrameMask), measured as the receiver moves its avatar's edge
// (common/headmodel/head_outline.h). A job holds everything one frame needs,
// so that it can be measured on another thread than the tracker's
// (sender/outline_pipeline.h).
#pragma once

#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "common/avatar/matte.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/tracking/frame_mask.h"

namespace headcast {

struct OutlineJob {
  cv::Mat bgr;                 // the whole frame (owned: the tracker may read the next one meanwhile)
  Landmarks2d face;            // the shape predictor's landmarks, pixels of the frame
  FrameCrop crop;              // the avatar's square in this camera's frames
  Landmarks2d fitted_in_crop;  // the fitted head's landmarks in the crop's camera
  FrameParams params;          // the fit; its outline is what the job fills
  Eigen::VectorXd identity;    // the tracker's shape when it fitted this frame
  bool face_was_lost = false;  // frames without a face came before this one: the colour models start anew
};

class FrameOutliner {
 public:
  // Throws std::invalid_argument naming a mask option out of range.
  FrameOutliner(const HeadModel& model, const MatteRules& rules, const HeadMaskOptions& mask);
  // The job's outline (millimetres, OutlineOptions' bins). Throws
  // std::invalid_argument when its mask cannot be cut (empty frame,
  // non-finite landmarks).
  std::vector<float> Measure(const OutlineJob& job);

 private:
  const HeadModel& model_;
  MatteRules rules_;
  HeadMaskOptions mask_;
  Eigen::VectorXd shape_;  // the identity identity_ was made for
  std::optional<HeadIdentity> identity_;
  // GrabCut's colour models from frame to frame (HeadMaskOptions::refit_every).
  HeadMaskModels models_;
};

}  // namespace headcast
