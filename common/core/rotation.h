// Axis-angle rotations (radians) with derivatives, shared by fitting and rendering.
#pragma once

#include <Eigen/Core>
#include <array>

namespace headcast {

// R = exp([w]x). If `dR_dw` is given, it receives dR/dw_i for i = 0..2.
Eigen::Matrix3d AxisAngleToMatrix(const Eigen::Vector3d& w, std::array<Eigen::Matrix3d, 3>* dR_dw = nullptr);

// Inverse of AxisAngleToMatrix; the angle is in [0, pi]. `R` must be a rotation.
Eigen::Vector3d MatrixToAxisAngle(const Eigen::Matrix3d& R);

// [v]x, the matrix with [v]x * u = v x u.
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

// Rotation about the camera's/head's y axis extracted as FLAME's landmark code does:
// atan2(-R20, sqrt(R00^2 + R10^2)), radians.
double YawOfMatrix(const Eigen::Matrix3d& R);

}  // namespace headcast
