// Pinhole camera in OpenCV's convention (x right, y down, z forward; pixel centres at integers).
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

namespace headcast {

struct PinholeCamera {
  double fx = 500;   // focal length, pixels
  double fy = 500;   // focal length, pixels
  double cx = 320;   // principal point, pixels
  double cy = 240;   // principal point, pixels
  int width = 640;   // image width, pixels
  int height = 480;  // image height, pixels

  // A camera whose vertical field of view is `fov_y_deg` with the principal point centred.
  static PinholeCamera FromFovY(int width, int height, double fov_y_deg);

  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_cam) const;
  // 2x3 Jacobian of Project at `point_in_cam`.
  Eigen::Matrix<double, 2, 3> ProjectJacobian(const Eigen::Vector3d& point_in_cam) const;
  // The point at `depth` (metres along z) seen at `pixel`.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& pixel, double depth) const;

  // Intrinsics for the same view resampled to another image size (e.g. a NeRF
  // feature map): pixel-area-preserving, so (c + 0.5) scales with the image.
  PinholeCamera Resized(int new_width, int new_height) const;
  PinholeCamera Scaled(double factor) const;

  Eigen::Matrix3d K() const;
  void Check() const;  // throws std::invalid_argument naming what is wrong
  std::string ToString() const;
};

// {"fx", "fy", "cx", "cy", "width", "height"} in files (avatars, contracts).
nlohmann::json CameraToJson(const PinholeCamera& camera);
// Throws nlohmann's exception for a missing or mistyped field; the caller names the file.
PinholeCamera CameraFromJson(const nlohmann::json& j);

// "fx,fy,cx,cy" in pixels (a flag's value; `flag` names it in the error).
// Width and height stay at their defaults: the frames say how big they are.
PinholeCamera ParseIntrinsics(const std::string& text, const std::string& flag);

// "WIDTHxHEIGHT" in pixels; throws std::invalid_argument naming `flag`.
void ParseSize(const std::string& text, const std::string& flag, int* width, int* height);

}  // namespace headcast
