// The mesh fit's model and residual, exposed for ceres::GradientChecker tests.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <vector>

#include "common/core/rotation.h"
#include "common/headmodel/head_model.h"
#include "common/tracking/mesh_fitter.h"

namespace headcast::mesh_fit_internal {

// The model with the root at rest, linear in the fitted coefficients
// c = (shape[0..S), expression[0..E)) except for the jaw rotation:
//   p_i = mean_i + dirs_i c,  J = jaw_mean + jaw_dirs c,
//   p'_i = p_i + P_i vec(R_jaw - I),  q_i = p'_i + w_i (R_jaw - I)(p'_i - J).
// With neck and eye rotations zero this is exactly HeadModel::Forward.
struct MeshBasis {
  int n = 0, ns = 0, ne = 0, k = 1;  // k >= 1: a zero column when nothing is fitted
  Eigen::VectorXd mean;              // 3N
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> dirs;  // 3N x k
  Eigen::Vector3d jaw_mean;
  Eigen::Matrix<double, 3, Eigen::Dynamic> jaw_dirs;                       // 3 x k
  Eigen::VectorXd jaw_weight;                                              // N
  Eigen::Matrix<double, Eigen::Dynamic, 9, Eigen::RowMajor> jaw_posedirs;  // 3N x 9, or empty

  // Unique per basis (addresses are reused), for CachedJaw.
  const uint64_t id = NextId();
  static uint64_t NextId() {
    static std::atomic<uint64_t> next{1};
    return next++;
  }

  // `folded_shape`: a known identity built into the mean (with num_shape 0:
  // tracking a calibrated person fits the expression alone, and each residual
  // costs a fraction of the full basis).
  MeshBasis(const HeadModel& model, int num_shape, int num_expression,
            const Eigen::VectorXd& folded_shape = Eigen::VectorXd())
      : n(model.num_vertices()) {
    const auto& d = model.data();
    ns = num_shape;
    ne = num_expression;
    k = std::max(1, ns + ne);
    mean = Eigen::Map<const Eigen::VectorXf>(d.v_template.data(), 3 * n).cast<double>();
    dirs.setZero(3 * n, k);
    if (ns > 0) dirs.leftCols(ns) = d.shapedirs.leftCols(ns).cast<double>();
    if (ne > 0) dirs.middleCols(ns, ne) = d.expressiondirs.leftCols(ne).cast<double>();
    jaw_mean = model.RestJoint(kJawJoint).cast<double>();
    jaw_dirs.setZero(3, k);
    if (ns > 0) jaw_dirs.leftCols(ns) = model.JointShapeDirs(kJawJoint).leftCols(ns).cast<double>();
    if (ne > 0) jaw_dirs.middleCols(ns, ne) = model.JointExpressionDirs(kJawJoint).leftCols(ne).cast<double>();
    if (folded_shape.size() > 0) {
      if (folded_shape.size() > model.num_shape()) throw std::invalid_argument("MeshBasis: too many shape values");
      const Eigen::Index s = folded_shape.size();
      mean += d.shapedirs.leftCols(s).cast<double>() * folded_shape;
      jaw_mean += model.JointShapeDirs(kJawJoint).leftCols(s).cast<double>() * folded_shape;
    }
    jaw_weight = d.weights.col(kJawJoint).cast<double>();
    if (model.has_posedirs()) jaw_posedirs = d.posedirs.middleCols(9 * (kJawJoint - 1), 9).cast<double>();
  }

  // q_i and, when asked, dq/dc (3 x k, accumulated with weight b) and dq/dtheta (3 x 3).
  struct Jaw {
    Eigen::Matrix3d R, RmI;
    std::array<Eigen::Matrix3d, 3> dR;
    Eigen::Vector3d joint;
    Eigen::Matrix<double, 3, Eigen::Dynamic> RmI_jaw_dirs;  // (R - I) jaw_dirs
  };
  // MakeJaw for the parameters of the current evaluation: every residual of a
  // Ceres iteration sees the same values, so each thread recomputes only when they change.
  const Jaw& CachedJaw(const double* c, const double* theta) const {
    thread_local uint64_t owner = 0;
    thread_local std::vector<double> key;
    thread_local Jaw cached;
    const size_t n = static_cast<size_t>(k) + 3;
    bool same = owner == id && key.size() == n;
    for (size_t i = 0; same && i < n; ++i) same = key[i] == (i < static_cast<size_t>(k) ? c[i] : theta[i - k]);
    if (!same) {
      cached = MakeJaw(c, theta);
      owner = id;
      key.assign(c, c + k);
      key.insert(key.end(), theta, theta + 3);
    }
    return cached;
  }
  Jaw MakeJaw(const double* c, const double* theta) const {
    Jaw j;
    j.R = AxisAngleToMatrix(Eigen::Vector3d(theta[0], theta[1], theta[2]), &j.dR);
    j.RmI = j.R - Eigen::Matrix3d::Identity();
    j.joint = jaw_mean + jaw_dirs * Eigen::Map<const Eigen::VectorXd>(c, k);
    j.RmI_jaw_dirs = j.RmI * jaw_dirs;
    return j;
  }
  void Vertex(int i, const double* c, const Jaw& jaw, double b, Eigen::Vector3d* q,
              Eigen::Matrix<double, 3, Eigen::Dynamic>* dq_dc, Eigen::Matrix3d* dq_dtheta) const {
    const auto Bi = dirs.middleRows(3 * i, 3);
    Eigen::Vector3d p = mean.segment<3>(3 * i) + Bi * Eigen::Map<const Eigen::VectorXd>(c, k);
    if (jaw_posedirs.rows() > 0) {
      const auto Pi = jaw_posedirs.middleRows(3 * i, 3);
      p += Pi *
           Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix<double, 3, 3, Eigen::RowMajor>(jaw.RmI).data());
    }
    const double w = jaw_weight[i];
    const Eigen::Vector3d u = p - jaw.joint;
    *q += b * (p + w * jaw.RmI * u);
    if (dq_dc) {
      const Eigen::Matrix3d A = Eigen::Matrix3d::Identity() + w * jaw.RmI;
      dq_dc->noalias() += b * (A * Bi - w * jaw.RmI_jaw_dirs);
    }
    if (dq_dtheta) {
      const Eigen::Matrix3d A = Eigen::Matrix3d::Identity() + w * jaw.RmI;
      for (int a = 0; a < 3; ++a) {
        Eigen::Vector3d col = w * jaw.dR[a] * u;
        if (jaw_posedirs.rows() > 0) {
          const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> dRa = jaw.dR[a];
          col += A * (jaw_posedirs.middleRows(3 * i, 3) * Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dRa.data()));
        }
        dq_dtheta->col(a) += b * col;
      }
    }
  }
};

// Parameter blocks of every residual: coefficients (k), root rotation (3),
// translation (3), log scale (1), jaw rotation (3).
enum Block { kCoefficients = 0, kRotation, kTranslation, kLogScale, kJaw };

// A point on the model surface (1..3 vertices with barycentric weights) and
// the target it is pulled to, with the metric that weighs the difference:
// identity for point-to-point; for closest points n n^T + e (I - n n^T) with
// the target's normal n, mostly point-to-plane, so the surface may slide along
// itself between rounds.
struct SurfacePoint {
  std::array<int, 3> vertices{};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  int count = 1;
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::Matrix3d metric = Eigen::Matrix3d::Identity();
  double scale = 1;  // multiplies the residual (the square root of a fixed weight)
};

// The parameter-dependent parts every point of one evaluation shares.
struct SurfaceFrame {
  const MeshBasis::Jaw* jaw = nullptr;
  Eigen::Matrix3d Rr;
  std::array<Eigen::Matrix3d, 3> dRr;
  double s = 1;
  static SurfaceFrame For(const MeshBasis& b, double const* const* p) {
    SurfaceFrame f;
    f.jaw = &b.CachedJaw(p[kCoefficients], p[kJaw]);
    // The root rotation and its derivatives, once per parameter state and thread.
    thread_local Eigen::Vector3d cached_w(NAN, NAN, NAN);
    thread_local Eigen::Matrix3d Rr;
    thread_local std::array<Eigen::Matrix3d, 3> dRr;
    const Eigen::Vector3d w(p[kRotation][0], p[kRotation][1], p[kRotation][2]);
    if (!(w == cached_w)) {
      Rr = AxisAngleToMatrix(w, &dRr);
      cached_w = w;
    }
    f.Rr = Rr;
    f.dRr = dRr;
    f.s = std::exp(p[kLogScale][0]);
    return f;
  }
};

// One point's 3 residuals, written at `residual`, and its Jacobian rows at
// `row` of each requested block (row-major, as Ceres lays them out).
inline void EvaluateSurfacePoint(const MeshBasis& b, const SurfaceFrame& f, const SurfacePoint& pt,
                                 double const* const* p, double* residual, double** jacobians, int row) {
  const bool want = jacobians != nullptr;
  const bool want_c = want && jacobians[kCoefficients], want_jaw = want && jacobians[kJaw];
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  thread_local Eigen::Matrix<double, 3, Eigen::Dynamic> dq_dc;
  Eigen::Matrix3d dq_dtheta = Eigen::Matrix3d::Zero();
  if (want_c) dq_dc.setZero(3, b.k);
  for (int v = 0; v < pt.count; ++v)
    b.Vertex(pt.vertices[v], p[kCoefficients], *f.jaw, pt.bary[v], &q, want_c ? &dq_dc : nullptr,
             want_jaw ? &dq_dtheta : nullptr);
  const Eigen::Vector3d x = f.s * f.Rr * q + Eigen::Map<const Eigen::Vector3d>(p[kTranslation]);
  const Eigen::Matrix3d M = pt.scale * pt.metric;
  Eigen::Map<Eigen::Vector3d> r(residual);
  r = M * (x - pt.target);
  if (!want) return;
  const Eigen::Matrix3d sR = f.s * M * f.Rr;
  if (want_c) {
    Eigen::Map<Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>> J(jacobians[kCoefficients] + 3 * row * b.k, 3,
                                                                            b.k);
    J = sR * dq_dc;
  }
  if (jacobians[kRotation]) {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> J(jacobians[kRotation] + 9 * row);
    for (int a = 0; a < 3; ++a) J.col(a) = f.s * M * f.dRr[a] * q;
  }
  if (jacobians[kTranslation])
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(jacobians[kTranslation] + 9 * row) = M;
  if (jacobians[kLogScale]) Eigen::Map<Eigen::Vector3d>(jacobians[kLogScale] + 3 * row) = sR * q;
  if (want_jaw) Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(jacobians[kJaw] + 9 * row) = sR * dq_dtheta;
}

// A point on the model surface minus its target point: 3 residuals, analytic Jacobians.
class SurfacePointCost final : public ceres::CostFunction {
 public:
  SurfacePointCost(const MeshBasis* basis, const std::array<int, 3>& vertices, const Eigen::Vector3d& bary, int count,
                   const Eigen::Vector3d& target, const Eigen::Matrix3d& metric = Eigen::Matrix3d::Identity())
      : basis_(basis) {
    point_ = {vertices, bary, count, target, metric, 1.0};
    set_num_residuals(3);
    *mutable_parameter_block_sizes() = {basis->k, 3, 3, 1, 3};
  }
  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    EvaluateSurfacePoint(*basis_, SurfaceFrame::For(*basis_, p), point_, p, residuals, jacobians, 0);
    return true;
  }

 private:
  const MeshBasis* basis_;
  SurfacePoint point_;
};

// Many surface points in one residual block: the same residuals and
// Jacobians as a SurfacePointCost each, without Ceres's cost per block (which
// dominates a solve of a thousand points). Weights are fixed (no loss function).
class SurfacePointsCost final : public ceres::CostFunction {
 public:
  SurfacePointsCost(const MeshBasis* basis, std::vector<SurfacePoint> points)
      : basis_(basis), points_(std::move(points)) {
    set_num_residuals(3 * static_cast<int>(points_.size()));
    *mutable_parameter_block_sizes() = {basis->k, 3, 3, 1, 3};
  }
  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const SurfaceFrame f = SurfaceFrame::For(*basis_, p);
    for (size_t i = 0; i < points_.size(); ++i)
      EvaluateSurfacePoint(*basis_, f, points_[i], p, residuals + 3 * i, jacobians, static_cast<int>(i));
    return true;
  }

 private:
  const MeshBasis* basis_;
  std::vector<SurfacePoint> points_;
};

// The fit's unknowns, stored as Ceres parameter blocks.
struct FitState {
  Eigen::VectorXd coefficients;
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero(), translation = Eigen::Vector3d::Zero(),
                  jaw = Eigen::Vector3d::Zero();
  double log_scale = 0;
};

// A target point and the model surface point (1..3 vertices) it pairs with.
struct Correspondence {
  std::array<int, 3> vertices{};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  int count = 1;
  Eigen::Vector3d target;
  Eigen::Matrix3d metric = Eigen::Matrix3d::Identity();
  double weight = 1;
  bool face = false;
};

struct SolveSettings {
  MeshLoss loss = MeshLoss::kNorm;
  double loss_scale_m = 5e-4;
  // Points in a few residual blocks, the robust loss as fixed weights taken at
  // the starting state (one reweighting step per solve): much cheaper per
  // iteration, for fits that solve again after new correspondences anyway.
  bool batched = false;
  double shape_prior = 1e-9, expression_prior = 1e-9, jaw_prior = 1e-9;
  int max_iterations = 50;
  int threads = 2;  // Ceres threads (at most the cores there are)
  static SolveSettings From(const MeshFitOptions& options);
};

// Which unknowns one solve may change.
struct FreeBlocks {
  bool shape = true, expression = true, rigid = true, jaw = true, scale = false;
  static FreeBlocks RigidOnly() { return {false, false, true, false, false}; }
};

// All model vertices posed by `state`, in the target's frame.
RowMatrixX3f PoseAll(const MeshBasis& basis, const FitState& state);
// The part of the surface a target can reach, so that closest points need not
// pose and search the whole head: the faces to search, the faces around their
// vertices (the vertex normals come out as over the whole mesh) and the
// vertices those touch.
struct SurfacePatch {
  std::vector<int> faces, normal_faces, vertices;
};
// Faces that can come within `reach` of a point in the box [lo, hi] (each
// face's centroid and size in `posed`), plus the faces holding `extra_faces`.
SurfacePatch PatchNear(const HeadModel& model, const RowMatrixX3f& posed, const Eigen::Vector3f& lo,
                       const Eigen::Vector3f& hi, float reach, const std::vector<int>& extra_faces = {});
// The patch's vertices posed by `state` (the other rows are zero).
RowMatrixX3f PosePatch(const MeshBasis& basis, const FitState& state, const SurfacePatch& patch);
// Closest point on triangle abc to p, as barycentrics.
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                   const Eigen::Vector3d& c);
// Closest points on the posed surface (all of it, or a patch), through a
// bounding-volume hierarchy over its faces. One search may serve several
// rounds of a fit while the surface moves: the hierarchy is made once and its
// boxes are refitted to each pose asked about, so the answer stays exact.
// Find refits the boxes: one search is not for several threads at once.
class ClosestPointSearch {
 public:
  ClosestPointSearch(const HeadModel& model, const RowMatrixX3f& posed, const SurfacePatch* patch = nullptr);
  ~ClosestPointSearch();
  ClosestPointSearch(const ClosestPointSearch&) = delete;
  ClosestPointSearch& operator=(const ClosestPointSearch&) = delete;
  // From now on only `patch`'s faces are searched (and its normal faces
  // give the normals). For a search made over the whole head: one hierarchy
  // then serves every frame of a sequence, each frame its own patch.
  void Restrict(const SurfacePatch& patch);
  // As ClosestPoints, on `posed` (the same model and patch, posed anew).
  std::vector<Correspondence> Find(const RowMatrixX3f& posed, const RowMatrixX3f& points,
                                   const RowMatrixX3f& point_normals, const Eigen::VectorXf& omega,
                                   const Eigen::VectorXf& nu, double max_distance) const;

 private:
  struct Tree;
  RowMatrixX3i faces_, around_;  // searched; whose vertex normals count
  bool whole_head_ = false;      // faces_ are the model's faces, in its order
  std::vector<char> active_;     // per face of faces_ (empty: all of them)
  std::unique_ptr<Tree> tree_;
};

// For every point: the closest point on the posed model surface within
// `max_distance`, mostly point-to-plane along the point's normal (when it has
// one), skipped when the surfaces face different ways.
std::vector<Correspondence> ClosestPoints(const HeadModel& model, const RowMatrixX3f& posed, const RowMatrixX3f& points,
                                          const RowMatrixX3f& point_normals, const Eigen::VectorXf& omega,
                                          const Eigen::VectorXf& nu, double max_distance,
                                          const SurfacePatch* patch = nullptr);
// One Ceres solve over `pairs` (weighted, robust loss, priors); returns the iterations used.
int SolveOnce(const MeshBasis& basis, const std::vector<Correspondence>& pairs, const SolveSettings& settings,
              const FreeBlocks& free, FitState* state);
struct PairRms {
  double all_m = 0, face_m = 0;
};
PairRms MeasurePairs(const RowMatrixX3f& posed, const std::vector<Correspondence>& pairs);
Eigen::Matrix4d Umeyama(const std::vector<Eigen::Vector3d>& from, const std::vector<Eigen::Vector3d>& to, bool scale);
void SetRigid(const Eigen::Matrix4d& T, FitState* state);

}  // namespace headcast::mesh_fit_internal
