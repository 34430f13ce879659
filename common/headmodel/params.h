// The parameters that travel per frame (FrameParams) and once per subject (SubjectParams).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/core/camera.h"
#include "common/core/rigid_transform.h"
#include "common/headmodel/head_model.h"

namespace headcast {

// What the sender streams for each frame. Rotations are axis-angle (radians),
// translations metres, in the head model's frame (y up, z out of the face) and
// OpenCV's camera frame.
struct FrameParams {
  Eigen::VectorXf expression;  // psi, E values
  Eigen::Vector3f jaw = Eigen::Vector3f::Zero();
  Eigen::Vector3f neck = Eigen::Vector3f::Zero();
  Eigen::Vector3f left_eye = Eigen::Vector3f::Zero();
  Eigen::Vector3f right_eye = Eigen::Vector3f::Zero();
  Eigen::Vector3f cam_rotation = Eigen::Vector3f::Zero();     // cam_from_head, axis-angle
  Eigen::Vector3f cam_translation = Eigen::Vector3f::Zero();  // cam_from_head, metres
  double capture_time_s = 0;                                  // capture timestamp, seconds (sender's steady clock)
  uint64_t sequence = 0;                                      // frame number at the sender
  float confidence = 1;                                       // tracking confidence, 0..1
  // The skin's median R, G, B (0..1) in the frame (SkinColour): the avatar's
  // picture is matched to it (the camera's exposure and white balance, the
  // light on the face). None: not measured; the avatar draws its own.
  std::optional<Eigen::Vector3f> skin_colour;
  // The top of the head's outline in the frame, mm per arc (MeasureOutline,
  // common/headmodel/head_outline.h): the avatar's edge is moved there.
  // Empty: not measured; the avatar draws its own.
  std::vector<float> outline;

  // The model pose vector: root zero (the head's placement is cam_from_head), then neck, jaw, eyes.
  PoseVector HeadPose() const;
  // HeadPose with the root set to the head's rotation as seen by the camera
  // (a frontal view is zero): what view-dependent landmarks (FLAME's dynamic
  // contour) are chosen by.
  PoseVector ViewPose() const;
  RigidTransform CamFromHead() const;
  void SetCamFromHead(const RigidTransform& cam_from_head);
  // Finite values, |rotations| <= pi, |expression| <= max_abs_expression,
  // the head in front of the camera (0.05 .. 20 m). `why` names the first problem.
  bool IsValid(std::string* why, float max_abs_expression = 5.f) const;
};

// The head's rotation relative to a frontal camera, axis-angle (see FrameParams::ViewPose).
Eigen::Vector3d ViewRotation(const Eigen::Matrix3d& cam_from_head_rotation);

// Interpolation of parameters at fraction t in [0, 1]: linear for expression
// and translation, slerp for every rotation.
FrameParams InterpolateParams(const FrameParams& a, const FrameParams& b, double t);

// Per-person constants, sent once or baked into the avatar.
struct SubjectParams {
  Eigen::VectorXf shape;          // beta
  Eigen::VectorXf texture;        // tau
  std::array<float, 27> light{};  // lambda: 2nd-order SH, 9 per RGB channel
  PinholeCamera intrinsics;       // of the output image
};

// The camera contract of an avatar: the full frames' camera its training
// video was tracked with, and the square (source pixels) its training images
// were cut from. The avatar renders with the crop's intrinsics
// (SubjectParams::intrinsics); a tracker that drives it fits with `source`
// (scaled to its frame size), so that its poses mean what they meant in training.
struct CameraContract {
  PinholeCamera source;
  double crop_x0 = 0, crop_y0 = 0, crop_side = 0;  // pixels of the source frames
  // Throws std::invalid_argument naming what is out of range.
  void Check() const;
  nlohmann::json ToJson() const;
  // Throws std::invalid_argument naming what is missing or out of range.
  static CameraContract FromJson(const nlohmann::json& j);
};

// `source` for frames of `width` x `height`: scaled when only the resolution
// differs; nothing when the aspect ratio differs by more than 1 % (another
// camera or mode: the contract cannot be kept).
std::optional<PinholeCamera> ContractCameraFor(const CameraContract& contract, int width, int height);

}  // namespace headcast
