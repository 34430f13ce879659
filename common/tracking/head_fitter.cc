// Landmark fitting with Ceres.
#include "common/tracking/head_fitter.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <opencv2/calib3d.hpp>

#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/tracking/expression_fit.h"
#include "common/tracking/iris_locator.h"
#include "common/tracking/landmark_costs.h"
#include "common/tracking/rigid_vertex.h"

namespace headcast {

void HeadFitterOptions::Check() const {
  OptionsCheck c("HeadFitterOptions");
  c.InRange("num_expression", num_expression, 0, 1000);
  ExpressionFitSettings::Of(*this).CheckInto(&c);
  c.NonNegative("jaw_prior", jaw_prior).NonNegative("contour_weight", contour_weight);
  c.InRange("expression_limit", expression_limit, 0.1, 5.0);
  c.InRange("max_iterations", max_iterations, 1, 1000).Positive("huber_px", huber_px);
  c.NonNegative("iris_weight", iris_weight).NonNegative("gaze_prior", gaze_prior);
  c.NonNegative("vergence_weight", vergence_weight).NonNegative("eye_roll_weight", eye_roll_weight);
  c.InRange("max_gaze_rad", max_gaze_rad, 0.0, 1.5).NonNegative("rigid_flow_weight", rigid_flow_weight);
  c.NonNegative("shape_prior", shape_prior).InRange("max_focal_change", max_focal_change, 1, 100);
  c.NonNegative("calibration_mean_expression", calibration_mean_expression);
  c.ThrowIfErrors();
}

// The 68 landmarks as linear functions of expression, in the head frame, plus
// how much of each follows the jaw joint (skinning weights at the landmark).
struct HeadFitter::LandmarkBasis {
  Eigen::Matrix<double, kNumLandmarks, 3, Eigen::RowMajor> base;
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> dirs;        // per landmark: 3 x E
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> shape_dirs;  // per landmark: 3 x S (shape_free only)
  Eigen::Matrix<double, kNumLandmarks, 1> jaw_weight;
  Eigen::Vector3d jaw_joint;
};

namespace {

// Vertices above the brows that face forward and that no expression moves by
// more than a millimetre per unit coefficient (forehead, hairline, crown), nor
// the jaw or the eyes: what optical flow can follow as the rigid head. At most
// `count`, spread evenly over the candidates.
std::vector<int> RigidHeadVertices(const HeadModel& model,
                                   const Eigen::Matrix<double, kNumLandmarks, 3, Eigen::RowMajor>& rest_landmarks,
                                   int count) {
  const HeadModelData& d = model.data();
  const double brow_y = rest_landmarks.middleRows(17, 10).col(1).maxCoeff();
  const RowMatrixX3f normals = model.VertexNormals(d.v_template);
  std::vector<int> candidates;
  for (int v = 0; v < model.num_vertices(); ++v) {
    if (d.v_template(v, 1) < brow_y + 0.01 || normals(v, 2) < 0.3) continue;
    if (MovesOnlyWithTheSkull(model, v)) candidates.push_back(v);
  }
  if (static_cast<int>(candidates.size()) <= count) return candidates;
  std::vector<int> picked;
  for (int i = 0; i < count; ++i) picked.push_back(candidates[i * candidates.size() / count]);
  return picked;
}

}  // namespace

void RigidObservations::Append(const RigidObservations& more, double own_weight, double more_weight) {
  if (weight.size() < head.size()) weight.resize(head.size(), own_weight);
  head.insert(head.end(), more.head.begin(), more.head.end());
  observed.insert(observed.end(), more.observed.begin(), more.observed.end());
  for (size_t i = 0; i < more.head.size(); ++i) weight.push_back(i < more.weight.size() ? more.weight[i] : more_weight);
}

HeadFitter::HeadFitter(const HeadModel& model, const HeadFitterOptions& options) : model_(model), options_(options) {
  options.Check();
  num_expression_ =
      options.num_expression > 0 ? std::min(options.num_expression, model.num_expression()) : model.num_expression();
  // Once per fitter, not per frame: the names decide which coefficients the eyeLook prior weighs.
  const std::vector<std::string>& names = model.data().expression_names;
  expression_prior_weights_.assign(num_expression_, std::sqrt(options.expression_prior));
  auto starts = [](const std::string& name, const char* prefix) { return name.rfind(prefix, 0) == 0; };
  auto weighed = [&](const std::string& name) {
    return options.eye_look_prior_shapes == "vertical" ? starts(name, "eyeLookUp") || starts(name, "eyeLookDown")
                                                       : starts(name, "eyeLook");
  };
  for (int i = 0; i < num_expression_ && i < static_cast<int>(names.size()); ++i)
    if (weighed(names[i])) expression_prior_weights_[i] = std::sqrt(options.expression_prior + options.eye_look_prior);
  // The vertical eyeLook shapes of an articulated eye: each shape's side is
  // where it moves the mesh, and the look it stands for is the arc its
  // largest lid motion makes about the eye's pivot (the lid rides on the ball).
  const HeadModelData& d = model.data();
  for (int i = 0; i < num_expression_ && i < static_cast<int>(names.size()); ++i) {
    const bool up = starts(names[i], "eyeLookUp"), down = starts(names[i], "eyeLookDown");
    if (!up && !down) continue;
    double x_sum = 0, weight_sum = 0, largest = 0;
    for (int v = 0; v < model.num_vertices(); ++v) {
      const double moved = d.expressiondirs.block(3 * v, i, 3, 1).norm();
      x_sum += moved * d.v_template(v, 0);
      weight_sum += moved;
      largest = std::max(largest, moved);
    }
    const int joint = x_sum > 0 ? kLeftEyeJoint : kRightEyeJoint;  // the subject's left is +x
    const int pupil = model.PupilVertex(joint);
    if (weight_sum <= 0 || pupil < 0 || !model.JointIsArticulated(joint)) continue;
    const Eigen::Vector3d pivot = (d.j_regressor.row(joint) * d.v_template).transpose().cast<double>();
    const Eigen::Vector3d axis = d.v_template.row(pupil).transpose().cast<double>() - pivot;
    lid_gaze_.push_back(
        {i, joint, up ? 1.0 : -1.0, std::asin(std::min(1.0, largest / axis.norm())), axis.normalized()});
  }
  rigid_vertices_ = RigidHeadVertices(model, MakeBasis(PoseVector::Zero(), true).base, 64);
  SetIdentity(Eigen::VectorXd::Zero(model.num_shape()));
}

void HeadFitter::ProjectRigidPoints(const FrameParams& frame, const PinholeCamera& cam,
                                    const std::vector<Eigen::Vector3d>& head,
                                    std::vector<Eigen::Vector2d>* pixels) const {
  const Eigen::Matrix3d R = AxisAngleToMatrix(frame.cam_rotation.cast<double>());
  const Eigen::Vector3d t = frame.cam_translation.cast<double>();
  pixels->clear();
  for (const auto& p : head) pixels->push_back(cam.Project(R * p + t));
}

void HeadFitter::RigidPointsInView(const FrameParams& frame, const PinholeCamera& cam,
                                   std::vector<Eigen::Vector3d>* head, std::vector<Eigen::Vector2d>* pixels) const {
  head->clear();
  pixels->clear();
  const Eigen::Matrix3d R = AxisAngleToMatrix(frame.cam_rotation.cast<double>());
  const Eigen::Vector3d t = frame.cam_translation.cast<double>();
  for (size_t i = 0; i < rigid_vertices_.size(); ++i) {
    const Eigen::Vector3d p = identity_.v_shaped.segment<3>(3 * rigid_vertices_[i]).cast<double>();
    const Eigen::Vector3d x = R * p + t;
    const Eigen::Vector3d n = R * rigid_normals_.row(static_cast<Eigen::Index>(i)).transpose().cast<double>();
    if (x.z() <= 0 || n.dot(x.normalized()) > -0.3) continue;  // behind the camera, or seen edge-on or from behind
    const Eigen::Vector2d u = cam.Project(x);
    if (u.x() < 0 || u.y() < 0 || u.x() > cam.width - 1 || u.y() > cam.height - 1) continue;
    head->push_back(p);
    pixels->push_back(u);
  }
}

void HeadFitter::SetIdentity(const Eigen::VectorXd& shape) {
  identity_ = model_.MakeIdentity(shape);
  const RowMatrixX3f vertices = Eigen::Map<const RowMatrixX3f>(identity_.v_shaped.data(), model_.num_vertices(), 3);
  const RowMatrixX3f normals = model_.VertexNormals(vertices);
  rigid_normals_.resize(static_cast<Eigen::Index>(rigid_vertices_.size()), 3);
  for (size_t i = 0; i < rigid_vertices_.size(); ++i)
    rigid_normals_.row(static_cast<Eigen::Index>(i)) = normals.row(rigid_vertices_[i]);
}

HeadFitter::LandmarkBasis HeadFitter::MakeBasis(const PoseVector& pose, bool shape_free) const {
  LandmarkBasis b;
  Eigen::VectorXi faces;
  RowMatrixX3f bary;
  model_.LandmarkEmbedding(pose, &faces, &bary);
  const auto& d = model_.data();
  const int S = model_.num_shape();
  b.dirs.assign(kNumLandmarks, Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, num_expression_));
  if (shape_free) b.shape_dirs.assign(kNumLandmarks, Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, S));
  b.base.setZero();
  b.jaw_weight.setZero();
  for (int l = 0; l < kNumLandmarks; ++l)
    for (int k = 0; k < 3; ++k) {
      const int v = d.faces(faces[l], k);
      const double w = bary(l, k);
      if (w == 0) continue;
      if (shape_free) {
        b.base.row(l) += w * d.v_template.row(v).cast<double>();
        b.shape_dirs[l] += w * d.shapedirs.block(3 * v, 0, 3, S).cast<double>();
      } else {
        b.base.row(l) += w * identity_.v_shaped.segment<3>(3 * v).cast<double>().transpose();
      }
      b.dirs[l] += w * d.expressiondirs.block(3 * v, 0, 3, num_expression_).cast<double>();
      b.jaw_weight[l] += w * d.weights(v, kJawJoint);
    }
  b.jaw_joint = shape_free ? Eigen::Vector3d(model_.RestJoint(kJawJoint).cast<double>())
                           : Eigen::Vector3d(identity_.joints.row(kJawJoint).cast<double>().transpose());
  return b;
}

namespace {

// w_i * x_i for a whole parameter block, with its (diagonal) Jacobian.
class PriorCost : public ceres::CostFunction {
 public:
  PriorCost(int size, double weight) : PriorCost(std::vector<double>(size, weight)) {}
  explicit PriorCost(std::vector<double> weights) : weights_(std::move(weights)) {
    set_num_residuals(static_cast<int>(weights_.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(weights_.size()));
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const int n = num_residuals();
    for (int i = 0; i < n; ++i) residuals[i] = weights_[i] * x[0][i];
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + n * n, 0.0);
      for (int i = 0; i < n; ++i) jacobians[0][i * n + i] = weights_[i];
    }
    return true;
  }

 private:
  std::vector<double> weights_;
};

// w * (a - b) for two 3-blocks: the eyes turn together.
struct VergenceCost {
  explicit VergenceCost(double weight) : weight(weight) {}
  template <typename T>
  bool operator()(const T* a, const T* b, T* residual) const {
    for (int c = 0; c < 3; ++c) residual[c] = T(weight) * (a[c] - b[c]);
    return true;
  }
  double weight;
};

// Zero inside [lo, hi], weight * (distance outside) beyond: a soft box that
// keeps a blendshape model's coefficients where its shapes are faces without
// the bounded trust region's cost (about 3x the time per frame).
class RangeCost : public ceres::CostFunction {
 public:
  RangeCost(int size, double lo, double hi, double weight) : lo_(lo), hi_(hi), weight_(weight) {
    set_num_residuals(size);
    mutable_parameter_block_sizes()->push_back(size);
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const int n = num_residuals();
    for (int i = 0; i < n; ++i) residuals[i] = weight_ * (x[0][i] - std::clamp(x[0][i], lo_, hi_));
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + n * n, 0.0);
      for (int i = 0; i < n; ++i) jacobians[0][i * n + i] = x[0][i] < lo_ || x[0][i] > hi_ ? weight_ : 0.0;
    }
    return true;
  }

 private:
  double lo_, hi_, weight_;
};

// w * (the mean of n blocks of the same size), with its constant Jacobian.
class MeanCost : public ceres::CostFunction {
 public:
  MeanCost(int size, int blocks, double weight) : scale_(weight / blocks) {
    set_num_residuals(size);
    for (int b = 0; b < blocks; ++b) mutable_parameter_block_sizes()->push_back(size);
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const int n = num_residuals(), blocks = static_cast<int>(parameter_block_sizes().size());
    std::fill(residuals, residuals + n, 0.0);
    for (int b = 0; b < blocks; ++b)
      for (int i = 0; i < n; ++i) residuals[i] += scale_ * x[b][i];
    for (int b = 0; jacobians && b < blocks; ++b) {
      if (!jacobians[b]) continue;
      std::fill(jacobians[b], jacobians[b] + n * n, 0.0);
      for (int i = 0; i < n; ++i) jacobians[b][i * n + i] = scale_;
    }
    return true;
  }

 private:
  double scale_;
};

}  // namespace

void HeadFitter::AddLidGaze(ceres::Problem* problem, double* expression, double* left_eye, double* right_eye,
                            bool gaze_fitted) const {
  if (options_.lid_gaze_weight <= 0) return;
  for (const LidGaze& l : lid_gaze_) {
    double* eye = l.joint == kLeftEyeJoint ? left_eye : right_eye;
    problem->AddResidualBlock(
        new LidGazeCost(num_expression_, l.coefficient, l.axis, l.sign, l.radians, std::sqrt(options_.lid_gaze_weight)),
        nullptr, {expression, eye});
    // Without an iris this frame the gaze is held, and the lids follow the held one.
    if (!gaze_fitted) problem->SetParameterBlockConstant(eye);
  }
}

void HeadFitter::AddExpressionPriors(ceres::Problem* problem, double* expression) const {
  if (num_expression_ == 0) return;
  const HeadModelData& d = model_.data();
  problem->AddResidualBlock(new PriorCost(expression_prior_weights_), nullptr, expression);
  if (d.HasExpressionRange() && options_.expression_range_weight > 0)
    problem->AddResidualBlock(
        new RangeCost(num_expression_, d.expression_min, d.expression_max, std::sqrt(options_.expression_range_weight)),
        nullptr, expression);
}

bool HeadFitter::AddGaze(ceres::Problem* problem, const EyeIrises& irises, const PinholeCamera& cam, double* rotation,
                         double* translation, double* left_eye, double* right_eye) const {
  const int joints[2] = {kLeftEyeJoint, kRightEyeJoint};
  const IrisObservation* seen[2] = {&irises.left, &irises.right};
  double* eyes[2] = {left_eye, right_eye};
  bool any = false;
  for (int e = 0; e < 2; ++e) {
    const int pupil = model_.PupilVertex(joints[e]);
    if (!seen[e]->found || pupil < 0 || !seen[e]->center.allFinite()) continue;
    auto* cost = new ceres::AutoDiffCostFunction<PupilResidual, 2, 3, 3, 3>(new PupilResidual(
        identity_.v_shaped.segment<3>(3 * pupil).cast<double>(),
        identity_.joints.row(joints[e]).transpose().cast<double>(), seen[e]->center, cam, options_.iris_weight));
    problem->AddResidualBlock(cost, new ceres::HuberLoss(options_.huber_px), rotation, translation, eyes[e]);
    any = true;
  }
  if (!any) return false;
  const double g = std::sqrt(options_.gaze_prior), roll = std::sqrt(options_.eye_roll_weight);
  for (double* eye : eyes) problem->AddResidualBlock(new PriorCost({g, g, roll}), nullptr, eye);
  problem->AddResidualBlock(
      new ceres::AutoDiffCostFunction<VergenceCost, 3, 3, 3>(new VergenceCost(std::sqrt(options_.vergence_weight))),
      nullptr, left_eye, right_eye);
  return true;
}

bool HeadFitter::ProjectPupils(const FrameParams& frame, const PinholeCamera& cam, Eigen::Vector2d* left,
                               Eigen::Vector2d* right) const {
  const int joints[2] = {kLeftEyeJoint, kRightEyeJoint};
  const Eigen::Vector3f* rotations[2] = {&frame.left_eye, &frame.right_eye};
  Eigen::Vector2d* out[2] = {left, right};
  const Eigen::Matrix3d R = AxisAngleToMatrix(frame.cam_rotation.cast<double>());
  for (int e = 0; e < 2; ++e) {
    const int pupil = model_.PupilVertex(joints[e]);
    if (pupil < 0) return false;
    const Eigen::Vector3d joint = identity_.joints.row(joints[e]).transpose().cast<double>();
    const Eigen::Vector3d p = AxisAngleToMatrix(rotations[e]->cast<double>()) *
                                  (identity_.v_shaped.segment<3>(3 * pupil).cast<double>() - joint) +
                              joint;
    *out[e] = cam.Project(R * p + frame.cam_translation.cast<double>());
  }
  return true;
}

Landmarks2d HeadFitter::Project(const FrameParams& frame, const PinholeCamera& cam) const {
  const LandmarkBasis b = MakeBasis(frame.ViewPose());
  const Eigen::Matrix3d R = AxisAngleToMatrix(frame.cam_rotation.cast<double>());
  const Eigen::Matrix3d J = AxisAngleToMatrix(frame.jaw.cast<double>());
  Landmarks2d out;
  for (int l = 0; l < kNumLandmarks; ++l) {
    Eigen::Vector3d p = b.base.row(l).transpose();
    for (int k = 0; k < num_expression_ && k < frame.expression.size(); ++k)
      p += b.dirs[l].col(k) * frame.expression[k];
    if (b.jaw_weight[l] > 0) p = (1 - b.jaw_weight[l]) * p + b.jaw_weight[l] * (J * (p - b.jaw_joint) + b.jaw_joint);
    out[l] = cam.Project(R * p + frame.cam_translation.cast<double>());
  }
  return out;
}

LandmarkFitResult HeadFitter::Fit(const Landmarks2d& observed, const PinholeCamera& cam, FrameParams* frame,
                                  const EyeIrises* irises, const RigidObservations* rigid) const {
  if (frame->expression.size() != model_.num_expression())
    frame->expression = Eigen::VectorXf::Zero(model_.num_expression());
  const LandmarkBasis b = MakeBasis(frame->ViewPose());
  if (!(frame->cam_translation.z() > 0)) {
    // Initial pose from the rigid inner-face landmarks with OpenCV's PnP.
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (int l = 17; l < kNumLandmarks; ++l) {
      object.emplace_back(b.base(l, 0), b.base(l, 1), b.base(l, 2));
      image.emplace_back(observed[l].x(), observed[l].y());
    }
    cv::Mat K = (cv::Mat_<double>(3, 3) << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1), rvec, tvec;
    // Start in front of the camera, facing it (head y up -> camera y down).
    rvec = (cv::Mat_<double>(3, 1) << M_PI, 0, 0);
    tvec = (cv::Mat_<double>(3, 1) << 0, 0, 0.6);
    if (!cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE) ||
        tvec.at<double>(2) <= 0)
      return {};
    frame->cam_rotation = Eigen::Vector3f(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
    frame->cam_translation = Eigen::Vector3f(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  }
  double rotation[3], translation[3], jaw[3], left_eye[3], right_eye[3];
  for (int i = 0; i < 3; ++i) {
    rotation[i] = frame->cam_rotation[i];
    translation[i] = frame->cam_translation[i];
    jaw[i] = frame->jaw[i];
    left_eye[i] = frame->left_eye[i];
    right_eye[i] = frame->right_eye[i];
  }
  std::vector<double> expression(num_expression_);
  const double limit = options_.expression_limit;
  for (int k = 0; k < num_expression_; ++k) expression[k] = std::clamp<double>(frame->expression[k], -limit, limit);
  ceres::Problem problem;
  for (int l = 0; l < kNumLandmarks; ++l) {
    const double weight = l < kNumContourLandmarks ? options_.contour_weight : 1.0;
    auto* cost =
        new LandmarkCost(b.base.row(l).transpose(), b.dirs[l], b.jaw_weight[l], b.jaw_joint, observed[l], cam, weight);
    problem.AddResidualBlock(cost, new ceres::HuberLoss(options_.huber_px),
                             {rotation, translation, expression.data(), jaw});
  }
  if (rigid)
    for (size_t i = 0; i < rigid->head.size() && i < rigid->observed.size(); ++i) {
      const double weight = i < rigid->weight.size() ? rigid->weight[i] : options_.rigid_flow_weight;
      if (!(weight > 0)) continue;
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<RigidPointResidual, 2, 3, 3>(
                                   new RigidPointResidual(rigid->head[i], rigid->observed[i], cam, weight)),
                               new ceres::HuberLoss(options_.huber_px), rotation, translation);
    }
  AddExpressionPriors(&problem, expression.data());
  problem.AddResidualBlock(new PriorCost(3, std::sqrt(options_.jaw_prior)), nullptr, jaw);
  if (!model_.JointIsArticulated(kJawJoint)) problem.SetParameterBlockConstant(jaw);
  const bool gaze = irises && AddGaze(&problem, *irises, cam, rotation, translation, left_eye, right_eye);
  AddLidGaze(&problem, expression.data(), left_eye, right_eye, gaze);
  ceres::Solver::Options solver;
  // About 60 unknowns under a few hundred rows, held by priors: the normal
  // equations solve it faster than dense QR, to the same fits (bench/results/track_fitter_s81.json).
  solver.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  solver.max_num_iterations = options_.max_iterations;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  LandmarkFitResult r;
  r.iterations = static_cast<int>(summary.iterations.size());
  r.ok = summary.IsSolutionUsable() && translation[2] > 0;
  if (!r.ok) return r;
  // A frontal head is about pi from the camera; the solver may leave the angle
  // just beyond it. The same rotation with its angle in [0, pi] is what the
  // stream accepts (FrameParams::IsValid).
  const Eigen::Vector3d w =
      MatrixToAxisAngle(AxisAngleToMatrix(Eigen::Vector3d(rotation[0], rotation[1], rotation[2])));
  for (int i = 0; i < 3; ++i) {
    frame->cam_rotation[i] = static_cast<float>(w[i]);
    frame->cam_translation[i] = static_cast<float>(translation[i]);
    frame->jaw[i] = static_cast<float>(jaw[i]);
    if (gaze) {
      frame->left_eye[i] = static_cast<float>(left_eye[i]);
      frame->right_eye[i] = static_cast<float>(right_eye[i]);
    }
  }
  for (Eigen::Vector3f* eye : {&frame->left_eye, &frame->right_eye})
    if (eye->norm() > options_.max_gaze_rad) *eye *= static_cast<float>(options_.max_gaze_rad / eye->norm());
  // Clamped after the solve rather than bounded in it: Ceres' bounded trust
  // region made the per-frame fit ~3x slower (ICT, 53 components).
  for (int k = 0; k < num_expression_; ++k)
    frame->expression[k] = static_cast<float>(std::clamp(expression[k], -limit, limit));
  const Landmarks2d fitted = Project(*frame, cam);
  double sq = 0;
  for (int l = 0; l < kNumLandmarks; ++l) sq += (fitted[l] - observed[l]).squaredNorm();
  r.rms_px = std::sqrt(sq / kNumLandmarks);
  return r;
}

HeadFitter::Calibration HeadFitter::CalibrateIdentity(const std::vector<Landmarks2d>& key_frames,
                                                      const PinholeCamera& initial, std::vector<FrameParams>* frames,
                                                      bool known_focal) {
  Calibration result;
  const int S = model_.num_shape(), E = num_expression_;
  // Per-frame starts with the current identity.
  std::vector<FrameParams> params(key_frames.size());
  std::vector<bool> usable(key_frames.size(), false);
  for (size_t f = 0; f < key_frames.size(); ++f) {
    params[f].cam_translation.setZero();
    usable[f] = Fit(key_frames[f], initial, &params[f]).ok;
  }
  // Landmark bases relative to the template (MakeBasis with shape_free): shape is an unknown now.
  const Eigen::Matrix<double, 3, Eigen::Dynamic> jaw_shape_dirs = model_.JointShapeDirs(kJawJoint).cast<double>();
  Eigen::VectorXd shape = identity_.shape.cast<double>();
  if (shape.size() != S) shape = Eigen::VectorXd::Zero(S);
  double log_focal = 0;
  std::vector<std::array<double, 9>> pose(key_frames.size());  // rotation, translation, jaw
  std::vector<std::vector<double>> expression(key_frames.size(), std::vector<double>(std::max(E, 1), 0.0));
  ceres::Problem problem;
  for (size_t f = 0; f < key_frames.size(); ++f) {
    if (!usable[f]) continue;
    ++result.frames;
    for (int i = 0; i < 3; ++i) {
      pose[f][i] = params[f].cam_rotation[i];
      pose[f][3 + i] = params[f].cam_translation[i];
      pose[f][6 + i] = params[f].jaw[i];
    }
    for (int k = 0; k < E; ++k) expression[f][k] = params[f].expression[k];
    const LandmarkBasis b = MakeBasis(params[f].ViewPose(), /*shape_free=*/true);
    for (int l = 0; l < kNumLandmarks; ++l) {
      const double weight = l < kNumContourLandmarks ? options_.contour_weight : 1.0;
      auto* cost = new ceres::DynamicAutoDiffCostFunction<CalibrationResidual, 8>(
          new CalibrationResidual(b.base.row(l).transpose(), b.dirs[l], b.shape_dirs[l],
                                  model_.JointIsArticulated(kJawJoint) ? b.jaw_weight[l] : 0.0, b.jaw_joint,
                                  jaw_shape_dirs, key_frames[f][l], initial, weight));
      for (int size : {3, 3, std::max(E, 1), 3, S, 1}) cost->AddParameterBlock(size);
      cost->SetNumResiduals(2);
      problem.AddResidualBlock(
          cost, new ceres::HuberLoss(options_.huber_px),
          {pose[f].data(), pose[f].data() + 3, expression[f].data(), pose[f].data() + 6, shape.data(), &log_focal});
    }
    AddExpressionPriors(&problem, expression[f].data());
    problem.AddResidualBlock(new PriorCost(3, std::sqrt(options_.jaw_prior)), nullptr, pose[f].data() + 6);
    if (!model_.JointIsArticulated(kJawJoint)) problem.SetParameterBlockConstant(pose[f].data() + 6);
    if (E == 0) problem.SetParameterBlockConstant(expression[f].data());
  }
  if (result.frames < 2) return result;
  if (E > 0 && options_.calibration_mean_expression > 0) {
    std::vector<double*> blocks;
    for (size_t f = 0; f < key_frames.size(); ++f)
      if (usable[f]) blocks.push_back(expression[f].data());
    problem.AddResidualBlock(
        new MeanCost(E, result.frames, std::sqrt(options_.calibration_mean_expression * result.frames)), nullptr,
        blocks);
  }
  problem.AddResidualBlock(new PriorCost(S, std::sqrt(options_.shape_prior * kNumLandmarks * result.frames)), nullptr,
                           shape.data());
  problem.SetParameterLowerBound(&log_focal, 0, -std::log(options_.max_focal_change));
  problem.SetParameterUpperBound(&log_focal, 0, std::log(options_.max_focal_change));
  if (known_focal) problem.SetParameterBlockConstant(&log_focal);
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_SCHUR;
  solver.max_num_iterations = 100;
  solver.num_threads = 2;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  if (!summary.IsSolutionUsable()) return result;
  result.shape = shape;
  result.camera = initial;
  result.camera.fx *= std::exp(log_focal);
  result.camera.fy *= std::exp(log_focal);
  SetIdentity(shape);
  double sq = 0;
  int n = 0;
  for (size_t f = 0; f < key_frames.size(); ++f) {
    if (!usable[f]) continue;
    FrameParams& p = params[f];
    p.cam_rotation = Eigen::Vector3d(pose[f][0], pose[f][1], pose[f][2]).cast<float>();
    p.cam_translation = Eigen::Vector3d(pose[f][3], pose[f][4], pose[f][5]).cast<float>();
    p.jaw = Eigen::Vector3d(pose[f][6], pose[f][7], pose[f][8]).cast<float>();
    for (int k = 0; k < E; ++k) p.expression[k] = static_cast<float>(expression[f][k]);
    const Landmarks2d fitted = Project(p, result.camera);
    for (int l = 0; l < kNumLandmarks; ++l) sq += (fitted[l] - key_frames[f][l]).squaredNorm();
    n += kNumLandmarks;
  }
  result.rms_px = std::sqrt(sq / std::max(1, n));
  result.ok = true;
  if (frames) *frames = params;
  return result;
}

double LandmarkErrorIod(const Landmarks2d& a, const Landmarks2d& b) {
  double sum = 0;
  for (int l = 0; l < kNumLandmarks; ++l) sum += (a[l] - b[l]).norm();
  const double iod = (b[36] - b[45]).norm();
  return sum / kNumLandmarks / std::max(iod, 1e-9);
}

double LandmarkJitterIod(const Landmarks2d& before, const Landmarks2d& at, const Landmarks2d& after) {
  double sum = 0;
  for (int l = 0; l < kNumLandmarks; ++l) sum += (before[l] - 2 * at[l] + after[l]).norm();
  return sum / kNumLandmarks / std::max((at[36] - at[45]).norm(), 1e-9);
}

}  // namespace headcast
