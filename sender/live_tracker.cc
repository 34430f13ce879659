// Live tracking for the sender.
#include "sender/live_tracker.h"

#include <spdlog/spdlog.h>

#include "common/core/options.h"
#include "common/core/timer.h"

namespace headcast {

std::pair<PinholeCamera, std::string> ChooseTrackingCamera(const LiveTrackerOptions& o,
                                                           const std::optional<PinholeCamera>& source_camera, int width,
                                                           int height) {
  if (o.camera) return {*o.camera, "given intrinsics"};
  if (source_camera) return {*source_camera, "the source's calibration"};
  if (o.contract) {
    if (const std::optional<PinholeCamera> k = ContractCameraFor(*o.contract, width, height))
      return {*k, "the avatar's training camera"};
    spdlog::warn(
        "the avatar was trained with a {}x{} camera; these frames are {}x{} (another aspect): tracking with "
        "a {:.0f} degree field of view instead",
        o.contract->source.width, o.contract->source.height, width, height, o.fov_deg);
  }
  return {PinholeCamera::FromFovY(width, height, o.fov_deg), "the field of view"};
}

LiveTracker::LiveTracker(const HeadModel& model, const LiveTrackerOptions& options)
    : model_(model), options_(options), tracker_(model, options.tracker) {
  OptionsCheck c("LiveTrackerOptions");
  c.InRange("outline_resolution", options.outline_resolution, 32, 2048);
  c.ThrowIfErrors();
  options.outline_mask.Check();
  if (options.identity.size() > 0) tracker_.SetIdentity(options.identity);
  if (options.anchor) tracker_.SetAnchor(*options.anchor);
}

LiveTrackResult LiveTracker::Process(const CapturedFrame& frame, FrameParams* params) {
  const cv::Mat& bgr = frame.bgr;
  if (!camera_) {
    auto [camera, why] = ChooseTrackingCamera(options_, frame.camera, bgr.cols, bgr.rows);
    spdlog::info("tracking with {} ({})", why, camera.ToString());
    camera_ = camera;
  }
  camera_->width = bgr.cols;  // given intrinsics: the frame says how big it is
  camera_->height = bgr.rows;
  if (options_.outline && !crop_ && !outline_refused_) {
    if (options_.contract) crop_ = ContractCrop(*options_.contract, *camera_, options_.outline_resolution);
    outline_refused_ = !crop_;
    if (outline_refused_)
      spdlog::warn("the hair's outline is not measured: {}",
                   options_.contract ? "these frames are not of the avatar's camera (another aspect)"
                                     : "no camera contract (--identity-from an avatar that records one)");
  }
  Stopwatch watch;
  const FaceObservation face = tracker_.Observe(bgr, frame.capture_time_s);
  const double landmarks_ms = watch.ElapsedMs();
  // The outline's head mask is cut beside the fit: it needs only the landmarks.
  const bool outline = crop_ && face.status != FaceStatus::kNoFace;
  if (outline) {
    if (!outliner_)
      outliner_ = std::make_unique<FrameOutliner>(model_, *crop_, options_.matte_rules, options_.outline_mask,
                                                  options_.outline_beside_fit);
    outliner_->Start(bgr, face.raw);
  }
  TrackedFrame t = tracker_.TrackObserved(bgr, frame.depth_m, face, *camera_, params, frame.depth_on_demand.get());
  t.landmarks_ms = landmarks_ms;
  LiveTrackResult r{t.fitted,   t.with_depth,     t.face.status,          t.landmarks_ms,        t.fit_ms,
                    t.depth_ms, t.identity_frame, t.provisional_identity, t.identity_frozen_now, t.anchored,
                    t.anchor_ms};
  if (!t.fitted) {
    if (outliner_) outliner_->Forget();
    return r;
  }
  if (outline) {
    watch.Restart();
    try {
      params->outline =
          outliner_->Finish(*params, tracker_.fitter().Project(*params, crop_->camera), tracker_.identity());
    } catch (const std::exception& e) {  // a frame the mask cannot be cut on goes without an outline
      spdlog::warn("frame without the hair's outline: {}", e.what());
    }
    r.outline_ms = watch.ElapsedMs();
  }
  return r;
}

}  // namespace headcast
