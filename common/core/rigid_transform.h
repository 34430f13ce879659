// A rigid transform such as cam_from_head (rotation, translation in metres).
#pragma once

#include <Eigen/Core>

namespace headcast {

struct RigidTransform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d Apply(const Eigen::Vector3d& p) const { return rotation * p + translation; }
  RigidTransform Inverse() const { return {rotation.transpose(), -(rotation.transpose() * translation)}; }
  RigidTransform operator*(const RigidTransform& o) const {
    return {rotation * o.rotation, rotation * o.translation + translation};
  }
};

}  // namespace headcast
