// The built-in head posed by an expressive, turned frame: what the avatar
// tests of the canonical mapping and the matte rasterise and look up.
#pragma once

#include <memory>

#include "common/avatar/avatar.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/raster/rasterizer.h"

namespace headcast::testing {

inline std::shared_ptr<const HeadModel> BuiltinHead() {
  static auto model = std::make_shared<const HeadModel>(MakeBuiltinHead());
  return model;
}

// A frame with an expression and a turned head, so that the posed mesh is far
// from the canonical one.
inline FrameParams Expressive() {
  FrameParams p;
  p.expression = Eigen::VectorXf::Zero(BuiltinHead()->num_expression());
  p.expression[0] = 1.5f;  // smile
  p.expression[8] = 1.0f;  // lips part
  p.jaw = Eigen::Vector3f(0.25f, 0, 0);
  p.neck = Eigen::Vector3f(0.1f, 0.3f, 0);
  p.SetCamFromHead(FrontalCamFromHead(0.62));
  return p;
}

// The neutral-shaped built-in head posed by `frame`, seen by the default subject's camera at `size`.
struct Posed {
  HeadIdentity identity;
  HeadModelOutput posed;
  RasterVertices v_cam;
  PinholeCamera camera;
};

inline Posed Pose(const FrameParams& frame, int size) {
  const HeadModel& m = *BuiltinHead();
  Posed p;
  p.identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  m.Forward(p.identity, frame.expression.cast<double>(), frame.HeadPose(), &p.posed);
  TransformToCamera(p.posed.vertices, frame.CamFromHead(), &p.v_cam);
  p.camera = DefaultSubject(m, size).intrinsics;
  return p;
}

}  // namespace headcast::testing
