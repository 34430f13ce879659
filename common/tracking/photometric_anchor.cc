#include "common/tracking/photometric_anchor.h"

#include <ceres/ceres.h>
#include <ceres/cubic_interpolation.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>

#include "common/core/median.h"
#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/tracking/landmark_costs.h"

namespace headcast {

cv::Mat AnchorGray(const cv::Mat& bgr, double blur_px) {
  cv::Mat gray;
  cv::cvtColor(bgr, gray, bgr.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  gray.convertTo(gray, CV_32F, 1.0 / 255);
  if (blur_px > 0) cv::GaussianBlur(gray, gray, cv::Size(0, 0), blur_px);
  return gray;
}

namespace {

using Image = ceres::BiCubicInterpolator<ceres::Grid2D<float, 1>>;

// Weight of a point's pull toward where the landmarks' fit put it, grey
// levels per pixel: well below a smooth skin's grey-level slope, so that it
// only decides what the grey levels leave open.
constexpr double kLandmarkPull = 5e-5;
// The largest median absolute deviation of a point's grey level over the clip for it to be a reference.
constexpr float kMaxDeviation = 0.06f;

// A point's grey level at its projection, through the frame's gain and bias, against its reference.
struct AnchorResidual {
  AnchorResidual(const Image* image, const Eigen::Vector3d& point, double reference, const PinholeCamera& cam)
      : image(image), point(point), reference(reference), cam(cam) {}
  template <typename T>
  bool operator()(const T* rotation, const T* translation, const T* light, T* residual) const {
    const T p[3] = {T(point.x()), T(point.y()), T(point.z())};
    T x[3];
    ceres::AngleAxisRotatePoint(rotation, p, x);
    for (int c = 0; c < 3; ++c) x[c] += translation[c];
    if (!(x[2] > T(1e-3))) return false;
    const T u = T(cam.fx) * x[0] / x[2] + T(cam.cx), v = T(cam.fy) * x[1] / x[2] + T(cam.cy);
    T grey;
    image->Evaluate(v, u, &grey);
    residual[0] = light[0] * grey + light[1] - T(reference);
    return true;
  }
  const Image* image;
  Eigen::Vector3d point;
  double reference;
  PinholeCamera cam;
};

double Bilinear(const cv::Mat& gray, const Eigen::Vector2d& u) {
  const int x = static_cast<int>(std::floor(u.x())), y = static_cast<int>(std::floor(u.y()));
  const double fx = u.x() - x, fy = u.y() - y;
  const float* r0 = gray.ptr<float>(y);
  const float* r1 = gray.ptr<float>(y + 1);
  return (1 - fy) * ((1 - fx) * r0[x] + fx * r0[x + 1]) + fy * ((1 - fx) * r1[x] + fx * r1[x + 1]);
}

bool Inside(const cv::Mat& gray, const Eigen::Vector2d& u) {
  return u.x() >= 1 && u.y() >= 1 && u.x() < gray.cols - 2 && u.y() < gray.rows - 2;
}

// The i-th point of the 2D Halton sequence (bases 2 and 3).
Eigen::Vector2d Halton(int i) {
  Eigen::Vector2d h(0, 0);
  const int bases[2] = {2, 3};
  for (int d = 0; d < 2; ++d) {
    double f = 1;
    for (int n = i + 1; n > 0; n /= bases[d]) {
      f /= bases[d];
      h[d] += f * (n % bases[d]);
    }
  }
  return h;
}

}  // namespace

PhotometricAnchor::PhotometricAnchor(const HeadModel& model, const Eigen::VectorXd& shape,
                                     const PhotometricAnchorOptions& options)
    : options_(options) {
  options.Check();
  const HeadIdentity identity = model.MakeIdentity(shape);
  const RowMatrixX3f rest = Eigen::Map<const RowMatrixX3f>(identity.v_shaped.data(), model.num_vertices(), 3);
  // The face above the nose's base (landmark 33): forehead, brows, lids,
  // nose, temples, crown; not the mouth and jaw, whose pictures change most
  // with the expression, nor the neck under the chin (the chin's shadow). A
  // forehead alone is too often hair (a fringe that lifts with the brows).
  // The points follow the frame's expression; those whose grey level still
  // comes and goes (lids, hair) are left out by Reference.
  const HeadModelOutput rest_out = model.Forward(HeadModelParams{});
  const float floor = rest_out.landmarks(33, 1);
  const HeadModelData& d = model.data();
  auto usable = [&](int v) {
    return d.weights(v, kJawJoint) == 0 && d.weights(v, kLeftEyeJoint) == 0 && d.weights(v, kRightEyeJoint) == 0 &&
           rest(v, 1) >= floor;
  };
  const RowMatrixX3i& faces = model.data().faces;
  std::vector<int> triangles;
  std::vector<double> cumulative_area;
  double total = 0;
  for (int f = 0; f < faces.rows(); ++f) {
    if (!usable(faces(f, 0)) || !usable(faces(f, 1)) || !usable(faces(f, 2))) continue;
    const Eigen::Vector3f a = rest.row(faces(f, 0)), b = rest.row(faces(f, 1)), c = rest.row(faces(f, 2));
    const Eigen::Vector3f n = (b - a).cross(c - a);
    const double area = 0.5 * n.norm();
    if (area <= 0 || n.z() < 0.3f * n.norm()) continue;  // facing forward at rest
    triangles.push_back(f);
    total += area;
    cumulative_area.push_back(total);
  }
  if (triangles.empty()) return;
  for (int k = 0; k < options.points; ++k) {
    const double at = (k + 0.5) / options.points * total;
    const size_t t = std::lower_bound(cumulative_area.begin(), cumulative_area.end(), at) - cumulative_area.begin();
    const int f = triangles[std::min(t, triangles.size() - 1)];
    // A uniform point of the triangle from a low-discrepancy pair.
    const Eigen::Vector2d h = Halton(k);
    const double s = std::sqrt(h.x());
    const double wa = 1 - s, wb = s * (1 - h.y()), wc = s * h.y();
    const Eigen::Vector3d a = rest.row(faces(f, 0)).cast<double>().transpose();
    const Eigen::Vector3d b = rest.row(faces(f, 1)).cast<double>().transpose();
    const Eigen::Vector3d c = rest.row(faces(f, 2)).cast<double>().transpose();
    points_.push_back(wa * a + wb * b + wc * c);
    normals_.push_back((b - a).cross(c - a).normalized());
    const int E = model.num_expression();
    const Eigen::MatrixXd corner_dirs[3] = {d.expressiondirs.middleRows(3 * faces(f, 0), 3).cast<double>(),
                                            d.expressiondirs.middleRows(3 * faces(f, 1), 3).cast<double>(),
                                            d.expressiondirs.middleRows(3 * faces(f, 2), 3).cast<double>()};
    dirs_.push_back(E > 0 ? Eigen::MatrixXd(wa * corner_dirs[0] + wb * corner_dirs[1] + wc * corner_dirs[2])
                          : Eigen::MatrixXd::Zero(3, 0));
  }
  reference_.assign(points_.size(), std::numeric_limits<double>::quiet_NaN());
  seen_.resize(points_.size());
}

Eigen::Vector3d PhotometricAnchor::At(int i, const FrameParams& frame) const {
  const Eigen::Index n = std::min<Eigen::Index>(dirs_[i].cols(), frame.expression.size());
  if (n == 0) return points_[i];
  return points_[i] + dirs_[i].leftCols(n) * frame.expression.head(n).cast<double>();
}

std::vector<int> PhotometricAnchor::Visible(const FrameParams& frame, const PinholeCamera& camera) const {
  const RigidTransform cam_from_head = frame.CamFromHead();
  std::vector<int> visible;
  for (size_t i = 0; i < points_.size(); ++i) {
    const Eigen::Vector3d x = cam_from_head.Apply(At(static_cast<int>(i), frame));
    // Facing the camera within 60 degrees: nearer the outline the blur mixes in the background.
    if (x.z() <= 0 || (cam_from_head.rotation * normals_[i]).dot(x.normalized()) > -0.5) continue;
    visible.push_back(static_cast<int>(i));
  }
  return visible;
}

void PhotometricAnchor::Observe(const cv::Mat& gray, const FrameParams& frame, const PinholeCamera& camera) {
  ++observed_frames_;
  const RigidTransform cam_from_head = frame.CamFromHead();
  for (int i : Visible(frame, camera)) {
    const Eigen::Vector2d u = camera.Project(cam_from_head.Apply(At(i, frame)));
    if (Inside(gray, u)) seen_[i].push_back(static_cast<float>(Bilinear(gray, u)));
  }
}

int PhotometricAnchor::Reference(double min_share) {
  int referenced = 0;
  for (size_t i = 0; i < points_.size(); ++i) {
    std::vector<float>& s = seen_[i];
    reference_[i] = std::numeric_limits<double>::quiet_NaN();
    if (s.empty() || s.size() < min_share * observed_frames_) {
      s.clear();
      continue;
    }
    const float median = MedianInPlace(s);
    // A point whose grey level comes and goes (hair falling over it, an
    // occluding ear, the outline) says nothing steady about the head's place.
    for (float& v : s) v = std::abs(v - median);
    if (MedianInPlace(s) <= kMaxDeviation) {
      reference_[i] = median;
      ++referenced;
    }
    s.clear();
  }
  observed_frames_ = 0;
  return referenced;
}

void PhotometricAnchor::SetReference(const std::vector<double>& grey) {
  if (grey.size() != points_.size())
    throw std::invalid_argument("photometric anchor: " + std::to_string(grey.size()) + " references for " +
                                std::to_string(points_.size()) + " points");
  reference_ = grey;
}

AnchorAlignment PhotometricAnchor::Align(const cv::Mat& gray, const PinholeCamera& camera, FrameParams* frame) const {
  AnchorAlignment a;
  CV_Assert(gray.type() == CV_32F && gray.isContinuous());
  const RigidTransform start = frame->CamFromHead();
  std::vector<int> used;
  std::vector<Eigen::Vector3d> head;  // at the frame's expression, held through the alignment
  std::vector<Eigen::Vector2d> start_px;
  for (int i : Visible(*frame, camera)) {
    const Eigen::Vector3d p = At(i, *frame);
    const Eigen::Vector2d u = camera.Project(start.Apply(p));
    if (std::isnan(reference_[i]) || !Inside(gray, u)) continue;
    used.push_back(i);
    head.push_back(p);
    start_px.push_back(u);
  }
  a.points = static_cast<int>(used.size());
  if (a.points < kMinAlignPoints) return a;
  // The light first: gain and bias by least squares at the starting pose.
  Eigen::MatrixX2d design(a.points, 2);
  Eigen::VectorXd target(a.points);
  for (int k = 0; k < a.points; ++k) {
    design(k, 0) = Bilinear(gray, start_px[k]);
    design(k, 1) = 1;
    target(k) = reference_[used[k]];
  }
  Eigen::Vector2d light = design.colPivHouseholderQr().solve(target);
  if (!light.allFinite() || light.x() <= 0.2 || light.x() > 5) light = Eigen::Vector2d(1, 0);
  a.rms_before = std::sqrt((design * light - target).squaredNorm() / a.points);

  const ceres::Grid2D<float, 1> grid(gray.ptr<float>(), 0, gray.rows, 0, gray.cols);
  const Image image(grid);
  double rotation[3], translation[3];
  for (int c = 0; c < 3; ++c) {
    rotation[c] = frame->cam_rotation[c];
    translation[c] = frame->cam_translation[c];
  }
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::HuberLoss huber(options_.huber);
  for (int k = 0; k < a.points; ++k) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<AnchorResidual, 1, 3, 3, 2>(
                                 new AnchorResidual(&image, head[k], reference_[used[k]], camera)),
                             &huber, rotation, translation, light.data());
    // A weak pull toward the landmarks' placement: directions the points do
    // not see (the forehead is nearly flat) stay where the landmarks put them.
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<RigidPointResidual, 2, 3, 3>(
                                 new RigidPointResidual(head[k], start_px[k], camera, kLandmarkPull)),
                             nullptr, rotation, translation);
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 30;
  so.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) return a;
  FrameParams aligned = *frame;
  aligned.cam_rotation = Eigen::Map<Eigen::Vector3d>(rotation).cast<float>();
  aligned.cam_translation = Eigen::Map<Eigen::Vector3d>(translation).cast<float>();
  const RigidTransform end = aligned.CamFromHead();
  double shift = 0, sq = 0;
  int inside = 0;
  for (int k = 0; k < a.points; ++k) {
    const Eigen::Vector2d u = camera.Project(end.Apply(head[k]));
    shift += (u - start_px[k]).norm();
    if (!Inside(gray, u)) continue;
    const double r = light.x() * Bilinear(gray, u) + light.y() - reference_[used[k]];
    sq += r * r;
    ++inside;
  }
  a.shift_px = shift / a.points;
  a.rms_after = inside > 0 ? std::sqrt(sq / inside) : a.rms_before;
  a.ok = aligned.cam_translation.allFinite() && aligned.cam_rotation.allFinite() && aligned.cam_translation.z() > 0;
  if (a.ok) *frame = aligned;
  return a;
}

bool PhotometricAnchor::Refit(const cv::Mat& gray, const Landmarks2d& landmarks, const EyeIrises* irises, double iod,
                              const PinholeCamera& camera, const HeadFitter& fitter, FrameParams* frame,
                              AnchorAlignment* alignment, const RigidObservations* more) const {
  FrameParams aligned = *frame;
  *alignment = Align(gray, camera, &aligned);
  if (alignment->ok && alignment->shift_px > options_.max_shift_iod * iod) alignment->ok = false;
  if (!alignment->ok) return false;
  RigidObservations rigid = Observations(aligned, camera, options_.fit_points);
  if (more) rigid.Append(*more, options_.weight, options_.weight);
  FrameParams refit = *frame;
  if (!fitter.Fit(landmarks, camera, &refit, irises, &rigid).ok) return false;
  *frame = refit;
  return true;
}

RigidObservations PhotometricAnchor::Observations(const FrameParams& frame, const PinholeCamera& camera,
                                                  int count) const {
  std::vector<int> usable;
  const RigidTransform cam_from_head = frame.CamFromHead();
  for (int i : Visible(frame, camera))
    if (!std::isnan(reference_[i])) usable.push_back(i);
  RigidObservations o;
  const size_t n = std::min<size_t>(usable.size(), static_cast<size_t>(std::max(count, 0)));
  for (size_t k = 0; k < n; ++k) {
    const int i = usable[k * usable.size() / n];
    o.head.push_back(At(i, frame));
    o.observed.push_back(camera.Project(cam_from_head.Apply(o.head.back())));
  }
  return o;
}

}  // namespace headcast
