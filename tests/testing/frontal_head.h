// The built-in head before a 640 x 480 camera, turned about its landmarks'
// centroid: what the tracking tests render, anchor and fit.
#pragma once

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"

namespace headcast::testing {

inline const HeadModel& BuiltinModel() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

inline const PinholeCamera kFrontalCamera = PinholeCamera::FromFovY(640, 480, 45);
inline constexpr double kFrontalDistance = 0.45;  // metres

// Neutral expression, the head `kFrontalDistance` before the camera, turned by yaw and pitch.
inline FrameParams FrontalPose(double yaw_deg, double pitch_deg) {
  FrameParams f;
  f.expression = Eigen::VectorXf::Zero(BuiltinModel().num_expression());
  f.SetCamFromHead(FrontalCamFromHead(kFrontalDistance, yaw_deg, pitch_deg, BuiltinModel().rest_landmark_centroid()));
  return f;
}

}  // namespace headcast::testing
