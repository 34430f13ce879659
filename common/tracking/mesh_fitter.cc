// Fitting the head model to a polygonal head: weighted residual, analytic
// Jacobians in Ceres, closest points through a bounding-volume hierarchy for other topologies.
#include "common/tracking/mesh_fitter.h"

#include <ceres/ceres.h>
#include <ceres/normal_prior.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <thread>

#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/tracking/mesh_fit_cost.h"

namespace headcast {

void MeshFitOptions::Check() const {
  OptionsCheck c("MeshFitOptions");
  c.InRange("num_shape", num_shape, 0, 100000).InRange("num_expression", num_expression, 0, 100000);
  c.Positive("loss_scale_m", loss_scale_m).NonNegative("shape_prior", shape_prior);
  c.NonNegative("expression_prior", expression_prior).NonNegative("jaw_prior", jaw_prior);
  c.InRange("max_iterations", max_iterations, 1, 10000).InRange("closest_point_rounds", closest_point_rounds, 1, 1000);
  c.Positive("max_correspondence_m", max_correspondence_m);
  for (const auto& [index, point] : target_landmarks) {
    c.InRange("target_landmarks index", index, 0, kNumLandmarks - 1);
    c.That(point.allFinite(), "target_landmarks: landmark " + std::to_string(index) + " is not finite");
  }
  c.That(importance.allFinite(), "importance has non-finite values");
  c.That(importance.size() == 0 || importance.minCoeff() >= 0, "importance has negative values");
  c.ThrowIfErrors();
}

void BlackBoxFitOptions::Check() const {
  OptionsCheck c("BlackBoxFitOptions");
  c.Positive("step", step).Positive("loss_scale_m", loss_scale_m).NonNegative("prior", prior);
  c.InRange("reweight_rounds", reweight_rounds, 1, 1000).InRange("max_iterations", max_iterations, 1, 10000);
  c.ThrowIfErrors();
}

namespace mesh_fit_internal {

// All model vertices posed by `state`, in the mesh frame.
namespace {

template <class EachVertex>
RowMatrixX3f Pose(const MeshBasis& b, const FitState& st, EachVertex each) {
  const MeshBasis::Jaw jaw = b.MakeJaw(st.coefficients.data(), st.jaw.data());
  const Eigen::Matrix3d sR = std::exp(st.log_scale) * AxisAngleToMatrix(st.rotation);
  RowMatrixX3f out = RowMatrixX3f::Zero(b.n, 3);
  each([&](int i) {
    Eigen::Vector3d q = Eigen::Vector3d::Zero();
    b.Vertex(i, st.coefficients.data(), jaw, 1.0, &q, nullptr, nullptr);
    out.row(i) = (sR * q + st.translation).cast<float>().transpose();
  });
  return out;
}

}  // namespace

RowMatrixX3f PoseAll(const MeshBasis& b, const FitState& st) {
  return Pose(b, st, [&](auto pose) {
    for (int i = 0; i < b.n; ++i) pose(i);
  });
}

RowMatrixX3f PosePatch(const MeshBasis& b, const FitState& st, const SurfacePatch& patch) {
  return Pose(b, st, [&](auto pose) {
    for (int i : patch.vertices) pose(i);
  });
}

namespace {

// Each face's bounding sphere in `posed`: its centroid and (when asked) the
// distance to its farthest corner.
void FaceSpheres(const RowMatrixX3i& faces, const RowMatrixX3f& posed, RowMatrixX3f* centroids,
                 std::vector<float>* radius = nullptr) {
  centroids->resize(faces.rows(), 3);
  if (radius) radius->resize(faces.rows());
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::RowVector3f c = (posed.row(faces(f, 0)) + posed.row(faces(f, 1)) + posed.row(faces(f, 2))) / 3;
    centroids->row(f) = c;
    if (radius)
      (*radius)[f] = std::max({(posed.row(faces(f, 0)) - c).norm(), (posed.row(faces(f, 1)) - c).norm(),
                               (posed.row(faces(f, 2)) - c).norm()});
  }
}

}  // namespace

SurfacePatch PatchNear(const HeadModel& model, const RowMatrixX3f& posed, const Eigen::Vector3f& lo,
                       const Eigen::Vector3f& hi, float reach, const std::vector<int>& extra_faces) {
  const auto& faces = model.data().faces;
  SurfacePatch patch;
  std::vector<char> searched(faces.rows(), 0), touched(posed.rows(), 0);
  RowMatrixX3f centroids;
  std::vector<float> radius;
  FaceSpheres(faces, posed, &centroids, &radius);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3f c = centroids.row(f).transpose();
    // Distance from the centroid to the box: the face can reach the box only within its own radius of it.
    const float d = (c.cwiseMax(lo) - c).cwiseMax(c - c.cwiseMin(hi)).cwiseMax(0.f).norm();
    if (d <= reach + radius[f]) searched[f] = 1;
  }
  for (int f : extra_faces) searched[f] = 1;
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    if (searched[f]) {
      patch.faces.push_back(static_cast<int>(f));
      for (int k = 0; k < 3; ++k) touched[faces(f, k)] = 1;
    }
  std::vector<char> posed_vertex(posed.rows(), 0);
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    if (touched[faces(f, 0)] || touched[faces(f, 1)] || touched[faces(f, 2)]) {
      patch.normal_faces.push_back(static_cast<int>(f));
      for (int k = 0; k < 3; ++k) posed_vertex[faces(f, k)] = 1;
    }
  for (Eigen::Index i = 0; i < posed.rows(); ++i)
    if (posed_vertex[i]) patch.vertices.push_back(static_cast<int>(i));
  return patch;
}

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5), as barycentrics.
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                   const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = 1 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

// A bounding-volume hierarchy over the searched faces. Its shape (which faces
// share a node) is made once, by median splits where the faces are at
// construction; its boxes are refitted to every pose a search is asked
// about, so each answer is exact however far the surface has moved since.
struct ClosestPointSearch::Tree {
  static constexpr int kLeafFaces = 4;
  struct Node {
    Eigen::AlignedBox3f box;
    int first = 0, count = 0;  // a leaf: order[first, first + count)
    int right = 0;             // an inner node: children at index + 1 and `right`
  };
  std::vector<Node> nodes;  // depth first: children after their parent
  std::vector<int> order;   // face indices, leaves' faces contiguous

  int Build(const RowMatrixX3f& centroids, int first, int count) {
    const int index = static_cast<int>(nodes.size());
    nodes.emplace_back();
    if (count <= kLeafFaces) {
      nodes[index].first = first;
      nodes[index].count = count;
      return index;
    }
    Eigen::AlignedBox3f spread;
    for (int i = first; i < first + count; ++i) spread.extend(centroids.row(order[i]).transpose());
    int axis = 0;
    spread.sizes().maxCoeff(&axis);
    const auto begin = order.begin() + first, mid = begin + count / 2, end = begin + count;
    std::nth_element(begin, mid, end, [&](int a, int b) { return centroids(a, axis) < centroids(b, axis); });
    Build(centroids, first, count / 2);
    const int right = Build(centroids, first + count / 2, count - count / 2);
    nodes[index].right = right;
    return index;
  }

  // Boxes around the active faces (all when `active` is empty) where `posed` puts them.
  void Refit(const RowMatrixX3i& faces, const RowMatrixX3f& posed, const std::vector<char>& active) {
    for (int i = static_cast<int>(nodes.size()) - 1; i >= 0; --i) {
      Node& n = nodes[i];
      n.box.setEmpty();
      if (n.count > 0) {
        for (int k = n.first; k < n.first + n.count; ++k)
          if (active.empty() || active[order[k]])
            for (int v = 0; v < 3; ++v) n.box.extend(posed.row(faces(order[k], v)).transpose());
      } else {
        n.box = nodes[i + 1].box.merged(nodes[n.right].box);
      }
    }
  }
};

ClosestPointSearch::ClosestPointSearch(const HeadModel& model, const RowMatrixX3f& posed, const SurfacePatch* patch)
    : tree_(std::make_unique<Tree>()) {
  const auto& all_faces = model.data().faces;
  if (patch) {
    faces_.resize(static_cast<Eigen::Index>(patch->faces.size()), 3);
    for (size_t f = 0; f < patch->faces.size(); ++f)
      faces_.row(static_cast<Eigen::Index>(f)) = all_faces.row(patch->faces[f]);
    around_.resize(static_cast<Eigen::Index>(patch->normal_faces.size()), 3);
    for (size_t f = 0; f < patch->normal_faces.size(); ++f)
      around_.row(static_cast<Eigen::Index>(f)) = all_faces.row(patch->normal_faces[f]);
  } else {
    faces_ = all_faces;
    around_ = all_faces;
    whole_head_ = true;
  }
  if (faces_.rows() == 0) return;
  RowMatrixX3f centroids;
  FaceSpheres(faces_, posed, &centroids);
  tree_->order.resize(static_cast<size_t>(faces_.rows()));
  for (Eigen::Index f = 0; f < faces_.rows(); ++f) tree_->order[static_cast<size_t>(f)] = static_cast<int>(f);
  tree_->nodes.reserve(static_cast<size_t>(4 * faces_.rows() / Tree::kLeafFaces + 1));
  tree_->Build(centroids, 0, static_cast<int>(faces_.rows()));
}

ClosestPointSearch::~ClosestPointSearch() = default;

void ClosestPointSearch::Restrict(const SurfacePatch& patch) {
  if (!whole_head_) throw std::logic_error("ClosestPointSearch::Restrict: the search was made over a patch");
  active_.assign(static_cast<size_t>(faces_.rows()), 0);
  for (int f : patch.faces) active_.at(static_cast<size_t>(f)) = 1;
  around_.resize(static_cast<Eigen::Index>(patch.normal_faces.size()), 3);
  for (size_t f = 0; f < patch.normal_faces.size(); ++f)
    around_.row(static_cast<Eigen::Index>(f)) = faces_.row(patch.normal_faces[f]);
}

// For every target point: the closest point on the posed model surface within
// max_distance. Branch and bound down the hierarchy, nearer child first: a
// node whose box lies farther than the best face so far cannot hold a closer
// one -- the same answer as measuring every face, at a few box and triangle
// tests per point.
std::vector<Correspondence> ClosestPointSearch::Find(const RowMatrixX3f& posed, const RowMatrixX3f& points,
                                                     const RowMatrixX3f& point_normals, const Eigen::VectorXf& omega,
                                                     const Eigen::VectorXf& nu, double max_distance) const {
  // Mostly point-to-plane: a tenth of the weight stays on the tangential part.
  constexpr double kTangential = 0.1;
  constexpr double kMinNormalAgreement = 0.5;  // cos 60 degrees
  std::vector<Correspondence> out;
  if (faces_.rows() == 0) return out;
  const RowMatrixX3f model_normals = VertexNormals(posed, around_);
  tree_->Refit(faces_, posed, active_);
  const auto& faces = faces_;
  const auto& nodes = tree_->nodes;
  const auto& order = tree_->order;
  // Only a face within max_distance can pair: the search starts there.
  const double gate2 = std::nextafter(max_distance * max_distance, INFINITY);
  std::vector<std::pair<float, int>> stack;
  stack.reserve(64);
  for (Eigen::Index j = 0; j < points.rows(); ++j) {
    const Eigen::Vector3f tf = points.row(j).transpose();
    const Eigen::Vector3d t = tf.cast<double>();
    double best = gate2;
    Correspondence c;
    bool found = false;
    auto try_face = [&](int f) {
      const Eigen::Vector3d a = posed.row(faces(f, 0)).cast<double>().transpose();
      const Eigen::Vector3d b = posed.row(faces(f, 1)).cast<double>().transpose();
      const Eigen::Vector3d cc = posed.row(faces(f, 2)).cast<double>().transpose();
      const Eigen::Vector3d bary = ClosestBarycentric(t, a, b, cc);
      const double d = (bary[0] * a + bary[1] * b + bary[2] * cc - t).squaredNorm();
      if (d < best) {
        best = d;
        found = true;
        c.vertices = {faces(f, 0), faces(f, 1), faces(f, 2)};
        c.bary = bary;
      }
    };
    // Box distances in float, compared with a margin for its rounding.
    auto prune = [&](float box2) { return box2 > best * (1 + 1e-5) + 1e-12; };
    // An empty box (no active face below) is infinitely far.
    auto distance2 = [&](int i) {
      const Eigen::AlignedBox3f& box = nodes[static_cast<size_t>(i)].box;
      return box.isEmpty() ? INFINITY : box.squaredExteriorDistance(tf);
    };
    stack.clear();
    stack.emplace_back(distance2(0), 0);
    while (!stack.empty()) {
      const auto [box2, i] = stack.back();
      stack.pop_back();
      if (prune(box2)) continue;
      const Tree::Node& n = nodes[static_cast<size_t>(i)];
      if (n.count > 0) {
        for (int k = n.first; k < n.first + n.count; ++k) {
          const int f = order[static_cast<size_t>(k)];
          if (active_.empty() || active_[static_cast<size_t>(f)]) try_face(f);
        }
        continue;
      }
      const int left = i + 1, right = n.right;
      const float dl = distance2(left), dr = distance2(right);
      // The nearer child last, so that it is searched first.
      if (dl <= dr) {
        if (!prune(dr)) stack.emplace_back(dr, right);
        if (!prune(dl)) stack.emplace_back(dl, left);
      } else {
        if (!prune(dl)) stack.emplace_back(dl, left);
        if (!prune(dr)) stack.emplace_back(dr, right);
      }
    }
    if (!found) continue;
    c.count = 3;
    c.target = t;
    const Eigen::Vector3d normal = point_normals.row(j).cast<double>().transpose();
    // Surfaces facing another way are other parts (an eyelid over an eyeball,
    // lips over teeth, the inside of a scan): no pair.
    Eigen::Vector3d model_normal = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) model_normal += c.bary[k] * model_normals.row(c.vertices[k]).cast<double>().transpose();
    if (normal.squaredNorm() > 0.5 && model_normal.squaredNorm() > 1e-6 &&
        normal.dot(model_normal.normalized()) < kMinNormalAgreement)
      continue;
    if (normal.squaredNorm() > 0.5) {
      const Eigen::Matrix3d nn = normal * normal.transpose();
      c.metric = nn + kTangential * (Eigen::Matrix3d::Identity() - nn);
    }
    c.weight = 0;
    double importance = 0;
    for (int k = 0; k < 3; ++k) {
      c.weight += c.bary[k] * omega[c.vertices[k]];
      importance += c.bary[k] * nu[c.vertices[k]];
    }
    c.face = importance >= 0.999;
    out.push_back(c);
  }
  return out;
}

std::vector<Correspondence> ClosestPoints(const HeadModel& model, const RowMatrixX3f& posed, const RowMatrixX3f& points,
                                          const RowMatrixX3f& point_normals, const Eigen::VectorXf& omega,
                                          const Eigen::VectorXf& nu, double max_distance, const SurfacePatch* patch) {
  return ClosestPointSearch(model, posed, patch).Find(posed, points, point_normals, omega, nu, max_distance);
}

Eigen::Matrix4d Umeyama(const std::vector<Eigen::Vector3d>& from, const std::vector<Eigen::Vector3d>& to, bool scale) {
  Eigen::Matrix3Xd a(3, from.size()), b(3, to.size());
  for (size_t i = 0; i < from.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = from[i];
    b.col(static_cast<Eigen::Index>(i)) = to[i];
  }
  return Eigen::umeyama(a, b, scale);
}

void SetRigid(const Eigen::Matrix4d& T, FitState* st) {
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  const double s = std::cbrt(sR.determinant());
  st->log_scale = std::log(s);
  st->rotation = MatrixToAxisAngle(sR / s);
  st->translation = T.topRightCorner<3, 1>();
}

// One Ceres solve over `pairs`; returns the LM iterations used.
SolveSettings SolveSettings::From(const MeshFitOptions& o) {
  SolveSettings s;
  s.loss = o.loss;
  s.loss_scale_m = o.loss_scale_m;
  s.shape_prior = o.shape_prior;
  s.expression_prior = o.expression_prior;
  s.jaw_prior = o.jaw_prior;
  s.max_iterations = o.max_iterations;
  return s;
}

int SolveOnce(const MeshBasis& basis, const std::vector<Correspondence>& pairs, const SolveSettings& o,
              const FreeBlocks& free, FitState* st) {
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  std::unique_ptr<ceres::LossFunction> base;
  if (o.loss == MeshLoss::kNorm) base = std::make_unique<ceres::SoftLOneLoss>(o.loss_scale_m);
  if (o.loss == MeshLoss::kHuber) base = std::make_unique<ceres::HuberLoss>(o.loss_scale_m);
  if (o.loss == MeshLoss::kCauchy) base = std::make_unique<ceres::CauchyLoss>(o.loss_scale_m);
  double* blocks[] = {st->coefficients.data(), st->rotation.data(), st->translation.data(), &st->log_scale,
                      st->jaw.data()};
  const int threads = std::max(1, std::min(o.threads, static_cast<int>(std::thread::hardware_concurrency())));
  if (o.batched) {
    // Fixed weights: the pair's weight times the loss's slope at the starting state.
    const double* start[] = {blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]};
    const SurfaceFrame frame = SurfaceFrame::For(basis, start);
    std::vector<SurfacePoint> points;
    for (const Correspondence& c : pairs) {
      if (c.weight <= 0) continue;
      SurfacePoint point{c.vertices, c.bary, c.count, c.target, c.metric, 1.0};
      double slope = 1;
      if (base) {
        double residual[3], rho[3];
        EvaluateSurfacePoint(basis, frame, point, start, residual, nullptr, 0);
        base->Evaluate(Eigen::Map<const Eigen::Vector3d>(residual).squaredNorm(), rho);
        slope = rho[1];
      }
      point.scale = std::sqrt(c.weight * slope);
      points.push_back(point);
    }
    // A block per Ceres thread, so that the threads share the evaluation.
    const size_t part_size = (points.size() + threads - 1) / threads;
    for (size_t begin = 0; begin < points.size(); begin += part_size) {
      std::vector<SurfacePoint> part(
          points.begin() + static_cast<std::ptrdiff_t>(begin),
          points.begin() + static_cast<std::ptrdiff_t>(std::min(points.size(), begin + part_size)));
      problem.AddResidualBlock(new SurfacePointsCost(&basis, std::move(part)), nullptr, blocks, 5);
    }
  } else {
    for (const Correspondence& c : pairs) {
      if (c.weight <= 0) continue;
      problem.AddResidualBlock(new SurfacePointCost(&basis, c.vertices, c.bary, c.count, c.target, c.metric),
                               new ceres::ScaledLoss(base.get(), c.weight, ceres::DO_NOT_TAKE_OWNERSHIP), blocks, 5);
    }
  }
  if (problem.NumResidualBlocks() == 0) throw std::runtime_error("mesh fit: no usable correspondences");
  // Priors keep components the mesh does not constrain at zero. They are
  // scaled by the number of residuals so their strength does not depend on the mesh density.
  const double count = static_cast<double>(pairs.size());
  Eigen::VectorXd prior_weights = Eigen::VectorXd::Zero(basis.k);
  prior_weights.head(basis.ns).setConstant(std::sqrt(o.shape_prior * count));
  prior_weights.segment(basis.ns, basis.ne).setConstant(std::sqrt(o.expression_prior * count));
  if (basis.ns + basis.ne > 0)
    problem.AddResidualBlock(
        new ceres::NormalPrior(prior_weights.asDiagonal().toDenseMatrix(), Eigen::VectorXd::Zero(basis.k)), nullptr,
        blocks[kCoefficients]);
  problem.AddResidualBlock(
      new ceres::NormalPrior(std::sqrt(o.jaw_prior * count) * Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()),
      nullptr, blocks[kJaw]);
  // Coefficients: all free, a subset (SubsetManifold holds the rest), or none.
  std::vector<int> fixed;
  for (int i = 0; i < basis.ns; ++i)
    if (!free.shape) fixed.push_back(i);
  for (int i = basis.ns; i < basis.ns + basis.ne; ++i)
    if (!free.expression) fixed.push_back(i);
  if (basis.ns + basis.ne == 0 || static_cast<int>(fixed.size()) == basis.k)
    problem.SetParameterBlockConstant(blocks[kCoefficients]);
  else if (!fixed.empty())
    problem.SetManifold(blocks[kCoefficients], new ceres::SubsetManifold(basis.k, fixed));
  if (!free.rigid) {
    problem.SetParameterBlockConstant(blocks[kRotation]);
    problem.SetParameterBlockConstant(blocks[kTranslation]);
  }
  if (!free.jaw) problem.SetParameterBlockConstant(blocks[kJaw]);
  if (!free.scale) problem.SetParameterBlockConstant(blocks[kLogScale]);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  so.max_num_iterations = o.max_iterations;
  so.num_threads = threads;
  so.function_tolerance = 1e-9;
  so.parameter_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (summary.termination_type == ceres::FAILURE) throw std::runtime_error("mesh fit: " + summary.message);
  return static_cast<int>(summary.iterations.size());
}

void MeasureRms(const RowMatrixX3f& posed, const std::vector<Correspondence>& pairs, MeshFitResult* r) {
  const PairRms rms = MeasurePairs(posed, pairs);
  r->correspondences = static_cast<int>(pairs.size());
  r->rms_m = rms.all_m;
  r->rms_face_m = rms.face_m;
}

PairRms MeasurePairs(const RowMatrixX3f& posed, const std::vector<Correspondence>& pairs) {
  double all = 0, face = 0;
  int n_face = 0;
  for (const Correspondence& c : pairs) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int k = 0; k < c.count; ++k) x += c.bary[k] * posed.row(c.vertices[k]).cast<double>().transpose();
    const double d2 = (x - c.target).squaredNorm();
    all += d2;
    if (c.face) {
      face += d2;
      ++n_face;
    }
  }
  PairRms r;
  r.all_m = pairs.empty() ? 0 : std::sqrt(all / pairs.size());
  r.face_m = n_face == 0 ? 0 : std::sqrt(face / n_face);
  return r;
}

}  // namespace mesh_fit_internal

namespace {

using namespace mesh_fit_internal;

bool SameTopology(const HeadModel& model, const TriangleMesh& target) {
  return target.vertices.rows() == model.num_vertices() && target.faces.rows() == model.num_faces() &&
         target.faces == model.data().faces;
}

}  // namespace

Eigen::VectorXf DefaultImportance(const HeadModel& model) {
  const HeadModelOutput rest = model.Forward(HeadModelParams{});
  const auto& L = rest.landmarks;
  const int n = model.num_vertices();
  const float iod = (L.row(36) - L.row(45)).norm();
  // Face outline in the frontal (x, y) plane: jaw contour 0..16, then the brows 26..17 lifted to the hairline.
  std::vector<Eigen::Vector2f> outline;
  for (int k = 0; k <= 16; ++k) outline.emplace_back(L(k, 0), L(k, 1));
  for (int k = 26; k >= 17; --k) outline.emplace_back(L(k, 0), L(k, 1) + 0.45f * iod);
  auto inside = [&](float x, float y) {
    bool in = false;
    for (size_t a = 0, b = outline.size() - 1; a < outline.size(); b = a++) {
      const Eigen::Vector2f& p = outline[a];
      const Eigen::Vector2f& q = outline[b];
      if ((p.y() > y) != (q.y() > y) && x < (q.x() - p.x()) * (y - p.y()) / (q.y() - p.y()) + p.x()) in = !in;
    }
    return in;
  };
  float contour_z = INFINITY;
  for (int k = 0; k <= 16; ++k) contour_z = std::min(contour_z, L(k, 2));
  const float front_z = contour_z - 0.2f * iod;
  const float centre_z = rest.vertices.col(2).mean();
  Eigen::VectorXf nu(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3f v = rest.vertices.row(i).transpose();
    float near_nose = INFINITY;
    for (int k = 27; k <= 35; ++k) near_nose = std::min(near_nose, (v - L.row(k).transpose()).norm());
    const bool face = v.z() > front_z && inside(v.x(), v.y());
    if (face && near_nose < 0.25f * iod)
      nu[i] = 2;
    else if (face)
      nu[i] = 1;
    else if (v.z() > centre_z)
      nu[i] = 0.3f;
    else
      nu[i] = 0.1f;
  }
  return nu;
}

Eigen::VectorXf ParameterCountWeights(const HeadModel& model, int num_shape, int num_expression, bool jaw) {
  const int n = model.num_vertices();
  Eigen::VectorXi count = Eigen::VectorXi::Zero(n);
  auto add = [&](const Eigen::MatrixXf& dirs, int columns) {
    for (int k = 0; k < columns; ++k) {
      Eigen::VectorXf m(n);
      for (int i = 0; i < n; ++i) m[i] = dirs.block(3 * i, k, 3, 1).norm();
      const float threshold = 0.05f * m.maxCoeff();
      if (threshold <= 0) continue;
      for (int i = 0; i < n; ++i) count[i] += m[i] > threshold;
    }
  };
  add(model.data().shapedirs, std::min(num_shape, model.num_shape()));
  add(model.data().expressiondirs, std::min(num_expression, model.num_expression()));
  if (jaw && model.JointIsArticulated(kJawJoint))
    for (int i = 0; i < n; ++i) count[i] += model.data().weights(i, kJawJoint) > 0.05f;
  Eigen::VectorXf phi = (count.cast<float>().array() + 1).inverse();
  return phi / phi.mean();
}

int MeshFitOptions::ShapeCount(const HeadModel& model) const {
  if (!fit_shape) return 0;
  return num_shape > 0 ? std::min(num_shape, model.num_shape()) : model.num_shape();
}

int MeshFitOptions::ExpressionCount(const HeadModel& model) const {
  if (!fit_expression) return 0;
  return num_expression > 0 ? std::min(num_expression, model.num_expression()) : model.num_expression();
}

Eigen::VectorXf MeshFitOptions::Importance(const HeadModel& model) const {
  if (importance.size() == 0) return DefaultImportance(model);
  if (importance.size() != model.num_vertices())
    throw std::invalid_argument("importance map has " + std::to_string(importance.size()) +
                                " values; the head model has " + std::to_string(model.num_vertices()) + " vertices");
  return importance;
}

namespace {

// omega from an importance map nu already at hand (it is also needed for the face region).
Eigen::VectorXf WeightsFromImportance(const HeadModel& model, const MeshFitOptions& o, const Eigen::VectorXf& nu) {
  if (o.weighting == MeshWeighting::kUniform) return Eigen::VectorXf::Ones(model.num_vertices());
  Eigen::VectorXf w = nu;
  if (o.weighting == MeshWeighting::kImportanceAndCount)
    w = w.cwiseProduct(ParameterCountWeights(model, o.ShapeCount(model), o.ExpressionCount(model), o.fit_jaw));
  if (!(w.sum() > 0)) throw std::invalid_argument("mesh-fit weights are all zero");
  return w / w.mean();
}

}  // namespace

Eigen::VectorXf MeshFitWeights(const HeadModel& model, const MeshFitOptions& o) {
  if (o.weighting == MeshWeighting::kUniform) return Eigen::VectorXf::Ones(model.num_vertices());
  return WeightsFromImportance(model, o, o.Importance(model));
}

void CheckMeshForFit(const HeadModel& model, const TriangleMesh& target, const MeshFitOptions& o) {
  o.Check();
  if (target.vertices.rows() == 0 || target.faces.rows() == 0)
    throw std::invalid_argument("the mesh is empty (" + std::to_string(target.vertices.rows()) + " vertices, " +
                                std::to_string(target.faces.rows()) + " faces)");
  if (target.faces.minCoeff() < 0 || target.faces.maxCoeff() >= target.vertices.rows())
    throw std::invalid_argument("the mesh has face indices out of range");
  const MeshDiagnostics d = Diagnose(target);
  if (d.non_finite_vertices > 0)
    throw std::invalid_argument("the mesh has " + std::to_string(d.non_finite_vertices) +
                                " vertices with NaN or infinite coordinates");
  if (d.non_manifold_edges > 0 && !o.allow_non_manifold)
    throw std::invalid_argument("the mesh is non-manifold: " + std::to_string(d.non_manifold_edges) +
                                " edges are shared by more than two faces (repair it, or allow non-manifold meshes)");
  const double model_radius = Diagnose(TriangleMesh{model.data().v_template, model.data().faces}).rms_radius;
  const double ratio = d.rms_radius / model_radius;
  auto unit_hint = [&](const std::string& unit) {
    return "the mesh looks like it is in " + unit + " (RMS radius " + std::to_string(d.rms_radius) +
           " units; the head model's is " + std::to_string(model_radius) + " m): convert it to metres (--unit " +
           (unit == "centimetres" ? "cm" : "mm") + ")";
  };
  if (ratio > 30 && ratio < 300) throw std::invalid_argument(unit_hint("centimetres"));
  if (ratio >= 300 && ratio < 3000) throw std::invalid_argument(unit_hint("millimetres"));
  const double tolerance = o.fit_scale ? 5.0 : 2.0;
  if (ratio > tolerance || ratio < 1 / tolerance)
    throw std::invalid_argument("the mesh's size is " + std::to_string(ratio) +
                                " times the head model's; check its unit (metres expected)" +
                                (o.fit_scale ? "" : " or fit a scale"));
  if (o.correspondence == MeshCorrespondence::kSameTopology && !SameTopology(model, target))
    throw std::invalid_argument("same-topology fit asked for, but the mesh has " +
                                std::to_string(target.vertices.rows()) + " vertices and " +
                                std::to_string(target.faces.rows()) + " faces against the model's " +
                                std::to_string(model.num_vertices()) + " and " + std::to_string(model.num_faces()) +
                                (target.vertices.rows() == model.num_vertices() ? " (the faces differ)" : ""));
}

MeshFitResult FitHeadModelToMesh(const HeadModel& model, const TriangleMesh& target, const MeshFitOptions& o) {
  CheckMeshForFit(model, target, o);
  MeshFitResult r;
  r.same_topology = o.correspondence == MeshCorrespondence::kSameTopology ||
                    (o.correspondence == MeshCorrespondence::kAuto && SameTopology(model, target));
  const MeshBasis basis(model, o.ShapeCount(model), o.ExpressionCount(model));
  const Eigen::VectorXf nu = o.Importance(model);
  const Eigen::VectorXf omega = WeightsFromImportance(model, o, nu);
  FitState st;
  st.coefficients = Eigen::VectorXd::Zero(basis.k);
  const RowMatrixX3f& rest = model.data().v_template;
  const SolveSettings settings = SolveSettings::From(o);
  FreeBlocks all_free;
  all_free.jaw = o.fit_jaw && model.JointIsArticulated(kJawJoint);
  all_free.scale = o.fit_scale;

  if (r.same_topology) {
    // Rigid pre-alignment on the face region, then rigid-only, then everything.
    std::vector<Eigen::Vector3d> from, to;
    for (int i = 0; i < model.num_vertices(); ++i)
      if (nu[i] >= 1) {
        from.push_back(rest.row(i).cast<double>().transpose());
        to.push_back(target.vertices.row(i).cast<double>().transpose());
      }
    SetRigid(Umeyama(from, to, o.fit_scale), &st);
    std::vector<Correspondence> pairs(model.num_vertices());
    for (int i = 0; i < model.num_vertices(); ++i) {
      pairs[i].vertices = {i, 0, 0};
      pairs[i].bary = {1, 0, 0};
      pairs[i].count = 1;
      pairs[i].target = target.vertices.row(i).cast<double>().transpose();
      pairs[i].weight = omega[i];
      pairs[i].face = nu[i] >= 1;
    }
    r.iterations += SolveOnce(basis, pairs, settings, FreeBlocks::RigidOnly(), &st);
    r.iterations += SolveOnce(basis, pairs, settings, all_free, &st);
    r.rounds = 1;
    MeasureRms(PoseAll(basis, st), pairs, &r);
    r.round_rms_m.push_back(r.rms_m);
  } else {
    if (!o.prealigned) {
      if (o.target_landmarks.size() < 4)
        throw std::invalid_argument(
            "a mesh in another topology needs at least 4 landmarks on it for the rigid pre-alignment (have " +
            std::to_string(o.target_landmarks.size()) + "), or a mesh already in the model's frame");
      std::vector<Eigen::Vector3d> from, to;
      const HeadModelOutput out = model.Forward(HeadModelParams{});
      for (const auto& [index, point] : o.target_landmarks) {
        from.push_back(out.landmarks.row(index).cast<double>().transpose());
        to.push_back(point);
      }
      Eigen::Matrix3Xd centred(3, to.size());
      for (size_t i = 0; i < to.size(); ++i) centred.col(static_cast<Eigen::Index>(i)) = to[i];
      centred.colwise() -= centred.rowwise().mean();
      const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
      if (svd.singularValues()[1] < 1e-3 * svd.singularValues()[0])
        throw std::invalid_argument("the mesh landmarks are (nearly) collinear: no rigid alignment from them");
      SetRigid(Umeyama(from, to, o.fit_scale), &st);
    }
    const RowMatrixX3f target_normals = VertexNormals(target.vertices, target.faces);
    double previous = INFINITY;
    std::vector<Correspondence> pairs;
    for (int round = 0; round < o.closest_point_rounds; ++round) {
      // Wider gates while the alignment is rough.
      const double gate = o.max_correspondence_m * (round < 2 ? 3.0 : 1.0);
      pairs = ClosestPoints(model, PoseAll(basis, st), target.vertices, target_normals, omega, nu, gate);
      r.iterations += SolveOnce(basis, pairs, settings, round == 0 ? FreeBlocks::RigidOnly() : all_free, &st);
      ++r.rounds;
      MeasureRms(PoseAll(basis, st), pairs, &r);
      r.round_rms_m.push_back(r.rms_m);
      spdlog::debug("mesh fit round {}: {} pairs, rms {:.3f} mm", round, pairs.size(), 1e3 * r.rms_m);
      if (round >= 2 && std::abs(previous - r.rms_m) < 1e-3 * previous) break;
      previous = r.rms_m;
    }
  }
  r.params.shape = Eigen::VectorXd::Zero(model.num_shape());
  r.params.expression = Eigen::VectorXd::Zero(model.num_expression());
  r.params.shape.head(basis.ns) = st.coefficients.head(basis.ns);
  r.params.expression.head(basis.ne) = st.coefficients.segment(basis.ns, basis.ne);
  r.params.pose.segment<3>(3 * kJawJoint) = st.jaw;
  r.scale = std::exp(st.log_scale);
  r.rotation = AxisAngleToMatrix(st.rotation);
  r.translation = st.translation;
  return r;
}

RowMatrixX3f FittedVertices(const HeadModel& model, const MeshFitResult& fit) {
  const RowMatrixX3f v = model.Forward(fit.params).vertices;
  const Eigen::Matrix3f sR = (fit.scale * fit.rotation).cast<float>();
  RowMatrixX3f out = v * sR.transpose();
  out.rowwise() += fit.translation.cast<float>().transpose();
  return out;
}

void WriteMeshFitJson(const std::string& path, const HeadModel& model, const MeshFitResult& fit,
                      const std::string& extra_json_object) {
  auto vec = [](const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); };
  nlohmann::json rotation = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rotation.push_back({fit.rotation(r, 0), fit.rotation(r, 1), fit.rotation(r, 2)});
  nlohmann::json j = {{"format", "headcast mesh fit 1"},
                      {"head_model", model.data().name},
                      {"head_model_fingerprint", model.fingerprint()},
                      {"shape", vec(fit.params.shape)},
                      {"expression", vec(fit.params.expression)},
                      {"pose", vec(fit.params.pose)},
                      {"mesh_from_model",
                       {{"scale", fit.scale},
                        {"rotation", rotation},
                        {"translation", {fit.translation.x(), fit.translation.y(), fit.translation.z()}},
                        {"what", "mesh = scale * rotation * model(shape, expression, pose) + translation, metres"}}},
                      {"same_topology", fit.same_topology},
                      {"correspondences", fit.correspondences},
                      {"rms_mm", 1e3 * fit.rms_m},
                      {"rms_face_mm", 1e3 * fit.rms_face_m},
                      {"rounds", fit.rounds},
                      {"iterations", fit.iterations}};
  j.update(nlohmann::json::parse(extra_json_object));
  std::ofstream out(path);
  out << j.dump(2) << "\n";
  if (!out) throw std::runtime_error(path + ": cannot write");
}

Eigen::VectorXd ReadIdentityFromMeshFit(const std::string& path, const HeadModel& model) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": not JSON (" + e.what() + ")");
  }
  if (!j.is_object() || j.value("format", "") != "headcast mesh fit 1" || !j.contains("shape") ||
      !j["shape"].is_array())
    throw std::runtime_error(path + ": not a headcast-fit-mesh result (no format/shape)");
  const std::string fingerprint = j.value("head_model_fingerprint", "");
  if (fingerprint != model.fingerprint())
    throw std::runtime_error(path + ": fitted with head model '" + j.value("head_model", "?") + "' (" + fingerprint +
                             "), not '" + model.data().name + "' (" + model.fingerprint() + ")");
  Eigen::VectorXd shape = Eigen::VectorXd::Zero(model.num_shape());
  const auto& values = j["shape"];
  if (static_cast<int>(values.size()) > model.num_shape())
    throw std::runtime_error(path + ": " + std::to_string(values.size()) + " shape values for a model with " +
                             std::to_string(model.num_shape()));
  for (size_t k = 0; k < values.size(); ++k) {
    if (!values[k].is_number() || !std::isfinite(values[k].get<double>()))
      throw std::runtime_error(path + ": shape[" + std::to_string(k) + "] is not a finite number");
    shape[static_cast<Eigen::Index>(k)] = values[k].get<double>();
  }
  return shape;
}

namespace {

// All vertices' weighted residuals of a black-box generator; Jacobian by central differences.
class BlackBoxCost final : public ceres::CostFunction {
 public:
  BlackBoxCost(const MeshGenerator& generator, const RowMatrixX3f& target, const Eigen::VectorXd& sqrt_weights,
               double step, int* calls)
      : generator_(generator), target_(target), sqrt_weights_(sqrt_weights), step_(step), calls_(calls) {
    set_num_residuals(static_cast<int>(3 * target.rows()));
  }
  void SetSize(int k) { mutable_parameter_block_sizes()->assign(1, k); }

  bool Evaluate(double const* const* p, double* residuals, double** jacobians) const override {
    const int k = parameter_block_sizes()[0];
    const Eigen::Index n = target_.rows();
    Eigen::VectorXd x = Eigen::Map<const Eigen::VectorXd>(p[0], k);
    RowMatrixX3f v;
    if (!Generate(x, &v)) return false;
    for (Eigen::Index i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) residuals[3 * i + c] = sqrt_weights_[i] * (v(i, c) - target_(i, c));
    if (!jacobians || !jacobians[0]) return true;
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jacobians[0], 3 * n, k);
    RowMatrixX3f plus, minus;
    for (int j = 0; j < k; ++j) {
      const double h = step_ * std::max(1.0, std::abs(x[j]));
      Eigen::VectorXd xp = x, xm = x;
      xp[j] += h;
      xm[j] -= h;
      if (!Generate(xp, &plus) || !Generate(xm, &minus)) return false;
      for (Eigen::Index i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c)
          J(3 * i + c, j) = sqrt_weights_[i] * (static_cast<double>(plus(i, c)) - minus(i, c)) / (2 * h);
    }
    return true;
  }

 private:
  bool Generate(const Eigen::VectorXd& x, RowMatrixX3f* v) const {
    ++*calls_;
    generator_(x, v);
    return v->rows() == target_.rows() && v->allFinite();
  }
  const MeshGenerator& generator_;
  const RowMatrixX3f& target_;
  const Eigen::VectorXd& sqrt_weights_;
  double step_;
  int* calls_;
};

}  // namespace

BlackBoxFitResult FitBlackBoxToMesh(const MeshGenerator& generator, const Eigen::VectorXd& initial,
                                    const RowMatrixX3f& target, const Eigen::VectorXf& weights,
                                    const BlackBoxFitOptions& o) {
  o.Check();
  if (target.rows() == 0 || !target.allFinite())
    throw std::invalid_argument("black-box fit: empty or non-finite target");
  if (weights.size() != target.rows())
    throw std::invalid_argument("black-box fit: " + std::to_string(weights.size()) + " weights for " +
                                std::to_string(target.rows()) + " vertices");
  if (initial.size() == 0) throw std::invalid_argument("black-box fit: no parameters");
  BlackBoxFitResult r;
  r.params = initial;
  Eigen::VectorXd sqrt_w = weights.cast<double>().cwiseSqrt();
  RowMatrixX3f v;
  for (int round = 0; round < o.reweight_rounds; ++round) {
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    BlackBoxCost cost(generator, target, sqrt_w, o.step, &r.generator_calls);
    cost.SetSize(static_cast<int>(r.params.size()));
    problem.AddResidualBlock(&cost, nullptr, r.params.data());
    std::unique_ptr<ceres::CostFunction> prior(new ceres::NormalPrior(
        std::sqrt(o.prior * target.rows()) * Eigen::MatrixXd::Identity(r.params.size(), r.params.size()),
        Eigen::VectorXd::Zero(r.params.size())));
    problem.AddResidualBlock(prior.get(), nullptr, r.params.data());
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o.max_iterations;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (summary.termination_type == ceres::FAILURE) throw std::runtime_error("black-box fit: " + summary.message);
    // Reweight so the squared problem minimises sum w_i * sqrt(|d_i|^2 + delta^2), the paper's norm.
    generator(r.params, &v);
    ++r.generator_calls;
    for (Eigen::Index i = 0; i < target.rows(); ++i) {
      const double d = (v.row(i) - target.row(i)).cast<double>().norm();
      sqrt_w[i] = std::sqrt(weights[i] * o.loss_scale_m / std::sqrt(d * d + o.loss_scale_m * o.loss_scale_m));
    }
  }
  double ss = 0;
  for (Eigen::Index i = 0; i < target.rows(); ++i) ss += (v.row(i) - target.row(i)).cast<double>().squaredNorm();
  r.rms_m = std::sqrt(ss / target.rows());
  return r;
}

}  // namespace headcast
