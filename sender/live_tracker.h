// The sender's per-frame pipeline from a camera frame to the parameters it
// streams: face tracker (dlib detector + 68 landmarks + One-Euro filter), then
// the head model fitted by HeadFitter, warm-started — the same code and
// settings headcast-track (and so the trainer's prep) uses.
#pragma once

#include <optional>
#include <string>

#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

struct LiveTrackerOptions {
  std::string predictor;                // dlib 68-point model; empty: the default path
  std::optional<PinholeCamera> camera;  // intrinsics; else the source's, else fov_deg
  double fov_deg = 40;                  // vertical field of view when nothing better is known
  Eigen::VectorXd identity;             // shape beta (empty: neutral); the avatar's own, ideally
};

struct LiveTrackResult {
  bool fitted = false;
  FaceStatus status = FaceStatus::kNoFace;
  double landmarks_ms = 0;  // detection/tracking + landmarks
  double fit_ms = 0;        // head-model fit
};

// The person's shape for tracking: from an avatar (.hcavatar: the identity it
// was trained with, so the fit agrees with the avatar) or a PARAMS.json
// (headcast-fit-mesh). Throws naming the file when it is unreadable or made
// for another head model.
Eigen::VectorXd ReadTrackingIdentity(const std::string& path, const HeadModel& model);

class LiveTracker {
 public:
  LiveTracker(const HeadModel& model, const LiveTrackerOptions& options);
  // Tracks one frame; on success *params holds the frame's expression, jaw and
  // cam_from_head (the caller stamps sequence and capture time).
  LiveTrackResult Process(const cv::Mat& bgr, double time_s, const std::optional<PinholeCamera>& source_camera,
                          FrameParams* params);

 private:
  LiveTrackerOptions options_;
  FaceTracker tracker_;
  HeadFitter fitter_;
  std::optional<PinholeCamera> camera_;
  FrameParams last_;
};

}  // namespace headcast
