// Axis-angle rotations with derivatives.
#include "common/core/rotation.h"

#include <Eigen/Geometry>
#include <cmath>

namespace headcast {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

Eigen::Matrix3d AxisAngleToMatrix(const Eigen::Vector3d& w, std::array<Eigen::Matrix3d, 3>* dR_dw) {
  const double theta2 = w.squaredNorm();
  Eigen::Matrix3d R;
  const Eigen::Matrix3d K = Skew(w);
  if (theta2 < 1e-16) {
    R = Eigen::Matrix3d::Identity() + K;  // first order; exact enough below 1e-8 rad
  } else {
    const double theta = std::sqrt(theta2);
    R = Eigen::Matrix3d::Identity() + std::sin(theta) / theta * K + (1 - std::cos(theta)) / theta2 * K * K;
  }
  if (dR_dw) {
    if (theta2 < 1e-16) {
      for (int i = 0; i < 3; ++i) (*dR_dw)[i] = Skew(Eigen::Vector3d::Unit(i));
    } else {
      // Closed form of Gallego & Yezzi (2015): dR/dw_i = (w_i [w]x + [w x (I - R) e_i]x) R / |w|^2.
      const Eigen::Matrix3d I_minus_R = Eigen::Matrix3d::Identity() - R;
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d e = Eigen::Vector3d::Unit(i);
        (*dR_dw)[i] = (w[i] * K + Skew(w.cross(I_minus_R * e))) * R / theta2;
      }
    }
  }
  return R;
}

Eigen::Vector3d MatrixToAxisAngle(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

double YawOfMatrix(const Eigen::Matrix3d& R) {
  return std::atan2(-R(2, 0), std::sqrt(R(0, 0) * R(0, 0) + R(1, 0) * R(1, 0)));
}

}  // namespace headcast
