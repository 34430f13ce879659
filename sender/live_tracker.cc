// Live tracking for the sender.
#include "sender/live_tracker.h"

#include <spdlog/spdlog.h>

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
    : options_(options), tracker_(model, options.tracker) {
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
  const TrackedFrame t =
      tracker_.Track(bgr, frame.depth_m, frame.capture_time_s, *camera_, params, frame.depth_on_demand.get());
  return {t.fitted,         t.with_depth,           t.face.status,         t.landmarks_ms, t.fit_ms,   t.depth_ms,
          t.identity_frame, t.provisional_identity, t.identity_frozen_now, t.anchored,     t.anchor_ms};
}

}  // namespace headcast
