// The per-frame rule the live sender and headcast-track (so also the
// trainer's prep) share, kept in one place so they cannot drift apart.
#pragma once

#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

// Fits the tracked face warm-started from *params (the previous frame's).
// A face found afresh by the detector after a loss starts from PnP with a
// neutral expression, not from the old pose. No face, or a failed fit, leaves
// *params marked cold (cam_translation zero) so the next face starts afresh;
// the result is then not ok.
// `rigid`: points the fit holds the pose to as well (optical flow), or null.
LandmarkFitResult FitTrackedFace(const HeadFitter& fitter, const FaceObservation& face, const PinholeCamera& camera,
                                 FrameParams* params, const RigidObservations* rigid = nullptr);

}  // namespace headcast
