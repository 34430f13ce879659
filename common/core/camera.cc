// Pinhole camera.
#include "common/core/camera.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "common/core/options.h"

namespace headcast {

PinholeCamera PinholeCamera::FromFovY(int width, int height, double fov_y_deg) {
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fy = 0.5 * height / std::tan(0.5 * fov_y_deg * M_PI / 180.0);
  c.fx = c.fy;
  c.cx = 0.5 * width - 0.5;
  c.cy = 0.5 * height - 0.5;
  return c;
}

Eigen::Vector2d PinholeCamera::Project(const Eigen::Vector3d& p) const {
  return {fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy};
}

Eigen::Matrix<double, 2, 3> PinholeCamera::ProjectJacobian(const Eigen::Vector3d& p) const {
  const double iz = 1.0 / p.z();
  Eigen::Matrix<double, 2, 3> J;
  J << fx * iz, 0, -fx * p.x() * iz * iz, 0, fy * iz, -fy * p.y() * iz * iz;
  return J;
}

Eigen::Vector3d PinholeCamera::Unproject(const Eigen::Vector2d& px, double depth) const {
  return {(px.x() - cx) / fx * depth, (px.y() - cy) / fy * depth, depth};
}

PinholeCamera PinholeCamera::Resized(int new_width, int new_height) const {
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  PinholeCamera c = *this;
  c.fx = fx * sx;
  c.fy = fy * sy;
  c.cx = (cx + 0.5) * sx - 0.5;
  c.cy = (cy + 0.5) * sy - 0.5;
  c.width = new_width;
  c.height = new_height;
  return c;
}

PinholeCamera PinholeCamera::Scaled(double factor) const {
  return Resized(static_cast<int>(std::lround(width * factor)), static_cast<int>(std::lround(height * factor)));
}

Eigen::Matrix3d PinholeCamera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

void PinholeCamera::Check() const {
  OptionsCheck check("PinholeCamera");
  check.Positive("fx", fx).Positive("fy", fy).Finite("cx", cx).Finite("cy", cy);
  check.Positive("width", width).Positive("height", height);
  check.ThrowIfErrors();
}

std::string PinholeCamera::ToString() const {
  std::ostringstream s;
  s << "fx=" << fx << " fy=" << fy << " cx=" << cx << " cy=" << cy << " " << width << "x" << height;
  return s.str();
}

nlohmann::json CameraToJson(const PinholeCamera& k) {
  return {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"width", k.width}, {"height", k.height}};
}

PinholeCamera CameraFromJson(const nlohmann::json& j) {
  return PinholeCamera{j.at("fx").get<double>(), j.at("fy").get<double>(), j.at("cx").get<double>(),
                       j.at("cy").get<double>(), j.at("width").get<int>(), j.at("height").get<int>()};
}

PinholeCamera ParseIntrinsics(const std::string& text, const std::string& flag) {
  PinholeCamera k;
  char end = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf%c", &k.fx, &k.fy, &k.cx, &k.cy, &end) != 4)
    throw std::invalid_argument(flag + " wants fx,fy,cx,cy in pixels, e.g. 640,640,320,240 (got '" + text + "')");
  if (!(k.fx > 0 && k.fy > 0 && std::isfinite(k.cx) && std::isfinite(k.cy)))
    throw std::invalid_argument(flag + ": focal lengths must be positive and the principal point finite");
  return k;
}

void ParseSize(const std::string& text, const std::string& flag, int* width, int* height) {
  char end = 0;
  int w = 0, h = 0;
  if (std::sscanf(text.c_str(), "%dx%d%c", &w, &h, &end) != 2 || w < 1 || h < 1 || w > 16384 || h > 16384)
    throw std::invalid_argument(flag + " wants WIDTHxHEIGHT in pixels, e.g. 1280x720 (got '" + text + "')");
  *width = w;
  *height = h;
}

}  // namespace headcast
