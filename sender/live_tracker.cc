// Live tracking for the sender.
#include "sender/live_tracker.h"

#include "common/core/timer.h"

namespace headcast {
namespace {

FaceTrackerOptions TrackerOptions(const LiveTrackerOptions& o) {
  FaceTrackerOptions t;
  if (!o.predictor.empty()) t.predictor_path = o.predictor;
  return t;
}

}  // namespace

LiveTracker::LiveTracker(const HeadModel& model, const LiveTrackerOptions& options)
    : options_(options), tracker_(TrackerOptions(options)), fitter_(model), camera_(options.camera) {
  if (options.identity.size() > 0) fitter_.SetIdentity(options.identity);
  last_.cam_translation.setZero();  // cold start
}

LiveTrackResult LiveTracker::Process(const cv::Mat& bgr, double time_s,
                                     const std::optional<PinholeCamera>& source_camera, FrameParams* params) {
  if (!camera_)
    camera_ = source_camera ? *source_camera : PinholeCamera::FromFovY(bgr.cols, bgr.rows, options_.fov_deg);
  camera_->width = bgr.cols;  // given intrinsics: the frame says how big it is
  camera_->height = bgr.rows;
  LiveTrackResult r;
  Stopwatch watch;
  const FaceObservation obs = tracker_.Track(bgr, time_s);
  r.landmarks_ms = watch.ElapsedMs();
  r.status = obs.status;
  if (obs.status == FaceStatus::kNoFace) {
    last_.cam_translation.setZero();  // the next face starts cold
    return r;
  }
  watch.Restart();
  // A newly detected face after a loss starts from PnP, not from the old pose.
  if (obs.status == FaceStatus::kDetected && !(last_.cam_translation.z() > 0)) last_.expression.resize(0);
  const FitResult fit = fitter_.Fit(obs.landmarks, *camera_, &last_);
  r.fit_ms = watch.ElapsedMs();
  r.fitted = fit.ok;
  if (!fit.ok) {
    last_.cam_translation.setZero();
    return r;
  }
  *params = last_;
  return r;
}

}  // namespace headcast
