#include "sender/frame_outliner.h"

#include "common/headmodel/head_outline.h"

namespace headcast {

FrameOutliner::FrameOutliner(const HeadModel& model, const MatteRules& rules, const HeadMaskOptions& mask)
    : model_(model), rules_(rules), mask_(mask) {
  mask_.Check();
}

std::vector<float> FrameOutliner::Measure(const OutlineJob& job) {
  if (job.face_was_lost) models_ = {};
  if (!identity_ || shape_.size() != job.identity.size() || shape_ != job.identity) {
    identity_ = model_.MakeIdentity(job.identity);
    shape_ = job.identity;
  }
  HeadModelOutput posed;
  model_.Forward(*identity_, job.params.expression.cast<double>(), job.params.HeadPose(), &posed);
  // The outline's rays run from its centre over the upper half of the
  // picture: the mask beneath the centre's row is not looked at.
  const OutlineOptions outline;
  const OutlineFrame frame = OutlineFrame::Of(job.crop.camera, job.params.CamFromHead(), outline);
  const cv::Mat mask = CutFrameMask(job.bgr, job.face, job.crop, model_, posed, job.fitted_in_crop, job.params, rules_,
                                    mask_, &models_, frame.centre_px.y());
  return MeasureOutline(mask, frame, outline);
}

}  // namespace headcast
