// The top of the head's outline on tracked live frames (FrameParams::outline):
// each frame's head mask cut as the avatar's training masks were
// (CropGrabCutMask, CutCropMask), measured as the receiver moves its avatar's edge
// (common/headmodel/head_outline.h).
//
// The mask's GrabCut needs only the frame and its landmarks, so it runs on a
// worker thread while the tracker fits the head (Start, then Finish after the
// fit): the frame's parameters leave a few milliseconds after its fit rather
// than a GrabCut later. Its colour models are carried from frame to frame and
// learnt anew every HeadMaskOptions::refit_every frames on a second, lower-
// priority thread (the models alone, LearnHeadMaskModels), so that no frame
// waits for the learning.
#pragma once

#include <condition_variable>
#include <mutex>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/avatar/matte.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/tracking/frame_mask.h"

namespace headcast {

class FrameOutliner {
 public:
  // `crop`: the avatar's square in the frames; `beside_fit` false: everything
  // on the caller's thread in Finish, the models learnt on the frames that
  // are due (as prep's HeadMask). Throws std::invalid_argument naming a mask
  // option out of range.
  FrameOutliner(const HeadModel& model, const FrameCrop& crop, const MatteRules& rules, const HeadMaskOptions& mask,
                bool beside_fit = true);
  ~FrameOutliner();
  FrameOutliner(const FrameOutliner&) = delete;
  FrameOutliner& operator=(const FrameOutliner&) = delete;

  // A frame whose face was found: its head mask is cut from here on. `bgr`
  // must stay unchanged until Finish or Abandon.
  void Start(const cv::Mat& bgr, const Landmarks2d& face);
  // The started frame's outline, once fitted (`fitted_in_crop`: the fitted
  // head's landmarks in the crop's camera; `identity`: the tracker's shape).
  // Throws std::invalid_argument when its mask could not be cut (the frame
  // then goes without an outline; the next ones are not affected).
  std::vector<float> Finish(const FrameParams& params, const Landmarks2d& fitted_in_crop,
                            const Eigen::VectorXd& identity);
  // The started frame was not fitted: its cut is dropped.
  void Abandon();
  // The face was lost: the next face learns its own colour models.
  void Forget();

 private:
  cv::Mat Cut(const cv::Mat& bgr, const Landmarks2d& face, double wanted_above_y);  // the crop's GrabCut mask
  void CutLoop();
  void LearnLoop();
  cv::Mat WaitForCut();  // rethrows the cut's error

  const HeadModel& model_;
  const FrameCrop crop_;
  const MatteRules rules_;
  const HeadMaskOptions mask_;
  const HeadMaskOptions frozen_;  // mask_ for a cut with the carried models only
  const bool beside_fit_;
  Eigen::VectorXd shape_;  // the identity identity_ was made for
  std::optional<HeadIdentity> identity_;
  double centre_row_ = -1;  // the last outline's centre in the crop (< 0: none): the rows the next cut needs

  // The frame being cut (Start to Finish; kept until the next Start).
  cv::Mat bgr_;
  Landmarks2d face_{};
  bool started_ = false;

  std::mutex mutex_;
  std::condition_variable changed_;
  bool stop_ = false;
  bool cut_asked_ = false, cut_done_ = false;
  cv::Mat cut_;
  std::string cut_error_;
  HeadMaskModels models_;   // carried; replaced by the learner
  int models_version_ = 0;  // bumped when models_ is replaced
  // The cutting thread's copy of models_ and the last mask cut with them
  // (HeadMaskOptions::band); remade when models_version_ moves on.
  HeadMaskModels cutting_;
  int cutting_version_ = 0;
  int generation_ = 0;  // bumped by Forget: a learning from before is dropped
  int frames_since_learnt_ = 0;
  cv::Mat learn_bgr_;  // a frame for the learner (empty: none asked)
  Landmarks2d learn_face_{};
  int learn_generation_ = 0;
  bool learning_ = false;
  std::thread cutter_, learner_;
};

}  // namespace headcast
