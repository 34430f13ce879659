// FrameParams helpers.
#include "common/headmodel/params.h"

#include <Eigen/Geometry>
#include <cmath>

#include "common/core/rotation.h"
#include "common/headmodel/head_outline.h"

namespace headcast {

PoseVector FrameParams::HeadPose() const {
  PoseVector p = PoseVector::Zero();
  p.segment<3>(3 * kNeckJoint) = neck.cast<double>();
  p.segment<3>(3 * kJawJoint) = jaw.cast<double>();
  p.segment<3>(3 * kLeftEyeJoint) = left_eye.cast<double>();
  p.segment<3>(3 * kRightEyeJoint) = right_eye.cast<double>();
  return p;
}

PoseVector FrameParams::ViewPose() const {
  PoseVector p = HeadPose();
  p.segment<3>(0) = ViewRotation(AxisAngleToMatrix(cam_rotation.cast<double>()));
  return p;
}

Eigen::Vector3d ViewRotation(const Eigen::Matrix3d& cam_from_head_rotation) {
  // The camera has y down and z forward; the head y up and z out of the face.
  // A head facing the camera has cam_from_head = diag(1, -1, -1).
  return MatrixToAxisAngle(Eigen::Vector3d(1, -1, -1).asDiagonal() * cam_from_head_rotation);
}

RigidTransform FrameParams::CamFromHead() const {
  return {AxisAngleToMatrix(cam_rotation.cast<double>()), cam_translation.cast<double>()};
}

void FrameParams::SetCamFromHead(const RigidTransform& t) {
  cam_rotation = MatrixToAxisAngle(t.rotation).cast<float>();
  cam_translation = t.translation.cast<float>();
}

bool FrameParams::IsValid(std::string* why, float max_abs_expression) const {
  auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (!expression.allFinite()) return fail("expression has NaN or infinite values");
  if (expression.size() > 0 && expression.cwiseAbs().maxCoeff() > max_abs_expression)
    return fail("expression out of range (|value| > " + std::to_string(max_abs_expression) + ")");
  const std::pair<const char*, const Eigen::Vector3f*> rotations[] = {{"jaw", &jaw},
                                                                      {"neck", &neck},
                                                                      {"left_eye", &left_eye},
                                                                      {"right_eye", &right_eye},
                                                                      {"cam_rotation", &cam_rotation}};
  for (const auto& [name, r] : rotations) {
    if (!r->allFinite()) return fail(std::string(name) + " has NaN or infinite values");
    if (r->norm() > M_PI + 1e-3) return fail(std::string(name) + " rotation angle exceeds pi");
  }
  if (!cam_translation.allFinite()) return fail("cam_translation has NaN or infinite values");
  if (!(cam_translation.z() > 0.05f && cam_translation.z() < 20.f))
    return fail("head not 0.05..20 m in front of the camera");
  if (!std::isfinite(capture_time_s)) return fail("capture time is not finite");
  if (!(confidence >= 0 && confidence <= 1)) return fail("confidence outside 0..1");
  if (skin_colour && !(skin_colour->allFinite() && skin_colour->minCoeff() >= 0 && skin_colour->maxCoeff() <= 1))
    return fail("skin colour outside 0..1");
  if (std::string outline_why; !OutlineIsValid(outline, &outline_why)) return fail(outline_why);
  return true;
}

namespace {
Eigen::Vector3f Slerp(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double t) {
  auto quat = [](const Eigen::Vector3f& w) {
    const double angle = w.norm();
    return angle < 1e-12 ? Eigen::Quaterniond::Identity()
                         : Eigen::Quaterniond(Eigen::AngleAxisd(angle, w.cast<double>() / angle));
  };
  const Eigen::AngleAxisd r(quat(a).slerp(t, quat(b)));
  return (r.angle() * r.axis()).cast<float>();
}
}  // namespace

FrameParams InterpolateParams(const FrameParams& a, const FrameParams& b, double t) {
  FrameParams out = t < 0.5 ? a : b;
  if (a.expression.size() == b.expression.size())
    out.expression = ((1 - t) * a.expression.cast<double>() + t * b.expression.cast<double>()).cast<float>();
  out.jaw = Slerp(a.jaw, b.jaw, t);
  out.neck = Slerp(a.neck, b.neck, t);
  out.left_eye = Slerp(a.left_eye, b.left_eye, t);
  out.right_eye = Slerp(a.right_eye, b.right_eye, t);
  out.cam_rotation = Slerp(a.cam_rotation, b.cam_rotation, t);
  out.cam_translation =
      ((1 - t) * a.cam_translation.cast<double>() + t * b.cam_translation.cast<double>()).cast<float>();
  out.capture_time_s = (1 - t) * a.capture_time_s + t * b.capture_time_s;
  out.confidence = static_cast<float>((1 - t) * a.confidence + t * b.confidence);
  if (a.skin_colour && b.skin_colour)
    out.skin_colour = ((1 - t) * a.skin_colour->cast<double>() + t * b.skin_colour->cast<double>()).cast<float>();
  if (a.outline.size() == b.outline.size())  // a bin unknown in either stays unknown
    for (size_t k = 0; k < a.outline.size(); ++k)
      out.outline[k] = a.outline[k] == kOutlineUnknown || b.outline[k] == kOutlineUnknown
                           ? kOutlineUnknown
                           : static_cast<float>((1 - t) * a.outline[k] + t * b.outline[k]);
  else
    out.outline.clear();
  return out;
}

nlohmann::json CameraContract::ToJson() const {
  return {{"source", CameraToJson(source)}, {"crop", {{"x0", crop_x0}, {"y0", crop_y0}, {"side", crop_side}}}};
}

CameraContract CameraContract::FromJson(const nlohmann::json& j) {
  CameraContract c;
  try {
    c.source = CameraFromJson(j.at("source"));
    c.crop_x0 = j.at("crop").at("x0");
    c.crop_y0 = j.at("crop").at("y0");
    c.crop_side = j.at("crop").at("side");
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("camera contract: ") + e.what());
  }
  c.Check();
  return c;
}

void CameraContract::Check() const {
  source.Check();
  if (!(crop_side > 0 && std::isfinite(crop_x0) && std::isfinite(crop_y0)))
    throw std::invalid_argument("camera contract: the crop needs a positive side and a finite corner");
}

std::optional<PinholeCamera> ContractCameraFor(const CameraContract& contract, int width, int height) {
  const PinholeCamera& s = contract.source;
  const double aspect = static_cast<double>(width) / height, source_aspect = static_cast<double>(s.width) / s.height;
  if (std::abs(aspect / source_aspect - 1) > 0.01) return std::nullopt;
  if (width == s.width && height == s.height) return s;
  return s.Resized(width, height);
}

}  // namespace headcast
