#include "sender/frame_outliner.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <stdexcept>

#include "common/headmodel/head_outline.h"

namespace headcast {

FrameOutliner::FrameOutliner(const HeadModel& model, const FrameCrop& crop, const MatteRules& rules,
                             const HeadMaskOptions& mask, bool beside_fit)
    : model_(model),
      crop_(crop),
      rules_(rules),
      mask_(mask),
      frozen_([&] {
        HeadMaskOptions o = mask;
        o.refit_every = 1000;  // the learner refits the models
        return o;
      }()),
      beside_fit_(beside_fit) {
  mask_.Check();
  if (!beside_fit_) return;
  cutter_ = std::thread([this] { CutLoop(); });
  if (mask_.refit_every > 1) learner_ = std::thread([this] { LearnLoop(); });
}

FrameOutliner::~FrameOutliner() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (cutter_.joinable()) cutter_.join();
  if (learner_.joinable()) learner_.join();
}

void FrameOutliner::Start(const cv::Mat& bgr, const Landmarks2d& face) {
  Abandon();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    bgr_ = bgr;
    face_ = face;
    started_ = true;
    cut_asked_ = beside_fit_;
    cut_done_ = false;
  }
  changed_.notify_all();
}

cv::Mat FrameOutliner::WaitForCut() {
  if (!beside_fit_) return Cut(bgr_, face_, centre_row_);
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return cut_done_; });
  cut_done_ = false;
  const cv::Mat cut = std::move(cut_);
  cut_ = cv::Mat();
  if (!cut_error_.empty()) throw std::invalid_argument(cut_error_);
  return cut;
}

std::vector<float> FrameOutliner::Finish(const FrameParams& params, const Landmarks2d& fitted_in_crop,
                                         const Eigen::VectorXd& identity) {
  if (!started_) throw std::logic_error("FrameOutliner::Finish without Start");
  started_ = false;
  const cv::Mat grabcut = WaitForCut();
  if (!identity_ || shape_.size() != identity.size() || shape_ != identity) {
    identity_ = model_.MakeIdentity(identity);
    shape_ = identity;
  }
  HeadModelOutput posed;
  model_.Forward(*identity_, params.expression.cast<double>(), params.HeadPose(), &posed);
  const OutlineOptions outline;
  const OutlineFrame frame = OutlineFrame::Of(crop_.camera, params.CamFromHead(), outline);
  centre_row_ = frame.centre_px.y();
  const cv::Mat mask = CutCropMask(grabcut, model_, posed, fitted_in_crop, params, crop_.camera, rules_);
  return MeasureOutline(mask, frame, outline);
}

void FrameOutliner::Abandon() {
  if (!started_) return;
  started_ = false;
  if (beside_fit_) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] { return cut_done_; });
    cut_done_ = false;
    cut_ = cv::Mat();
  }
}

void FrameOutliner::Forget() {
  Abandon();
  std::lock_guard<std::mutex> lock(mutex_);
  models_ = {};
  ++models_version_;
  ++generation_;
  frames_since_learnt_ = 0;
  learn_bgr_ = cv::Mat();
  centre_row_ = -1;
}

cv::Mat FrameOutliner::Cut(const cv::Mat& bgr, const Landmarks2d& face, double centre_row) {
  // The outline's rays run from its centre over the upper half of the
  // picture: the mask beneath the centre's row (the last frame's; the head
  // moves little in a frame) is not looked at.
  const double wanted_above_y = centre_row >= 0 ? centre_row : HUGE_VAL;
  if (!beside_fit_) return CropGrabCutMask(bgr, face, crop_, mask_, &models_, wanted_above_y);
  if (mask_.refit_every == 1) return CropGrabCutMask(bgr, face, crop_, mask_);  // every frame learns its own
  int generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    generation = generation_;
    if (cutting_version_ != models_version_) {  // new models: this frame is cut whole, not near the last outline
      cutting_ = {models_.background.clone(), models_.foreground.clone(), 0, {}, {}};
      cutting_version_ = models_version_;
    }
  }
  if (cutting_.background.empty()) {  // the first frame of a face learns its models here
    const cv::Mat grabcut = CropGrabCutMask(bgr, face, crop_, mask_, &cutting_);
    std::lock_guard<std::mutex> lock(mutex_);
    if (generation == generation_) {
      models_ = {cutting_.background, cutting_.foreground, 0, {}, {}};
      cutting_version_ = ++models_version_;
      frames_since_learnt_ = 0;
    }
    return grabcut;
  }
  cutting_.frames_since_fit = 0;  // the learner refits them
  const cv::Mat grabcut = CropGrabCutMask(bgr, face, crop_, frozen_, &cutting_, wanted_above_y);
  bool ask = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (generation == generation_ && ++frames_since_learnt_ >= mask_.refit_every && !learning_ && learn_bgr_.empty()) {
      learn_bgr_ = bgr.clone();
      learn_face_ = face;
      learn_generation_ = generation_;
      frames_since_learnt_ = 0;
      ask = true;
    }
  }
  if (ask) changed_.notify_all();
  return grabcut;
}

void FrameOutliner::CutLoop() {
  for (;;) {
    cv::Mat bgr;
    Landmarks2d face;
    double centre_row = -1;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || cut_asked_; });
      if (stop_) return;
      cut_asked_ = false;
      bgr = bgr_;
      face = face_;
      centre_row = centre_row_;
    }
    cv::Mat cut;
    std::string error;
    try {
      cut = Cut(bgr, face, centre_row);
    } catch (const std::exception& e) {
      error = e.what()[0] ? e.what() : "the head mask could not be cut";
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      cut_ = std::move(cut);
      cut_error_ = std::move(error);
      cut_done_ = true;
    }
    changed_.notify_all();
  }
}

void FrameOutliner::LearnLoop() {
  // Learning may wait for the tracker and the frames' cuts; they may not wait for it.
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10);
  for (;;) {
    cv::Mat bgr;
    Landmarks2d face;
    int generation = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || !learn_bgr_.empty(); });
      if (stop_) return;
      bgr = std::move(learn_bgr_);
      learn_bgr_ = cv::Mat();
      face = learn_face_;
      generation = learn_generation_;
      learning_ = true;
    }
    HeadMaskModels fresh;
    try {
      fresh = LearnHeadMaskModels(bgr, face, mask_);
    } catch (const std::exception&) {  // a frame it cannot be learnt on: the models stay
      fresh = {};
    }
    std::lock_guard<std::mutex> lock(mutex_);
    learning_ = false;
    if (generation == generation_ && !fresh.background.empty()) {
      models_ = {fresh.background, fresh.foreground, 0, {}, {}};
      ++models_version_;
    }
  }
}

}  // namespace headcast
