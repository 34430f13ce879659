// The sender's per-frame pipeline from a camera frame to the parameters it
// streams: the one FrameTracker (face tracker, landmarks, head-model fit,
// warm-started) with the camera the live input gives — the same code and
// settings the offline pass (and so the trainer's prep) uses.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "common/capture/frame_source.h"
#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/frame_mask.h"
#include "common/tracking/frame_tracker.h"
#include "sender/frame_outliner.h"

namespace headcast {

struct LiveTrackerOptions {
  FrameTrackerOptions tracker;
  std::optional<PinholeCamera> camera;  // given intrinsics; else the source's, else the contract's, else fov_deg
  // The camera the avatar was trained with (--identity-from an avatar): used
  // when the source has no calibration and its frames have the same aspect.
  std::optional<CameraContract> contract;
  double fov_deg = 40;       // vertical field of view when nothing better is known
  Eigen::VectorXd identity;  // shape beta (empty: neutral); the avatar's own, ideally
  // The avatar's photometric anchor (ReadAvatarAnchorReference): the head's
  // placement held to the appearance its training frames were fitted to.
  std::optional<AnchorReference> anchor;
  // With the contract: each fitted frame carries the top of its head's
  // outline (FrameParams::outline), measured on the frame's head mask cut as
  // the avatar's training masks were (CutCropMask, at this resolution), so
  // that the receiver draws the hair's edge where the person's is. It costs
  // a GrabCut a frame, cut on a worker thread beside the fit (FrameOutliner;
  // the benchmark report has what it costs); headcast-sender turns it on
  // where it can be measured.
  bool outline = false;
  bool outline_beside_fit = true;  // false: the mask cut on the tracking thread after the fit
  int outline_resolution = 256;
  MatteRules matte_rules;  // the avatar's (its masks' rules)
  // GrabCut's: the training masks', except that a frame learns its own colour
  // models only every 8th frame (HeadMaskOptions::refit_every) and the
  // frames between are cut near the last one's outline (band; the benchmark
  // report has what each costs and saves).
  HeadMaskOptions outline_mask = [] {
    HeadMaskOptions o;
    o.refit_every = 8;
    o.band = 8;
    return o;
  }();
};

struct LiveTrackResult {
  bool fitted = false;
  bool with_depth = false;  // fitted (or tried) by the RGB-D fit
  FaceStatus status = FaceStatus::kNoFace;
  double landmarks_ms = 0;      // detection/tracking + landmarks
  double fit_ms = 0;            // head-model fit
  double depth_ms = 0;          // depth made on demand (stereo in the face's box)
  bool identity_frame = false;  // RGB-D: fitted with a free shape (the first frames, before the identity is frozen)
  bool provisional_identity = false;  // RGB-D, identity fitted beside tracking: not made yet
  bool identity_frozen_now = false;   // RGB-D: the identity was made at this frame
  bool anchored = false;              // fitted again with the placement held to the anchor's references
  double anchor_ms = 0;               // the anchor's alignment and fit (within fit_ms)
  // The outline's share of the frame's time after its fit: waiting for its
  // head mask, cutting it to the matte's rules, measuring the outline on it.
  double outline_ms = 0;
};

// The camera to track `width` x `height` frames with, and where it came from.
std::pair<PinholeCamera, std::string> ChooseTrackingCamera(const LiveTrackerOptions& options,
                                                           const std::optional<PinholeCamera>& source_camera, int width,
                                                           int height);

class LiveTracker {
 public:
  // Throws std::invalid_argument naming an option out of range.
  LiveTracker(const HeadModel& model, const LiveTrackerOptions& options);
  // Tracks one frame; on success *params holds the frame's expression, jaw and
  // cam_from_head (the caller stamps sequence and capture time), and its
  // outline when asked for.
  LiveTrackResult Process(const CapturedFrame& frame, FrameParams* params);
  const Eigen::VectorXd& identity() const { return tracker_.identity(); }

 private:
  const HeadModel& model_;
  LiveTrackerOptions options_;
  FrameTracker tracker_;
  std::optional<PinholeCamera> camera_;
  std::optional<FrameCrop> crop_;  // the avatar's square in this camera's frames (with the contract)
  bool outline_refused_ = false;   // asked for, but these frames have no square: said once
  // Made with the crop; its GrabCut colour models are carried from frame to
  // frame and forgotten when the face is lost, so that a face that returns
  // learns its own.
  std::unique_ptr<FrameOutliner> outliner_;
};

}  // namespace headcast
