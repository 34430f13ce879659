#include "common/tracking/tracked_fit.h"

namespace headcast {

LandmarkFitResult FitTrackedFace(const HeadFitter& fitter, const FaceObservation& face, const PinholeCamera& camera,
                                 FrameParams* params, const RigidObservations* rigid) {
  if (face.status == FaceStatus::kNoFace) {
    params->cam_translation.setZero();
    return {};
  }
  if (face.status == FaceStatus::kDetected && !(params->cam_translation.z() > 0)) {
    params->expression.resize(0);
    params->left_eye.setZero();
    params->right_eye.setZero();
  }
  const LandmarkFitResult fit = fitter.Fit(face.landmarks, camera, params, &face.irises, rigid);
  if (!fit.ok) params->cam_translation.setZero();
  return fit;
}

}  // namespace headcast
