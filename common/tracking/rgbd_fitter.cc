// RGB-D fitting on the mesh-fit machinery (same residuals, closest points and solver).
#include "common/tracking/rgbd_fitter.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "common/core/median.h"
#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/headmodel/params.h"
#include "common/tracking/mesh_fit_cost.h"

namespace headcast {

using namespace mesh_fit_internal;

void RgbdFitOptions::Check() const {
  OptionsCheck c("RgbdFitOptions");
  c.InRange("num_expression", num_expression, 0, 100000).NonNegative("landmark_weight", landmark_weight);
  c.Positive("point_weight", point_weight).Positive("max_point_distance_m", max_point_distance_m);
  c.Positive("robust_scale_m", robust_scale_m).InRange("block2_rounds", block2_rounds, 1, 100);
  c.InRange("block3_rounds", block3_rounds, 0, 100).InRange("cloud_points", cloud_points, 50, 10000000);
  c.InRange("shape_cloud_points", shape_cloud_points, 50, 10000000)
      .InRange("shape_solve_threads", shape_solve_threads, 1, 64);
  c.InRange("warm_rounds", warm_rounds, 1, 100).InRange("warm_max_iterations", warm_max_iterations, 1, 1000);
  c.NonNegative("cloud_margin_m", cloud_margin_m).Positive("head_depth_m", head_depth_m);
  c.Positive("contour_tolerance_m", contour_tolerance_m).NonNegative("shape_prior", shape_prior);
  c.NonNegative("contour_weight", contour_weight).InRange("accuracy_every", accuracy_every, 1, 1000);
  c.NonNegative("expression_prior", expression_prior).InRange("max_iterations", max_iterations, 1, 1000);
  c.ThrowIfErrors();
}

float DepthAt(const cv::Mat& depth_m, const Eigen::Vector2d& pixel, int radius) {
  const int u = static_cast<int>(std::lround(pixel.x())), v = static_cast<int>(std::lround(pixel.y()));
  std::vector<float> values;
  for (int y = std::max(0, v - radius); y <= std::min(depth_m.rows - 1, v + radius); ++y)
    for (int x = std::max(0, u - radius); x <= std::min(depth_m.cols - 1, u + radius); ++x) {
      const float z = depth_m.at<float>(y, x);
      if (z > 0 && std::isfinite(z)) values.push_back(z);
    }
  if (values.empty()) return 0.f;
  return MedianInPlace(values);
}

struct RgbdFitter::Impl {
  // With the shape fitted: shape and expression columns. With it frozen: the
  // identity folded into the mean, expression columns alone.
  std::unique_ptr<MeshBasis> basis;
  int ne = 0;
  Eigen::VectorXf nu;
  Eigen::VectorXd identity;
  std::unique_ptr<ClosestPointSearch> search;  // tracking: made once, then restricted to each frame's patch
  Impl(const HeadModel& model, int num_expression, bool fit_shape) : ne(num_expression) {
    nu = Eigen::VectorXf::Ones(model.num_vertices());
    identity = Eigen::VectorXd::Zero(model.num_shape());
    Rebuild(model, fit_shape);
  }
  void Rebuild(const HeadModel& model, bool fit_shape) {
    basis = fit_shape ? std::make_unique<MeshBasis>(model, model.num_shape(), ne)
                      : std::make_unique<MeshBasis>(model, 0, ne, identity);
  }
};

RgbdFitter::RgbdFitter(const HeadModel& model, const RgbdFitOptions& options) : model_(model), options_(options) {
  options.Check();
  const int ne =
      options.num_expression > 0 ? std::min(options.num_expression, model.num_expression()) : model.num_expression();
  impl_ = std::make_unique<Impl>(model, ne, options.fit_shape);
}

RgbdFitter::~RgbdFitter() = default;

void RgbdFitter::SetIdentity(const Eigen::VectorXd& shape) {
  if (shape.size() > model_.num_shape()) throw std::invalid_argument("SetIdentity: too many shape values");
  impl_->identity.setZero();
  impl_->identity.head(shape.size()) = shape;
  if (!options_.fit_shape) impl_->Rebuild(model_, false);
  impl_->search.reset();  // made anew, tight around the new identity
}

namespace {

// Organised point cloud from depth: points inside `box` and [z_near, z_far],
// every `stride` pixels, with normals from neighbouring pixels (toward the camera).
void BuildCloud(const cv::Mat& depth, const PinholeCamera& cam, const cv::Rect& box, float z_near, float z_far,
                int stride, RowMatrixX3f* points, RowMatrixX3f* normals) {
  std::vector<Eigen::Vector3f> p, n;
  auto at = [&](int x, int y, Eigen::Vector3f* out) {
    if (x < 0 || y < 0 || x >= depth.cols || y >= depth.rows) return false;
    const float z = depth.at<float>(y, x);
    if (!(z >= z_near && z <= z_far)) return false;
    *out = cam.Unproject(Eigen::Vector2d(x, y), z).cast<float>();
    return true;
  };
  for (int y = box.y; y < box.y + box.height; y += stride)
    for (int x = box.x; x < box.x + box.width; x += stride) {
      Eigen::Vector3f c, l, r, u, d;
      if (!at(x, y, &c)) continue;
      Eigen::Vector3f normal = Eigen::Vector3f::Zero();
      if (at(x - stride, y, &l) && at(x + stride, y, &r) && at(x, y - stride, &u) && at(x, y + stride, &d)) {
        normal = (r - l).cross(d - u);
        if (normal.norm() > 0) normal.normalize();
        if (normal.z() > 0) normal = -normal;  // facing the camera
        // Depth jumps (silhouettes, stereo edges) give grazing normals: no normal, point-to-point.
        const float spread = std::max({(r - l).norm(), (d - u).norm()});
        if (spread > 6.0f * stride * c.z() / static_cast<float>(cam.fx)) normal.setZero();
      }
      p.push_back(c);
      n.push_back(normal);
    }
  points->resize(static_cast<Eigen::Index>(p.size()), 3);
  normals->resize(static_cast<Eigen::Index>(p.size()), 3);
  for (size_t i = 0; i < p.size(); ++i) {
    points->row(static_cast<Eigen::Index>(i)) = p[i].transpose();
    normals->row(static_cast<Eigen::Index>(i)) = n[i].transpose();
  }
}

// The pixel stride that leaves about `target` of the box's depths within [z_near, z_far].
int CloudStride(const cv::Mat& depth, const cv::Rect& box, float z_near, float z_far, int target) {
  int valid = 0;
  for (int y = box.y; y < box.y + box.height; y += 2)
    for (int x = box.x; x < box.x + box.width; x += 2) {
      const float z = depth.at<float>(y, x);
      valid += z >= z_near && z <= z_far;
    }
  return std::clamp(static_cast<int>(std::lround(std::sqrt(4.0 * valid / target))), 1, 64);
}

}  // namespace

RgbdFitResult RgbdFitter::Fit(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera,
                              const RgbdFitResult* previous) {
  RgbdFitResult r;
  if (depth_m.empty() || depth_m.type() != CV_32FC1) {
    r.problem = "depth must be a CV_32F image in metres";
    return r;
  }
  if (depth_m.cols != camera.width || depth_m.rows != camera.height) {
    r.problem = "depth is " + std::to_string(depth_m.cols) + "x" + std::to_string(depth_m.rows) + ", the camera " +
                std::to_string(camera.width) + "x" + std::to_string(camera.height);
    return r;
  }
  const MeshBasis& basis = *impl_->basis;
  const int ns = basis.ns;  // 0 when the identity is folded into the basis
  // 1. 3D landmarks.
  std::array<Eigen::Vector3d, kNumLandmarks> lmk3d;
  std::array<bool, kNumLandmarks> has3d{};
  double u_lo = INFINITY, u_hi = -INFINITY, v_lo = INFINITY, v_hi = -INFINITY;
  float z_near = INFINITY;
  int inner = 0;
  for (int l = 0; l < kNumLandmarks; ++l) {
    const Eigen::Vector2d& p = landmarks[l];
    if (!p.allFinite()) continue;
    u_lo = std::min(u_lo, p.x());
    u_hi = std::max(u_hi, p.x());
    v_lo = std::min(v_lo, p.y());
    v_hi = std::max(v_hi, p.y());
    const float z = DepthAt(depth_m, p, 1);
    if (z <= 0) continue;
    lmk3d[l] = camera.Unproject(p, z);
    has3d[l] = true;
    if (l >= kNumContourLandmarks) {
      ++inner;
      z_near = std::min(z_near, z);
    }
  }
  if (inner < 6) {
    r.problem = "only " + std::to_string(inner) + " inner-face landmarks have depth";
    return r;
  }
  // 2. The face cloud: the landmarks' span (plus the forehead above the brows) and depth range.
  const double margin_px = options_.cloud_margin_m * camera.fx / z_near;
  const double forehead_px = 0.35 * (v_hi - v_lo);
  const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(u_lo - margin_px), static_cast<int>(v_lo - forehead_px)),
                                cv::Point(static_cast<int>(u_hi + margin_px), static_cast<int>(v_hi + margin_px))) &
                       cv::Rect(0, 0, depth_m.cols, depth_m.rows);
  const float z_lo = z_near - 0.03f, z_hi = z_near + static_cast<float>(options_.head_depth_m);
  const int target_points = options_.fit_shape ? options_.shape_cloud_points : options_.cloud_points;
  RowMatrixX3f cloud, cloud_normals;
  BuildCloud(depth_m, camera, box, z_lo, z_hi, CloudStride(depth_m, box, z_lo, z_hi, target_points), &cloud,
             &cloud_normals);
  r.cloud_points = static_cast<int>(cloud.rows());
  if (r.cloud_points < 50) {
    r.problem = "only " + std::to_string(r.cloud_points) + " depth points on the face";
    return r;
  }

  FitState st;
  st.coefficients = Eigen::VectorXd::Zero(basis.k);
  if (options_.fit_shape) st.coefficients.head(ns) = impl_->identity;
  SolveSettings settings;
  settings.loss = MeshLoss::kHuber;
  settings.loss_scale_m = options_.robust_scale_m;
  settings.shape_prior = options_.shape_prior;
  settings.expression_prior = options_.expression_prior;
  settings.max_iterations = options_.max_iterations;
  settings.batched = options_.batched_solve && !options_.fit_shape;
  // Tracking is one camera's work on one core (the other runs the receiver
  // of a call, or another camera); the identity's few frames may take both.
  settings.threads = options_.fit_shape ? options_.shape_solve_threads : 1;
  if (previous && previous->ok) settings.max_iterations = options_.warm_max_iterations;
  const bool jaw = model_.JointIsArticulated(kJawJoint);
  // The landmarks' faces and barycentrics for the current view (the dynamic contour follows it).
  auto embed = [&](Eigen::VectorXi* faces, RowMatrixX3f* bary) {
    PoseVector pose = PoseVector::Zero();
    pose.segment<3>(0) = ViewRotation(AxisAngleToMatrix(st.rotation));
    model_.LandmarkEmbedding(pose, faces, bary);
  };
  auto landmark_pairs = [&](bool contour, double weight) {
    Eigen::VectorXi faces;
    RowMatrixX3f bary;
    embed(&faces, &bary);
    std::vector<Correspondence> pairs;
    for (int l = contour ? 0 : kNumContourLandmarks; l < kNumLandmarks; ++l) {
      if (!has3d[l]) continue;
      Correspondence c;
      for (int k = 0; k < 3; ++k) c.vertices[k] = model_.data().faces(faces[l], k);
      c.bary = bary.row(l).cast<double>().transpose();
      c.count = 3;
      c.target = lmk3d[l];
      // Contour landmarks sit where the surface turns away: their depth is the least reliable.
      c.weight = l < kNumContourLandmarks ? options_.contour_weight * weight : weight;
      c.face = true;
      pairs.push_back(c);
    }
    return pairs;
  };

  // Block 1: pose (and jaw) from the inner 3D landmarks.
  if (previous && previous->ok) {
    st.coefficients.tail(basis.ne) = previous->params.expression.head(basis.ne);
    if (options_.fit_shape) st.coefficients.head(ns) = previous->params.shape;
    st.rotation = MatrixToAxisAngle(previous->rotation);
    st.translation = previous->translation;
    st.jaw = previous->params.pose.segment<3>(3 * kJawJoint);
  } else {
    HeadModelParams neutral;
    neutral.shape = impl_->identity;
    const HeadModelOutput rest = model_.Forward(neutral);
    std::vector<Eigen::Vector3d> from, to;
    for (int l = kNumContourLandmarks; l < kNumLandmarks; ++l)
      if (has3d[l]) {
        from.push_back(rest.landmarks.row(l).cast<double>().transpose());
        to.push_back(lmk3d[l]);
      }
    SetRigid(Umeyama(from, to, false), &st);
    st.log_scale = 0;
  }
  FreeBlocks pose_only = FreeBlocks::RigidOnly();
  pose_only.jaw = jaw;
  SolveOnce(basis, landmark_pairs(false, 1.0), settings, pose_only, &st);

  // The model where block 1 put it, and its landmarks for this view.
  const RowMatrixX3f posed_after_block1 = PoseAll(basis, st);
  Eigen::VectorXi landmark_faces;
  RowMatrixX3f landmark_bary;
  embed(&landmark_faces, &landmark_bary);

  // Contour landmarks whose depth disagrees with the posed model lie on the background.
  if (options_.reject_background_contour) {
    const RowMatrixX3f& posed = posed_after_block1;
    const Eigen::VectorXi& faces = landmark_faces;
    const RowMatrixX3f& bary = landmark_bary;
    for (int l = 0; l < kNumContourLandmarks; ++l) {
      if (!has3d[l]) continue;
      Eigen::Vector3d model_point = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k)
        model_point += bary(l, k) * posed.row(model_.data().faces(faces[l], k)).cast<double>().transpose();
      if (std::abs(model_point.z() - lmk3d[l].z()) > options_.contour_tolerance_m) {
        has3d[l] = false;
        ++r.contour_rejected;
      }
    }
  }

  // Closest points search the surface near the cloud only (the pose moves
  // little from here on: the reach allows for it).
  const SurfacePatch patch =
      PatchNear(model_, posed_after_block1, cloud.colwise().minCoeff().transpose(),
                cloud.colwise().maxCoeff().transpose(), static_cast<float>(2 * options_.max_point_distance_m + 0.02),
                std::vector<int>(landmark_faces.data(), landmark_faces.data() + landmark_faces.size()));

  // One search over the whole head serves every frame and round: its
  // hierarchy is refitted to each pose asked about (exact however the surface
  // moves), and each frame searches its own patch.
  if (!impl_->search) impl_->search = std::make_unique<ClosestPointSearch>(model_, posed_after_block1);
  impl_->search->Restrict(patch);
  const ClosestPointSearch& search = *impl_->search;

  // Block 2: landmarks + point-to-mesh over everything; block 3: points over shape.
  FreeBlocks all;
  all.shape = options_.fit_shape;
  all.jaw = jaw;
  FreeBlocks shape_only{options_.fit_shape, false, false, false, false};
  std::vector<Correspondence> points;
  const Eigen::VectorXf ones = Eigen::VectorXf::Ones(model_.num_vertices());
  const bool warm = previous && previous->ok;
  const int block2 = warm ? options_.warm_rounds : options_.block2_rounds;
  const int rounds = block2 + (options_.fit_shape ? options_.block3_rounds : 0);
  for (int round = 0; round < rounds; ++round) {
    const bool block3 = round >= block2;
    const double gate = options_.max_point_distance_m * (round == 0 && !warm ? 2.0 : 1.0);
    const RowMatrixX3f posed = PosePatch(basis, st, patch);
    points = search.Find(posed, cloud, cloud_normals, ones, impl_->nu, gate);
    if (points.size() < 50) {
      r.problem = "only " + std::to_string(points.size()) + " depth points near the model";
      return r;
    }
    for (auto& p : points) p.weight = options_.point_weight;
    std::vector<Correspondence> pairs = points;
    if (!block3 && options_.landmark_weight > 0) {
      // w1 * mean landmark term against w2 * mean point term.
      const int nl = static_cast<int>(std::count(has3d.begin(), has3d.end(), true));
      const auto lmk = landmark_pairs(true, options_.landmark_weight * points.size() / std::max(1, nl));
      pairs.insert(pairs.end(), lmk.begin(), lmk.end());
    }
    SolveOnce(basis, pairs, settings, block3 ? shape_only : all, &st);
  }
  const RowMatrixX3f posed = PosePatch(basis, st, patch);
  r.paired_points = static_cast<int>(points.size());  // in the last round
  // The accuracy: the distance of every n-th point to the final surface (fresh closest points).
  const int every = options_.accuracy_every;
  RowMatrixX3f sample((cloud.rows() + every - 1) / every, 3), sample_normals(sample.rows(), 3);
  for (Eigen::Index i = 0; i < sample.rows(); ++i) {
    sample.row(i) = cloud.row(i * every);
    sample_normals.row(i) = cloud_normals.row(i * every);
  }
  r.accuracy_m =
      MeasurePairs(posed, search.Find(posed, sample, sample_normals, ones, impl_->nu, options_.max_point_distance_m))
          .all_m;
  const auto lmk = landmark_pairs(true, 1.0);
  r.landmarks_3d = static_cast<int>(lmk.size());
  r.landmark_rmse_m = MeasurePairs(posed, lmk).all_m;
  r.params.shape = options_.fit_shape ? Eigen::VectorXd(st.coefficients.head(ns)) : impl_->identity;
  r.params.expression = Eigen::VectorXd::Zero(model_.num_expression());
  r.params.expression.head(basis.ne) = st.coefficients.segment(ns, basis.ne);
  r.params.pose.segment<3>(3 * kJawJoint) = st.jaw;
  r.rotation = AxisAngleToMatrix(st.rotation);
  r.translation = st.translation;
  r.ok = true;
  return r;
}

}  // namespace headcast
