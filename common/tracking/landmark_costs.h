// The head fitter's residuals (landmark reprojection; the lids' tie to the gaze), in a header so tests can
// check them with ceres::GradientChecker.
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "common/core/camera.h"

namespace headcast {

// weight * (the pinhole projection of cam_from_head * p - observed), pixels.
template <typename T>
void ProjectionResidual(const T* cam_rotation, const T* cam_translation, const T* p, const PinholeCamera& cam,
                        const Eigen::Vector2d& observed, double weight, T* residual) {
  T x[3];
  ceres::AngleAxisRotatePoint(cam_rotation, p, x);
  for (int c = 0; c < 3; ++c) x[c] += cam_translation[c];
  residual[0] = T(weight) * (T(cam.fx) * x[0] / x[2] + T(cam.cx) - T(observed.x()));
  residual[1] = T(weight) * (T(cam.fy) * x[1] / x[2] + T(cam.cy) - T(observed.y()));
}

// One landmark of one frame: expression-linear position, jaw skinning,
// cam_from_head, pinhole projection; blocks rotation, translation,
// expression, jaw. Its Jacobian is written out: the position is linear in the
// expression, so one product with the landmark's directions gives that block,
// where autodiff would carry a derivative per coefficient through every step.
// Only the two rotations go through jets (three derivatives each).
class LandmarkCost : public ceres::CostFunction {
 public:
  LandmarkCost(const Eigen::Vector3d& base, const Eigen::Matrix<double, 3, Eigen::Dynamic>& dirs, double jaw_weight,
               const Eigen::Vector3d& jaw_joint, const Eigen::Vector2d& observed, const PinholeCamera& cam,
               double weight)
      : base_(base),
        dirs_(dirs),
        jaw_weight_(jaw_weight),
        jaw_joint_(jaw_joint),
        observed_(observed),
        cam_(cam),
        weight_(weight) {
    set_num_residuals(2);
    *mutable_parameter_block_sizes() = {3, 3, static_cast<int>(dirs.cols()), 3};
  }

  bool Evaluate(double const* const* blocks, double* residual, double** jacobians) const override {
    const int k = static_cast<int>(dirs_.cols());
    const Eigen::Vector3d unskinned = base_ + dirs_ * Eigen::Map<const Eigen::VectorXd>(blocks[2], k);
    Eigen::Vector3d p = unskinned;
    Eigen::Matrix3d by_unskinned = Eigen::Matrix3d::Identity(), by_jaw = Eigen::Matrix3d::Zero();
    if (jaw_weight_ > 0) {
      // Linear blend skinning between the head (identity) and the jaw joint's rotation.
      Eigen::Matrix3d jaw_rotation;
      const Eigen::Vector3d rotated = Rotate(blocks[3], unskinned - jaw_joint_, &by_jaw, &jaw_rotation);
      p = (1 - jaw_weight_) * unskinned + jaw_weight_ * (rotated + jaw_joint_);
      by_unskinned = (1 - jaw_weight_) * Eigen::Matrix3d::Identity() + jaw_weight_ * jaw_rotation;
      by_jaw *= jaw_weight_;
    }
    Eigen::Matrix3d x_by_rotation, cam_rotation;
    const Eigen::Vector3d x =
        Rotate(blocks[0], p, &x_by_rotation, &cam_rotation) + Eigen::Map<const Eigen::Vector3d>(blocks[1]);
    residual[0] = weight_ * (cam_.fx * x[0] / x[2] + cam_.cx - observed_.x());
    residual[1] = weight_ * (cam_.fy * x[1] / x[2] + cam_.cy - observed_.y());
    if (!jacobians) return true;
    Eigen::Matrix<double, 2, 3> r_by_x;
    r_by_x << cam_.fx / x[2], 0, -cam_.fx * x[0] / (x[2] * x[2]), 0, cam_.fy / x[2], -cam_.fy * x[1] / (x[2] * x[2]);
    r_by_x *= weight_;
    using RowMajor2x3 = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;
    if (jacobians[0]) Eigen::Map<RowMajor2x3>{jacobians[0]} = r_by_x * x_by_rotation;
    if (jacobians[1]) Eigen::Map<RowMajor2x3>{jacobians[1]} = r_by_x;
    const Eigen::Matrix<double, 2, 3> r_by_p = r_by_x * cam_rotation;
    if (jacobians[2])
      Eigen::Map<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>>(jacobians[2], 2, k) =
          (r_by_p * by_unskinned) * dirs_;
    if (jacobians[3]) Eigen::Map<RowMajor2x3>{jacobians[3]} = r_by_p * by_jaw;
    return true;
  }

 private:
  // `point` turned by the axis-angle `angle_axis` (ceres::AngleAxisRotatePoint),
  // with the derivative by the angle-axis and the rotation's matrix (the
  // derivative by the point).
  static Eigen::Vector3d Rotate(const double* angle_axis, const Eigen::Vector3d& point, Eigen::Matrix3d* by_angle_axis,
                                Eigen::Matrix3d* matrix) {
    using Jet = ceres::Jet<double, 3>;
    const Jet w[3] = {Jet(angle_axis[0], 0), Jet(angle_axis[1], 1), Jet(angle_axis[2], 2)};
    const Jet q[3] = {Jet(point[0]), Jet(point[1]), Jet(point[2])};
    Jet out[3];
    ceres::AngleAxisRotatePoint(w, q, out);
    for (int c = 0; c < 3; ++c) by_angle_axis->row(c) = out[c].v.transpose();
    ceres::AngleAxisToRotationMatrix(angle_axis, matrix->data());  // column-major, as Eigen's
    return {out[0].a, out[1].a, out[2].a};
  }

  Eigen::Vector3d base_;
  Eigen::Matrix<double, 3, Eigen::Dynamic> dirs_;
  double jaw_weight_;
  Eigen::Vector3d jaw_joint_;
  Eigen::Vector2d observed_;
  PinholeCamera cam_;
  double weight_;
};

// A point of the head that no expression moves (head frame), seen at
// `observed`: cam_from_head and the pinhole projection only.
struct RigidPointResidual {
  RigidPointResidual(const Eigen::Vector3d& head, const Eigen::Vector2d& observed, const PinholeCamera& cam,
                     double weight)
      : head(head), observed(observed), cam(cam), weight(weight) {}
  template <typename T>
  bool operator()(const T* cam_rotation, const T* cam_translation, T* residual) const {
    const T p[3] = {T(head.x()), T(head.y()), T(head.z())};
    ProjectionResidual(cam_rotation, cam_translation, p, cam, observed, weight, residual);
    return true;
  }
  Eigen::Vector3d head;
  Eigen::Vector2d observed;
  PinholeCamera cam;
  double weight;
};

// The same landmark during identity calibration: shape (and the jaw joint's
// dependence on it) and a log focal-length scale are unknowns too. Blocks:
// rotation, translation, expression, jaw, shape, log focal scale.
struct CalibrationResidual {
  CalibrationResidual(const Eigen::Vector3d& base, const Eigen::Matrix<double, 3, Eigen::Dynamic>& expression_dirs,
                      const Eigen::Matrix<double, 3, Eigen::Dynamic>& shape_dirs, double jaw_weight,
                      const Eigen::Vector3d& jaw_joint, const Eigen::Matrix<double, 3, Eigen::Dynamic>& jaw_shape_dirs,
                      const Eigen::Vector2d& observed, const PinholeCamera& cam, double weight)
      : base(base),
        expression_dirs(expression_dirs),
        shape_dirs(shape_dirs),
        jaw_weight(jaw_weight),
        jaw_joint(jaw_joint),
        jaw_shape_dirs(jaw_shape_dirs),
        observed(observed),
        cam(cam),
        weight(weight) {}

  template <typename T>
  bool operator()(T const* const* blocks, T* residual) const {
    const T* rotation = blocks[0];
    const T* translation = blocks[1];
    const T* expression = blocks[2];
    const T* jaw = blocks[3];
    const T* shape = blocks[4];
    const T* log_focal = blocks[5];
    T p[3], joint[3];
    for (int c = 0; c < 3; ++c) {
      p[c] = T(base[c]);
      joint[c] = T(jaw_joint[c]);
      for (int k = 0; k < expression_dirs.cols(); ++k) p[c] += T(expression_dirs(c, k)) * expression[k];
      for (int k = 0; k < shape_dirs.cols(); ++k) {
        p[c] += T(shape_dirs(c, k)) * shape[k];
        joint[c] += T(jaw_shape_dirs(c, k)) * shape[k];
      }
    }
    if (jaw_weight > 0) {
      T rel[3] = {p[0] - joint[0], p[1] - joint[1], p[2] - joint[2]}, rotated[3];
      ceres::AngleAxisRotatePoint(jaw, rel, rotated);
      for (int c = 0; c < 3; ++c) p[c] = (T(1) - T(jaw_weight)) * p[c] + T(jaw_weight) * (rotated[c] + joint[c]);
    }
    T x[3];
    ceres::AngleAxisRotatePoint(rotation, p, x);
    for (int c = 0; c < 3; ++c) x[c] += translation[c];
    const T scale = exp(log_focal[0]);
    residual[0] = T(weight) * (scale * T(cam.fx) * x[0] / x[2] + T(cam.cx) - T(observed.x()));
    residual[1] = T(weight) * (scale * T(cam.fy) * x[1] / x[2] + T(cam.cy) - T(observed.y()));
    return true;
  }

  Eigen::Vector3d base;
  Eigen::Matrix<double, 3, Eigen::Dynamic> expression_dirs, shape_dirs;
  double jaw_weight;
  Eigen::Vector3d jaw_joint;
  Eigen::Matrix<double, 3, Eigen::Dynamic> jaw_shape_dirs;
  Eigen::Vector2d observed;
  PinholeCamera cam;
  double weight;
};

// The pupil against the located iris: the pupil's rest point turned about its
// eye joint (gaze), then cam_from_head and the pinhole. Blocks: rotation,
// translation, eye rotation (axis-angle).
struct PupilResidual {
  PupilResidual(const Eigen::Vector3d& pupil, const Eigen::Vector3d& eye_joint, const Eigen::Vector2d& observed,
                const PinholeCamera& cam, double weight)
      : pupil(pupil), eye_joint(eye_joint), observed(observed), cam(cam), weight(weight) {}

  template <typename T>
  bool operator()(const T* cam_rotation, const T* cam_translation, const T* eye, T* residual) const {
    T rel[3] = {T(pupil[0] - eye_joint[0]), T(pupil[1] - eye_joint[1]), T(pupil[2] - eye_joint[2])}, p[3];
    ceres::AngleAxisRotatePoint(eye, rel, p);
    for (int c = 0; c < 3; ++c) p[c] += T(eye_joint[c]);
    ProjectionResidual(cam_rotation, cam_translation, p, cam, observed, weight, residual);
    return true;
  }

  Eigen::Vector3d pupil, eye_joint;
  Eigen::Vector2d observed;
  PinholeCamera cam;
  double weight;
};

// A vertical eyeLook coefficient against the lids its eye's pitch implies:
// weight * (c - clamp(sign * elevation / radians, 0, 1)), where elevation is how
// far `eye` turns the line of sight `axis` up (head frame, y up) from its rest
// elevation. Blocks: the expression and the eye's rotation. The derivative by
// the eye is left out on purpose: the lids follow the gaze the irises show,
// and must not pull it toward whatever look would explain raised lids.
class LidGazeCost : public ceres::CostFunction {
 public:
  LidGazeCost(int num_expression, int coefficient, const Eigen::Vector3d& axis, double sign, double radians,
              double weight)
      : coefficient_(coefficient),
        axis_(axis),
        rest_elevation_(Elevation(axis.data())),
        sign_(sign),
        radians_(radians),
        weight_(weight) {
    set_num_residuals(1);
    mutable_parameter_block_sizes()->push_back(num_expression);
    mutable_parameter_block_sizes()->push_back(3);
  }

  // What the coefficient should be for the eye's rotation `eye` (axis-angle, head frame).
  double Target(const double* eye) const {
    double d[3];
    ceres::AngleAxisRotatePoint(eye, axis_.data(), d);
    const double elevation = Elevation(d) - rest_elevation_;
    return std::clamp(sign_ * elevation / radians_, 0.0, 1.0);  // the shape's range: a wrong iris moves it no further
  }

  bool Evaluate(double const* const* blocks, double* residual, double** jacobians) const override {
    residual[0] = weight_ * (blocks[0][coefficient_] - Target(blocks[1]));
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + parameter_block_sizes()[0], 0.0);
      jacobians[0][coefficient_] = weight_;
    }
    if (jacobians && jacobians[1]) std::fill(jacobians[1], jacobians[1] + 3, 0.0);
    return true;
  }

 private:
  // Angle of the direction `d` above the head's horizontal plane (y up).
  static double Elevation(const double* d) { return std::atan2(d[1], std::hypot(d[0], d[2])); }

  int coefficient_;
  Eigen::Vector3d axis_;
  double rest_elevation_;  // of axis_, once: Target runs a few times a frame
  double sign_, radians_, weight_;
};

}  // namespace headcast
