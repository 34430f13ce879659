// Synthetic scans for the mesh fit.
#include "common/tracking/synthetic_scan.h"

#include <cmath>
#include <random>

#include "common/core/options.h"
#include "common/core/rotation.h"

namespace headcast {

void SyntheticScanOptions::Check() const {
  OptionsCheck c("SyntheticScanOptions");
  c.NonNegative("noise_m", noise_m).NonNegative("hair_m", hair_m);
  c.ThrowIfErrors();
}

MeshFitResult SyntheticScan::Truth() const {
  MeshFitResult t;
  t.params = params;
  t.rotation = rotation;
  t.translation = translation;
  return t;
}

SyntheticScan MakeSyntheticScan(const HeadModel& model, const SyntheticScanOptions& o) {
  o.Check();
  std::mt19937 rng(o.seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<float> gauss(0, static_cast<float>(o.noise_m));
  SyntheticScan s;
  s.params.shape = Eigen::VectorXd(model.num_shape());
  s.params.expression = Eigen::VectorXd(model.num_expression());
  for (auto& v : s.params.shape) v = u(rng);
  for (auto& v : s.params.expression) v = 0.5 * (u(rng) + 1);  // blendshape-style models want >= 0
  if (model.JointIsArticulated(kJawJoint)) s.params.pose[3 * kJawJoint] = 0.1 + 0.1 * u(rng);
  s.rotation = AxisAngleToMatrix(Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng), 0.2 * u(rng)));
  s.translation = Eigen::Vector3d(0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng));
  s.clean = FittedVertices(model, s.Truth());
  s.noisy = s.clean;
  for (Eigen::Index i = 0; i < s.noisy.rows(); ++i)
    for (int c = 0; c < 3; ++c) s.noisy(i, c) += gauss(rng);
  if (o.hair_m > 0) {
    const Eigen::VectorXf nu = DefaultImportance(model);
    const RowMatrixX3f normals = model.VertexNormals(model.data().v_template);
    const float top = static_cast<float>(model.rest_landmark_centroid().y());
    const Eigen::Matrix3f R = s.rotation.cast<float>();
    const float phase = static_cast<float>(o.seed);
    for (int i = 0; i < model.num_vertices(); ++i) {
      if (nu[i] >= 1 || model.data().v_template(i, 1) <= top) continue;
      // Smoothly varying thickness, 60..100 % of hair_m.
      const float amount =
          static_cast<float>(o.hair_m) * (0.6f + 0.4f * std::sin(40.0f * model.data().v_template(i, 0) + phase));
      s.noisy.row(i) += amount * (R * normals.row(i).transpose()).transpose();
    }
  }
  return s;
}

double FaceRmsAgainstTruthMm(const HeadModel& model, const MeshFitResult& fit, const RowMatrixX3f& truth) {
  const Eigen::VectorXf nu = DefaultImportance(model);
  const RowMatrixX3f v = FittedVertices(model, fit);
  double ss = 0;
  int n = 0;
  for (int i = 0; i < model.num_vertices(); ++i)
    if (nu[i] >= 1) {
      ss += (v.row(i) - truth.row(i)).squaredNorm();
      ++n;
    }
  return n == 0 ? 0 : 1e3 * std::sqrt(ss / n);
}

}  // namespace headcast
