// Mesh files and fitting the head model to a mesh (METHOD §8): analytic
// Jacobians against ceres::GradientChecker, recovery of known parameters with
// vertex noise (built-in head; ICT-FaceKit when ../shared/data is present),
// the weights against uniform weights on the face, other topologies, the
// black-box mode, and bad meshes refused with a reason.
#include "common/tracking/mesh_fitter.h"

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/ict_converter.h"
#include "common/headmodel/mesh_io.h"
#include "common/tracking/mesh_fit_cost.h"
#include "common/tracking/synthetic_scan.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Builtin() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

using KnownHead = SyntheticScan;

KnownHead MakeKnownHead(const HeadModel& model, unsigned seed, double noise_m) {
  SyntheticScanOptions o;
  o.seed = seed;
  o.noise_m = noise_m;
  return MakeSyntheticScan(model, o);
}

double FaceRmsMm(const HeadModel& model, const MeshFitResult& fit, const RowMatrixX3f& clean) {
  return FaceRmsAgainstTruthMm(model, fit, clean);
}

TEST(MeshIo, RoundTripsObjAndPlyAndReadsPolygonsAndBinaryPly) {
  const std::string dir = testing::TempDir("mesh_io");
  const TriangleMesh m{Builtin().data().v_template, Builtin().data().faces};
  for (const char* name : {"/m.obj", "/m.ply"}) {
    WriteMesh(dir + name, m);
    const TriangleMesh back = ReadMesh(dir + name);
    EXPECT_EQ(back.faces, m.faces) << name;
    EXPECT_LT((back.vertices - m.vertices).cwiseAbs().maxCoeff(), 1e-6f) << name;
  }
  // A quad with negative (relative) indices and texture/normal indices.
  std::ofstream(dir + "/quad.obj") << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf -4/1 -3/1 -2/1 -1/1\n";
  const TriangleMesh quad = ReadMesh(dir + "/quad.obj");
  EXPECT_EQ(quad.faces.rows(), 2);
  EXPECT_EQ(quad.faces(1, 2), 3);
  // Binary little-endian PLY with float vertices and an int-indexed face list.
  {
    std::ofstream f(dir + "/b.ply", std::ios::binary);
    f << "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const float v[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    f.write(reinterpret_cast<const char*>(v), sizeof(v));
    const unsigned char count = 3;
    const int idx[3] = {0, 1, 2};
    f.write(reinterpret_cast<const char*>(&count), 1);
    f.write(reinterpret_cast<const char*>(idx), sizeof(idx));
  }
  const TriangleMesh b = ReadMesh(dir + "/b.ply");
  EXPECT_EQ(b.faces.rows(), 1);
  EXPECT_FLOAT_EQ(b.vertices(1, 0), 1.0f);
}

TEST(MeshIo, RefusesBadFilesWithTheReason) {
  const std::string dir = testing::TempDir("mesh_io_bad");
  auto error_of = [](const std::string& path) {
    try {
      ReadMesh(path);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  std::ofstream(dir + "/nan.obj") << "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n";
  EXPECT_NE(error_of(dir + "/nan.obj").find("non-finite"), std::string::npos) << error_of(dir + "/nan.obj");
  std::ofstream(dir + "/range.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n";
  EXPECT_NE(error_of(dir + "/range.obj").find("out of range"), std::string::npos);
  std::ofstream(dir + "/empty.obj") << "# nothing\n";
  EXPECT_NE(error_of(dir + "/empty.obj").find("no vertices"), std::string::npos);
  std::ofstream(dir + "/nofaces.obj") << "v 0 0 0\n";
  EXPECT_NE(error_of(dir + "/nofaces.obj").find("no faces"), std::string::npos);
  {
    std::ofstream f(dir + "/cut.ply", std::ios::binary);
    f << "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n";
    f.write("\0\0\0\0\0\0", 6);
  }
  EXPECT_NE(error_of(dir + "/cut.ply").find("truncated"), std::string::npos);
  std::ofstream(dir + "/x.stl") << "solid";
  EXPECT_NE(error_of(dir + "/x.stl").find("unknown mesh format"), std::string::npos);
  EXPECT_NE(error_of(dir + "/missing.obj").find("cannot open"), std::string::npos);
}

TEST(MeshIo, RemeshingHelpersKeepTheSurface) {
  const TriangleMesh m{Builtin().data().v_template, Builtin().data().faces};
  const TriangleMesh fine = SubdivideMidpoints(m);
  EXPECT_EQ(fine.faces.rows(), 4 * m.faces.rows());
  EXPECT_GT(fine.vertices.rows(), 3 * m.vertices.rows());
  const TriangleMesh coarse = ClusterDecimate(m, 0.008);
  EXPECT_LT(coarse.vertices.rows(), m.vertices.rows() / 2);
  EXPECT_GT(coarse.faces.rows(), 500);
  EXPECT_EQ(Diagnose(coarse).non_manifold_edges, 0);
  EXPECT_NEAR(Diagnose(coarse).bounding_diagonal, Diagnose(m).bounding_diagonal, 0.02 * Diagnose(m).bounding_diagonal);
}

// GradientChecker's own verdict is relative per entry, which fails on entries
// that are zero up to 1e-17 rounding; compare each block against its largest entry instead.
void ExpectJacobiansMatch(const ceres::GradientChecker& checker, double* const* blocks) {
  ceres::GradientChecker::ProbeResults results;
  checker.Probe(blocks, 1e-6, &results);
  ASSERT_EQ(results.jacobians.size(), results.numeric_jacobians.size());
  for (size_t b = 0; b < results.jacobians.size(); ++b) {
    const Eigen::MatrixXd& analytic = results.jacobians[b];
    const Eigen::MatrixXd& numeric = results.numeric_jacobians[b];
    const double scale = std::max(1e-9, numeric.cwiseAbs().maxCoeff());
    EXPECT_LT((analytic - numeric).cwiseAbs().maxCoeff(), 1e-6 * scale) << "block " << b << "\n" << results.error_log;
  }
}

// The analytic Jacobians of the surface-point residual, at a random state, for
// a single vertex and a barycentric point of three, with and without jaw posedirs.
TEST(MeshFitCost, AnalyticJacobiansMatchNumericOnes) {
  using namespace mesh_fit_internal;
  const HeadModel& model = Builtin();
  const MeshBasis basis(model, model.num_shape(), model.num_expression());
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd c(basis.k);
  for (auto& v : c) v = u(rng);
  Eigen::Vector3d rotation(0.2, -0.3, 0.1), translation(0.01, -0.02, 0.3), jaw(0.15, 0.02, -0.01);
  double log_scale = 0.05;
  std::vector<const ceres::Manifold*> manifolds(5, nullptr);
  double* blocks[] = {c.data(), rotation.data(), translation.data(), &log_scale, jaw.data()};
  // A jaw vertex (largest jaw weight) and an arbitrary triangle.
  int jaw_vertex = 0;
  basis.jaw_weight.maxCoeff(&jaw_vertex);
  const auto& f = model.data().faces;
  const struct {
    std::array<int, 3> v;
    Eigen::Vector3d bary;
    int count;
  } cases[] = {{{jaw_vertex, 0, 0}, {1, 0, 0}, 1}, {{f(100, 0), f(100, 1), f(100, 2)}, {0.2, 0.5, 0.3}, 3}};
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, 0.9).normalized();
  const Eigen::Matrix3d point_to_plane = n * n.transpose() + 0.1 * (Eigen::Matrix3d::Identity() - n * n.transpose());
  for (const auto& k : cases) {
    SurfacePointCost cost(&basis, k.v, k.bary, k.count, Eigen::Vector3d(0.01, 0.02, 0.3), point_to_plane);
    ceres::NumericDiffOptions numeric;
    ceres::GradientChecker checker(&cost, &manifolds, numeric);
    ExpectJacobiansMatch(checker, blocks);
  }
  for (const auto& k : cases) {
    SurfacePointCost cost(&basis, k.v, k.bary, k.count, Eigen::Vector3d(0.01, 0.02, 0.3));
    ceres::NumericDiffOptions numeric;
    ceres::GradientChecker checker(&cost, &manifolds, numeric);
    ExpectJacobiansMatch(checker, blocks);
  }
  // The same with posedirs on the jaw (FLAME has them; the built-in head does not).
  HeadModelData data = model.data();
  data.posedirs = Eigen::MatrixXf::Zero(3 * model.num_vertices(), kNumPoseFeatures);
  std::normal_distribution<float> g(0, 0.003f);
  for (int i = 0; i < data.posedirs.rows(); ++i)
    for (int j = 9; j < 18; ++j) data.posedirs(i, j) = g(rng);
  const HeadModel with_posedirs(data);
  ASSERT_TRUE(with_posedirs.has_posedirs());
  const MeshBasis basis2(with_posedirs, with_posedirs.num_shape(), with_posedirs.num_expression());
  SurfacePointCost cost(&basis2, {jaw_vertex, 0, 0}, {1, 0, 0}, 1, Eigen::Vector3d(0.01, 0.02, 0.3));
  ceres::NumericDiffOptions numeric;
  ceres::GradientChecker checker(&cost, &manifolds, numeric);
  ExpectJacobiansMatch(checker, blocks);
  // And the forward pass equals HeadModel::Forward at that state (no rigid part).
  Eigen::Vector3d zero_rot = Eigen::Vector3d::Zero(), zero_t = Eigen::Vector3d::Zero();
  double zero_scale = 0;
  double* plain[] = {c.data(), zero_rot.data(), zero_t.data(), &zero_scale, jaw.data()};
  SurfacePointCost at(&basis2, {jaw_vertex, 0, 0}, {1, 0, 0}, 1, Eigen::Vector3d::Zero());
  Eigen::Vector3d residual;
  ASSERT_TRUE(at.Evaluate(plain, residual.data(), nullptr));
  HeadModelParams p;
  p.shape = c.head(with_posedirs.num_shape());
  p.expression = c.tail(with_posedirs.num_expression());
  p.pose.segment<3>(3 * kJawJoint) = jaw;
  const Eigen::Vector3d expected = with_posedirs.Forward(p).vertices.row(jaw_vertex).cast<double>().transpose();
  EXPECT_LT((residual - expected).norm(), 1e-6);
}

// The pruned search (centroid spheres) finds the same closest surface point
// as measuring every face, for points on, near and far from the surface.
TEST(MeshFitCost, ClosestPointsAreTheClosestOfAllFaces) {
  using namespace mesh_fit_internal;
  const HeadModel& model = Builtin();
  const RowMatrixX3f posed = model.Forward(HeadModelParams{}).vertices;
  const auto& faces = model.data().faces;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, 1);
  const int n = 400;
  RowMatrixX3f points(n, 3);
  for (int i = 0; i < n; ++i) {
    const int f = static_cast<int>(u(rng) * faces.rows()) % static_cast<int>(faces.rows());
    double a = u(rng), b = u(rng);
    if (a + b > 1) a = 1 - a, b = 1 - b;
    const Eigen::RowVector3f on =
        (1 - a - b) * posed.row(faces(f, 0)) + a * posed.row(faces(f, 1)) + b * posed.row(faces(f, 2));
    // On the surface, within 2 cm of it, or up to 20 cm away.
    const double offset = i % 3 == 0 ? 0.0 : i % 3 == 1 ? 0.02 * u(rng) : 0.2 * u(rng);
    points.row(i) = on + static_cast<float>(offset) * Eigen::RowVector3f(g(rng), g(rng), g(rng)).normalized();
  }
  std::vector<double> brute(n, INFINITY);  // every face measured
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d t = points.row(i).cast<double>().transpose();
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
      const Eigen::Vector3d a = posed.row(faces(f, 0)).cast<double>().transpose();
      const Eigen::Vector3d b = posed.row(faces(f, 1)).cast<double>().transpose();
      const Eigen::Vector3d c = posed.row(faces(f, 2)).cast<double>().transpose();
      const Eigen::Vector3d w = ClosestBarycentric(t, a, b, c);
      brute[i] = std::min(brute[i], (w[0] * a + w[1] * b + w[2] * c - t).norm());
    }
  }
  const RowMatrixX3f no_normals = RowMatrixX3f::Zero(n, 3);
  const Eigen::VectorXf ones = Eigen::VectorXf::Ones(model.num_vertices());
  // Ungated, and gated at 1 cm (which lets the search skip faces far from every point).
  for (const double gate : {1.0, 0.01}) {
    const std::vector<Correspondence> pairs = ClosestPoints(model, posed, points, no_normals, ones, ones, gate);
    const int within = static_cast<int>(std::count_if(brute.begin(), brute.end(), [&](double d) { return d <= gate; }));
    EXPECT_EQ(static_cast<int>(pairs.size()), within) << "gate " << gate;
    for (const Correspondence& p : pairs) {
      int i = 0;
      while (i < n && points.row(i).cast<double>().transpose() != p.target) ++i;
      ASSERT_LT(i, n);
      Eigen::Vector3d found = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) found += p.bary[k] * posed.row(p.vertices[k]).cast<double>().transpose();
      EXPECT_NEAR((found - p.target).norm(), brute[i], 1e-7) << "point " << i << ", gate " << gate;
    }
  }
  EXPECT_GT(std::count_if(brute.begin(), brute.end(), [](double d) { return d > 0.01; }),
            n / 5);  // the gate drops some
}

// Closest points searched on a patch around the targets (PatchNear, as the
// RGB-D fit does per frame) pair every target exactly as the whole head does,
// normals included, and pose and search a part of the head only.
TEST(MeshFitCost, ClosestPointsOnAPatchMatchTheWholeHead) {
  using namespace mesh_fit_internal;
  const HeadModel& model = Builtin();
  HeadModelParams params;
  params.expression = Eigen::VectorXd::Zero(model.num_expression());
  params.expression[0] = 0.8;
  params.pose.segment<3>(3 * kJawJoint) = Eigen::Vector3d(0.15, 0, 0);
  const MeshBasis basis(model, 0, model.num_expression());
  FitState st;
  st.coefficients = params.expression;
  st.jaw = params.pose.segment<3>(3 * kJawJoint);
  st.rotation = Eigen::Vector3d(3.0, 0.3, 0.05);  // about x by ~170 degrees: facing the camera
  st.translation = Eigen::Vector3d(0.01, -0.02, 0.5);
  const RowMatrixX3f posed = PoseAll(basis, st);
  // Targets: the surface facing the camera within 6 cm of the nose tip (the
  // landmark), pushed up to 1.5 cm off it, with its normals.
  const RowMatrixX3f normals = VertexNormals(posed, model.data().faces);
  const Eigen::RowVector3f nose = posed.row(model.data().faces(model.data().lmk_faces[30], 0));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Eigen::RowVector3f> chosen, chosen_normals;
  for (int i = 0; i < model.num_vertices(); ++i)
    if (normals(i, 2) < -0.5 && (posed.row(i) - nose).norm() < 0.06) {
      chosen.push_back(posed.row(i) + 0.015f * static_cast<float>(u(rng)) * normals.row(i));
      chosen_normals.push_back(normals.row(i));
    }
  ASSERT_GT(chosen.size(), 300u);
  RowMatrixX3f points(static_cast<Eigen::Index>(chosen.size()), 3), point_normals(points.rows(), 3);
  for (size_t i = 0; i < chosen.size(); ++i) {
    points.row(static_cast<Eigen::Index>(i)) = chosen[i];
    point_normals.row(static_cast<Eigen::Index>(i)) = chosen_normals[i];
  }
  const Eigen::VectorXf ones = Eigen::VectorXf::Ones(model.num_vertices());
  const double gate = 0.01;
  const SurfacePatch patch = PatchNear(model, posed, points.colwise().minCoeff().transpose(),
                                       points.colwise().maxCoeff().transpose(), static_cast<float>(gate));
  EXPECT_LT(patch.faces.size(), static_cast<size_t>(model.num_faces()) / 2);
  const std::vector<Correspondence> whole = ClosestPoints(model, posed, points, point_normals, ones, ones, gate);
  const std::vector<Correspondence> part =
      ClosestPoints(model, PosePatch(basis, st, patch), points, point_normals, ones, ones, gate, &patch);
  // The same pairs: targets, surface points on `surface` (on an edge two
  // faces share the point: either may be named) and metrics.
  auto expect_same_pairs = [](const RowMatrixX3f& surface, const std::vector<Correspondence>& a,
                              const std::vector<Correspondence>& b) {
    ASSERT_EQ(a.size(), b.size());
    auto surface_point = [&](const Correspondence& c) {
      Eigen::Vector3d x = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) x += c.bary[k] * surface.row(c.vertices[k]).cast<double>().transpose();
      return x;
    };
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].target, b[i].target) << i;
      EXPECT_LT((surface_point(a[i]) - surface_point(b[i])).norm(), 1e-7) << i;
      EXPECT_LT((a[i].metric - b[i].metric).norm(), 1e-5) << i;
    }
  };
  ASSERT_GT(whole.size(), chosen.size() / 2);
  expect_same_pairs(posed, whole, part);
  // A search built at this pose, asked after the head has moved (as the
  // rounds of one fit ask it), answers as a search built anew.
  const ClosestPointSearch kept(model, PosePatch(basis, st, patch), &patch);
  FitState moved = st;
  moved.rotation += Eigen::Vector3d(0.1, -0.05, 0.02);
  moved.translation += Eigen::Vector3d(0.01, -0.015, 0.01);
  moved.coefficients[1] += 0.5;
  moved.jaw.x() += 0.1;
  const RowMatrixX3f posed_again = PosePatch(basis, moved, patch);
  const std::vector<Correspondence> fresh =
      ClosestPoints(model, posed_again, points, point_normals, ones, ones, gate, &patch);
  ASSERT_GT(fresh.size(), chosen.size() / 3);
  expect_same_pairs(posed_again, fresh, kept.Find(posed_again, points, point_normals, ones, ones, gate));
  // One search over the whole head, restricted to the patch (tracking keeps
  // one for every frame), answers as a search made on the patch.
  ClosestPointSearch whole_head(model, posed);
  whole_head.Restrict(patch);
  expect_same_pairs(posed_again, fresh, whole_head.Find(posed_again, points, point_normals, ones, ones, gate));
  ClosestPointSearch on_patch(model, posed_again, &patch);
  EXPECT_THROW(on_patch.Restrict(patch), std::logic_error);  // made over a patch already
}

TEST(MeshFitter, RecoversKnownParametersOfTheBuiltinHeadWithVertexNoise) {
  const HeadModel& model = Builtin();
  for (unsigned seed : {1u, 2u, 3u}) {
    const KnownHead k = MakeKnownHead(model, seed, 0.5e-3);
    const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{k.noisy, model.data().faces}, MeshFitOptions{});
    EXPECT_TRUE(fit.same_topology);
    const double face_mm = FaceRmsMm(model, fit, k.clean);
    const double shape_err = (fit.params.shape - k.params.shape).cwiseAbs().maxCoeff();
    const double expr_err = (fit.params.expression - k.params.expression).cwiseAbs().maxCoeff();
    const double rot_deg = MatrixToAxisAngle(fit.rotation.transpose() * k.rotation).norm() * 180 / M_PI;
    std::printf(
        "seed %u: face RMS vs truth %.3f mm, residual %.3f mm, |d shape| %.4f, |d expr| %.4f, rot %.3f deg, "
        "trans %.3f mm, jaw %.4f rad\n",
        seed, face_mm, 1e3 * fit.rms_m, shape_err, expr_err, rot_deg, 1e3 * (fit.translation - k.translation).norm(),
        (fit.params.pose.segment<3>(6) - k.params.pose.segment<3>(6)).norm());
    // Coefficients are compared through the mesh they make: the built-in head's
    // expression fields 9 and 10 are exact opposites (one signed mouth field
    // twice), so single coefficients are not identifiable, the surface is.
    EXPECT_LT(face_mm, 0.15);
    EXPECT_LT(rot_deg, 0.1);
    EXPECT_LT((fit.translation - k.translation).norm(), 0.5e-3);
    EXPECT_NEAR(fit.rms_m, 0.5e-3 * std::sqrt(3.0), 0.2e-3);  // the noise itself is what remains
    EXPECT_LT((fit.params.pose.segment<3>(6) - k.params.pose.segment<3>(6)).norm(), 0.01);

    // The identity use: a neutral scan, shape only.
    KnownHead neutral = k;
    neutral.params.expression.setZero();
    neutral.params.pose.setZero();
    neutral.clean = FittedVertices(model, neutral.Truth());
    neutral.noisy = neutral.clean + (k.noisy - k.clean);
    MeshFitOptions shape_only;
    shape_only.fit_expression = shape_only.fit_jaw = false;
    const MeshFitResult id = FitHeadModelToMesh(model, TriangleMesh{neutral.noisy, model.data().faces}, shape_only);
    const double id_err = (id.params.shape - neutral.params.shape).cwiseAbs().maxCoeff();
    std::printf("seed %u, neutral, shape only: |d shape| %.4f, face RMS vs truth %.3f mm\n", seed, id_err,
                FaceRmsMm(model, id, neutral.clean));
    EXPECT_LT(id_err, 0.1);
  }
}

// Scans carry hair and clothing the model cannot represent: with 12 mm of
// hair, fits with each weighting (squared loss: the weights alone make the
// difference); the mean face RMS against the truth, mm.
std::array<double, 3> FaceErrorWithHair(const HeadModel& model, int trials) {
  std::array<double, 3> mean = {0, 0, 0};
  const MeshWeighting weightings[3] = {MeshWeighting::kUniform, MeshWeighting::kImportance,
                                       MeshWeighting::kImportanceAndCount};
  for (int t = 0; t < trials; ++t) {
    SyntheticScanOptions so;
    so.seed = 10 + t;
    so.noise_m = 0.3e-3;
    so.hair_m = 0.012;
    const SyntheticScan k = MakeSyntheticScan(model, so);
    for (int w = 0; w < 3; ++w) {
      MeshFitOptions o;
      o.weighting = weightings[w];
      o.loss = MeshLoss::kSquared;
      const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{k.noisy, model.data().faces}, o);
      mean[w] += FaceRmsMm(model, fit, k.clean) / trials;
    }
  }
  std::printf("%s: face RMS vs truth with hair, mean of %d: uniform %.3f mm, nu %.3f mm, nu*phi %.3f mm\n",
              model.data().name.c_str(), trials, mean[0], mean[1], mean[2]);
  return mean;
}

TEST(MeshFitter, ImportanceWeightsPayOffOnTheFace) {
  const HeadModel& model = Builtin();
  const std::array<double, 3> e = FaceErrorWithHair(model, 3);
  EXPECT_LT(e[1], 0.7 * e[0]);
  EXPECT_LT(e[2], 0.7 * e[0]);
  // The paper's norm with the weights on a clean scan stays near the noise.
  const KnownHead k = MakeKnownHead(model, 10, 0.3e-3);
  const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{k.noisy, model.data().faces}, MeshFitOptions{});
  EXPECT_LT(FaceRmsMm(model, fit, k.clean), 0.2);
}

std::vector<std::pair<int, Eigen::Vector3d>> LandmarksOf(const HeadModel& model, const KnownHead& k) {
  const HeadModelOutput out = model.Forward(k.params);
  std::vector<std::pair<int, Eigen::Vector3d>> l;
  for (int i : {36, 39, 42, 45, 30, 33, 48, 54, 8})  // eye corners, nose, mouth corners, chin
    l.emplace_back(i, k.rotation * out.landmarks.row(i).cast<double>().transpose() + k.translation);
  return l;
}

TEST(MeshFitter, FitsAMeshOfAnotherTopology) {
  const HeadModel& model = Builtin();
  const KnownHead k = MakeKnownHead(model, 21, 0.0);
  const TriangleMesh posed{k.clean, model.data().faces};
  const TriangleMesh variants[2] = {ClusterDecimate(posed, 0.006), SubdivideMidpoints(posed)};
  const char* names[2] = {"decimated", "subdivided"};
  for (int v = 0; v < 2; ++v) {
    MeshFitOptions o;
    o.target_landmarks = LandmarksOf(model, k);
    // Landmarks picked by hand are a few millimetres off.
    std::mt19937 rng(v);
    std::normal_distribution<double> g(0, 2e-3);
    for (auto& [i, p] : o.target_landmarks) p += Eigen::Vector3d(g(rng), g(rng), g(rng));
    const MeshFitResult fit = FitHeadModelToMesh(model, variants[v], o);
    EXPECT_FALSE(fit.same_topology);
    const double face_mm = FaceRmsMm(model, fit, k.clean);
    std::printf("%s (%ld vertices): face RMS vs truth %.3f mm, surface residual %.3f mm, %d rounds, %d pairs\n",
                names[v], static_cast<long>(variants[v].vertices.rows()), face_mm, 1e3 * fit.rms_m, fit.rounds,
                fit.correspondences);
    for (double r : fit.round_rms_m) std::printf(" %.3f", 1e3 * r);
    std::printf("\n");
    EXPECT_LT(face_mm, v == 0 ? 1.5 : 0.3);
    EXPECT_GT(fit.correspondences, 0.9 * variants[v].vertices.rows());
  }
}

TEST(MeshFitter, BlackBoxModeRecoversParametersWithNumericDerivatives) {
  const HeadModel& model = Builtin();
  const KnownHead k = MakeKnownHead(model, 31, 0.2e-3);
  // The black box: 6 shape and 4 expression numbers -> vertices (the rest fixed at the truth's rigid pose).
  const int ns = 6, ne = 4;
  const MeshGenerator generator = [&](const Eigen::VectorXd& x, RowMatrixX3f* v) {
    MeshFitResult r;
    r.params.shape = Eigen::VectorXd::Zero(model.num_shape());
    r.params.expression = Eigen::VectorXd::Zero(model.num_expression());
    r.params.shape.head(ns) = x.head(ns);
    r.params.expression.head(ne) = x.tail(ne);
    r.params.pose = k.params.pose;
    r.rotation = k.rotation;
    r.translation = k.translation;
    *v = FittedVertices(model, r);
  };
  Eigen::VectorXd truth(ns + ne);
  truth << k.params.shape.head(ns), k.params.expression.head(ne);
  KnownHead partial = k;
  {
    // The target made by the black box itself at the truth, plus noise.
    RowMatrixX3f clean;
    generator(truth, &clean);
    std::mt19937 rng(1);
    std::normal_distribution<float> g(0, 0.2e-3f);
    partial.noisy = clean;
    for (Eigen::Index i = 0; i < clean.rows(); ++i)
      for (int c = 0; c < 3; ++c) partial.noisy(i, c) += g(rng);
  }
  MeshFitOptions o;
  o.num_shape = ns;
  o.num_expression = ne;
  const BlackBoxFitResult fit =
      FitBlackBoxToMesh(generator, Eigen::VectorXd::Zero(ns + ne), partial.noisy, MeshFitWeights(model, o));
  std::printf("black box: |d params| max %.4f, rms %.3f mm, %d generator calls\n",
              (fit.params - truth).cwiseAbs().maxCoeff(), 1e3 * fit.rms_m, fit.generator_calls);
  EXPECT_LT((fit.params - truth).cwiseAbs().maxCoeff(), 0.03);
  EXPECT_NEAR(fit.rms_m, 0.2e-3 * std::sqrt(3.0), 0.1e-3);
  EXPECT_THROW(FitBlackBoxToMesh(generator, Eigen::VectorXd::Zero(ns + ne), partial.noisy, Eigen::VectorXf::Ones(3)),
               std::invalid_argument);
}

std::string FitError(const TriangleMesh& mesh, MeshFitOptions o = {}) {
  try {
    FitHeadModelToMesh(Builtin(), mesh, o);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "no error";
}

TEST(MeshFitter, RefusesBadMeshesWithTheReason) {
  const HeadModel& model = Builtin();
  const TriangleMesh good{model.data().v_template, model.data().faces};
  EXPECT_NE(FitError(TriangleMesh{}).find("empty"), std::string::npos);
  TriangleMesh nan = good;
  nan.vertices(5, 1) = NAN;
  EXPECT_NE(FitError(nan).find("NaN"), std::string::npos);
  // A third face on an existing edge: non-manifold.
  TriangleMesh nm = good;
  nm.faces.conservativeResize(nm.faces.rows() + 1, 3);
  nm.faces.row(nm.faces.rows() - 1) << good.faces(0, 0), good.faces(0, 1), good.faces(500, 2);
  EXPECT_NE(FitError(nm).find("non-manifold"), std::string::npos) << FitError(nm);
  TriangleMesh cm = good;
  cm.vertices *= 100.0f;
  EXPECT_NE(FitError(cm).find("centimetres"), std::string::npos) << FitError(cm);
  TriangleMesh mm = good;
  mm.vertices *= 1000.0f;
  EXPECT_NE(FitError(mm).find("millimetres"), std::string::npos);
  TriangleMesh big = good;
  big.vertices *= 4.0f;
  EXPECT_NE(FitError(big).find("times the head model"), std::string::npos);
  MeshFitOptions same;
  same.correspondence = MeshCorrespondence::kSameTopology;
  const TriangleMesh coarse = ClusterDecimate(good, 0.006);
  EXPECT_NE(FitError(coarse, same).find("same-topology fit asked for"), std::string::npos);
  // Another topology without landmarks: told what it needs.
  EXPECT_NE(FitError(coarse).find("at least 4 landmarks"), std::string::npos);
  MeshFitOptions collinear;
  for (int i = 0; i < 5; ++i) collinear.target_landmarks.emplace_back(i, Eigen::Vector3d(0.01 * i, 0, 0));
  EXPECT_NE(FitError(coarse, collinear).find("collinear"), std::string::npos);
  MeshFitOptions bad_importance;
  bad_importance.importance = Eigen::VectorXf::Ones(7);
  EXPECT_NE(FitError(good, bad_importance).find("importance map has 7 values"), std::string::npos);
}

TEST(MeshFitter, IdentityJsonRoundTripsAndIsCheckedAgainstTheModel) {
  const HeadModel& model = Builtin();
  const KnownHead k = MakeKnownHead(model, 41, 0);
  const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{k.clean, model.data().faces}, MeshFitOptions{});
  const std::string dir = testing::TempDir("mesh_fit_json");
  WriteMeshFitJson(dir + "/p.json", model, fit);
  const Eigen::VectorXd shape = ReadIdentityFromMeshFit(dir + "/p.json", model);
  EXPECT_LT((shape - fit.params.shape).cwiseAbs().maxCoeff(), 1e-9);
  HeadModelData other = model.data();
  other.v_template *= 1.01f;
  EXPECT_THROW(ReadIdentityFromMeshFit(dir + "/p.json", HeadModel(other)), std::runtime_error);
  std::ofstream(dir + "/junk.json") << "{\"shape\": [1, 2";
  EXPECT_THROW(ReadIdentityFromMeshFit(dir + "/junk.json", model), std::runtime_error);
}

TEST(MeshFitter, IctFaceKitRecoveryAndWeights) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  IctConvertOptions io;
  io.folder = testing::DataDir() + "/head-models/ict-facekit";
  const HeadModel model = ConvertIctFaceKit(io);
  const KnownHead k = MakeKnownHead(model, 51, 0.5e-3);
  MeshFitOptions o;
  const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{k.noisy, model.data().faces}, o);
  const double face_mm = FaceRmsMm(model, fit, k.clean);
  std::printf("ICT-FaceKit (%d vertices): face RMS vs truth %.3f mm, |d shape| %.4f, |d expr| %.4f\n",
              model.num_vertices(), face_mm, (fit.params.shape - k.params.shape).cwiseAbs().maxCoeff(),
              (fit.params.expression - k.params.expression).cwiseAbs().maxCoeff());
  EXPECT_LT(face_mm, 0.2);
  EXPECT_LT((fit.params.shape - k.params.shape).cwiseAbs().maxCoeff(), 0.1);
  const std::array<double, 3> e = FaceErrorWithHair(model, 1);
  EXPECT_LT(e[1], e[0]);
  EXPECT_LT(e[2], e[0]);
}

}  // namespace
}  // namespace headcast
