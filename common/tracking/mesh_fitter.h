// Head-model parameters for a given polygonal head (METHOD §8): minimise
// sum_i w_i * rho(|r_i^C - r_i(alpha)|) with w_i = nu_i * phi_i, where nu_i is
// a per-vertex importance (face and nose high, back of the head low) and phi_i
// is larger where fewer parameters move the vertex (those vertices are placed
// precisely). rho is the paper's plain norm (smoothed near zero), a squared
// norm, or Cauchy for scans with outliers.
//
// Same topology: vertex i of the mesh corresponds to model vertex i. Another
// topology (a scan, a remeshed copy): after a landmark-based rigid alignment,
// closest points on the model surface (a bounding-volume hierarchy) and the weighted fit
// alternate. The mesh is related to the model by a similarity:
// mesh = scale * R * model(shape, expression, jaw) + t.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "common/headmodel/head_model.h"
#include "common/headmodel/mesh_io.h"

namespace headcast {

enum class MeshCorrespondence { kAuto, kSameTopology, kClosestPoint };
enum class MeshWeighting { kImportanceAndCount, kImportance, kUniform };
enum class MeshLoss { kNorm, kSquared, kCauchy, kHuber };

struct MeshFitOptions {
  bool fit_shape = true, fit_expression = true;
  bool fit_jaw = true;                    // the jaw joint rotation (models with an articulated jaw)
  bool fit_scale = false;                 // a similarity instead of a rigid transform
  int num_shape = 0, num_expression = 0;  // components fitted (0: all the model has)
  MeshCorrespondence correspondence = MeshCorrespondence::kAuto;
  MeshWeighting weighting = MeshWeighting::kImportanceAndCount;
  MeshLoss loss = MeshLoss::kNorm;
  double loss_scale_m = 5e-4;  // where rho turns from quadratic to linear (kNorm) or saturates (kCauchy)
  // Tikhonov weights on the coefficients, in m^2 per unit^2 per point: small, they only
  // keep components the mesh does not constrain at zero.
  double shape_prior = 1e-9, expression_prior = 1e-9, jaw_prior = 1e-9;
  int max_iterations = 50;             // Levenberg-Marquardt iterations per solve
  int closest_point_rounds = 30;       // correspondence updates at most (other topology); stops on convergence
  double max_correspondence_m = 0.01;  // pairs farther apart are ignored (hair, shoulders, scan noise)
  // Other topology: target landmark positions (model landmark index 0..67 ->
  // point on the mesh) for the rigid pre-alignment; at least 4, not collinear.
  std::vector<std::pair<int, Eigen::Vector3d>> target_landmarks;
  bool prealigned = false;     // the mesh is already in the model's frame: no landmarks needed
  Eigen::VectorXf importance;  // nu override, one value per model vertex (empty: DefaultImportance)
  bool allow_non_manifold = false;
  void Check() const;
  // Components fitted for `model` (0 when that group is not fitted).
  int ShapeCount(const HeadModel& model) const;
  int ExpressionCount(const HeadModel& model) const;
  // nu: `importance`, checked against the model, or DefaultImportance.
  Eigen::VectorXf Importance(const HeadModel& model) const;
};

struct MeshFitResult {
  HeadModelParams params;  // shape, expression, jaw (root, neck, eyes zero)
  double scale = 1;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  bool same_topology = true;
  int rounds = 0, iterations = 0;
  int correspondences = 0;  // target points used in the last round
  double rms_m = 0;         // distance mesh <-> fitted model over the used points, metres
  double rms_face_m = 0;    // the same on the face region (nu >= 1)
  std::vector<double> round_rms_m;
};

// nu from the model's landmarks: 2 on the nose, 1 on the face (inside the
// jaw contour and brows, plus the forehead), 0.3 on the rest of the front
// half, 0.1 behind (back of the head, neck).
Eigen::VectorXf DefaultImportance(const HeadModel& model);
// phi: 1 / (1 + number of fitted parameters that move the vertex by more than
// 5 % of that parameter's largest displacement), scaled to mean 1.
Eigen::VectorXf ParameterCountWeights(const HeadModel& model, int num_shape, int num_expression, bool jaw);
// omega = nu * phi (or nu, or 1) per model vertex, mean 1.
Eigen::VectorXf MeshFitWeights(const HeadModel& model, const MeshFitOptions& options);

// Throws std::invalid_argument with what is wrong with `target` for this
// model: empty, non-finite, non-manifold (unless allowed), a scale that looks
// like centimetres or millimetres, a forced same-topology fit on another topology.
void CheckMeshForFit(const HeadModel& model, const TriangleMesh& target, const MeshFitOptions& options);

MeshFitResult FitHeadModelToMesh(const HeadModel& model, const TriangleMesh& target, const MeshFitOptions& options);
// The fitted model's vertices in the mesh's frame.
RowMatrixX3f FittedVertices(const HeadModel& model, const MeshFitResult& fit);

// PARAMS.json: the fit (parameters, similarity, residuals) plus the head
// model's name and fingerprint, written by headcast-fit-mesh.
void WriteMeshFitJson(const std::string& path, const HeadModel& model, const MeshFitResult& fit,
                      const std::string& extra_json_object = "{}");
// The shape (identity) of a PARAMS.json for `model`; throws when the file is
// unreadable, malformed, non-finite or made for another head model.
Eigen::VectorXd ReadIdentityFromMeshFit(const std::string& path, const HeadModel& model);

// Black-box mode (the source paper's setting): any generator Xi mapping K
// parameters to N vertices in the target's frame and topology; derivatives
// by central differences; the weighted norm by iteratively reweighted least squares.
using MeshGenerator = std::function<void(const Eigen::VectorXd& params, RowMatrixX3f* vertices)>;
struct BlackBoxFitOptions {
  double step = 1e-4;          // central-difference step per parameter
  double loss_scale_m = 5e-4;  // smoothing of the norm near zero
  double prior = 1e-9;         // Tikhonov weight on the parameters, m^2 per unit^2 per vertex
  int reweight_rounds = 8;
  int max_iterations = 20;  // per round
  void Check() const;
};
struct BlackBoxFitResult {
  Eigen::VectorXd params;
  double rms_m = 0;
  int generator_calls = 0;
};
BlackBoxFitResult FitBlackBoxToMesh(const MeshGenerator& generator, const Eigen::VectorXd& initial,
                                    const RowMatrixX3f& target, const Eigen::VectorXf& weights,
                                    const BlackBoxFitOptions& options = {});

}  // namespace headcast
