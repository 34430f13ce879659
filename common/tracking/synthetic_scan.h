// Synthetic head scans with known parameters, for testing and benchmarking the
// mesh fit: the model posed with random shape/expression/jaw and a random
// rigid transform, Gaussian vertex noise, and optionally hair-like bulges on
// the back and top of the head that no model parameter can produce.
#pragma once

#include "common/tracking/mesh_fitter.h"

namespace headcast {

struct SyntheticScanOptions {
  unsigned seed = 1;
  double noise_m = 0.5e-3;  // vertex noise, standard deviation per coordinate
  double hair_m = 0;        // largest outward bulge where importance < 1 above the eyes
  void Check() const;
};

struct SyntheticScan {
  HeadModelParams params;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  RowMatrixX3f clean, noisy;  // mesh-frame vertices: the truth, and what the fit sees
  MeshFitResult Truth() const;
};

SyntheticScan MakeSyntheticScan(const HeadModel& model, const SyntheticScanOptions& options);
// RMS distance between a fit and the true vertices over the face (importance >= 1), mm.
double FaceRmsAgainstTruthMm(const HeadModel& model, const MeshFitResult& fit, const RowMatrixX3f& truth);

}  // namespace headcast
