// RGB-D fitting (METHOD §3) on rendered depth with known parameters: the 3D
// reconstruction accuracy noise-free and at 0.5/1/2 mm depth noise, and with
// background depth leaking into the face border (the stereo weakness), with
// and without the contour-landmark check.
#include "common/tracking/rgbd_fitter.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/mesh_fitter.h"

namespace headcast {
namespace {

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

struct RgbdScene {
  HeadModelParams params;
  RigidTransform cam_from_head;
  PinholeCamera camera;
  cv::Mat depth;  // head + a wall 1.4 m away
  cv::Mat mask;
  Landmarks2d landmarks;
  RowMatrixX3f vertices_cam;  // true vertices, camera frame
};

RgbdScene MakeScene(unsigned seed, double yaw_deg) {
  const HeadModel& model = Model();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  RgbdScene s;
  s.params.shape = Eigen::VectorXd(model.num_shape());
  s.params.expression = Eigen::VectorXd(model.num_expression());
  for (auto& v : s.params.shape) v = u(rng);
  for (auto& v : s.params.expression) v = 0.5 * u(rng);
  s.params.pose[3 * kJawJoint] = 0.1 + 0.05 * u(rng);
  s.camera = PinholeCamera::FromFovY(640, 480, 45);
  s.cam_from_head = FrontalCamFromHead(0.55, yaw_deg, 5 * u(rng), model.rest_landmark_centroid());
  const HeadModelOutput out = model.Forward(s.params);
  const HeadRender r = RenderHead(model, out.vertices, s.cam_from_head, s.camera, AlbedoTexture(model));
  s.mask = r.mask;
  s.depth = r.depth.clone();
  s.depth.setTo(1.4f, r.mask == 0);
  // Landmarks of the view (FLAME-style contours follow the yaw).
  PoseVector pose = s.params.pose;
  pose.segment<3>(0) = ViewRotation(s.cam_from_head.rotation);
  Eigen::Matrix<float, kNumLandmarks, 3, Eigen::RowMajor> lmk;
  model.ComputeLandmarks(out.vertices, pose, &lmk);
  for (int l = 0; l < kNumLandmarks; ++l)
    s.landmarks[l] = s.camera.Project(s.cam_from_head.Apply(lmk.row(l).cast<double>().transpose()));
  s.vertices_cam.resize(out.vertices.rows(), 3);
  for (Eigen::Index i = 0; i < out.vertices.rows(); ++i)
    s.vertices_cam.row(i) =
        s.cam_from_head.Apply(out.vertices.row(i).cast<double>().transpose()).cast<float>().transpose();
  return s;
}

// RMS distance of the fitted face from the true one over the vertices the
// camera sees (face region, importance >= 1, depth-visible), mm: a single view
// says nothing about the far cheek or the back of the head.
double FaceErrorMm(const RgbdScene& s, const RgbdFitResult& fit) {
  const HeadModel& model = Model();
  const Eigen::VectorXf nu = DefaultImportance(model);
  const RowMatrixX3f v = model.Forward(fit.params).vertices;
  double ss = 0;
  int n = 0;
  for (int i = 0; i < model.num_vertices(); ++i) {
    if (nu[i] < 1) continue;
    const Eigen::Vector3d truth = s.vertices_cam.row(i).cast<double>().transpose();
    const Eigen::Vector2d px = s.camera.Project(truth);
    const int x = static_cast<int>(std::lround(px.x())), y = static_cast<int>(std::lround(px.y()));
    if (x < 0 || y < 0 || x >= s.camera.width || y >= s.camera.height || s.mask.at<uchar>(y, x) == 0) continue;
    if (std::abs(s.depth.at<float>(y, x) - truth.z()) > 1e-3) continue;  // hidden
    const Eigen::Vector3d fitted = fit.rotation * v.row(i).cast<double>().transpose() + fit.translation;
    ss += (fitted - truth).squaredNorm();
    ++n;
  }
  return n == 0 ? INFINITY : 1e3 * std::sqrt(ss / n);
}

TEST(RgbdFitter, NoiseFreeDepthIsReconstructedToATenthOfAMillimetre) {
  for (double yaw : {0.0, 25.0}) {
    const RgbdScene s = MakeScene(1, yaw);
    RgbdFitter fitter(Model());
    const RgbdFitResult fit = fitter.Fit(s.landmarks, s.depth, s.camera);
    ASSERT_TRUE(fit.ok) << fit.problem;
    const double face_mm = FaceErrorMm(s, fit);
    std::printf(
        "yaw %.0f: accuracy %.3f mm (%d of %d points paired), visible face vs truth %.3f mm, landmarks %.2f mm, "
        "contour rejected %d\n",
        yaw, 1e3 * fit.accuracy_m, fit.paired_points, fit.cloud_points, face_mm, 1e3 * fit.landmark_rmse_m,
        fit.contour_rejected);
    EXPECT_LT(fit.accuracy_m, 0.2e-3);
    EXPECT_LT(face_mm, 0.5);
  }
}

TEST(RgbdFitter, AccuracyAtDepthNoise) {
  const RgbdScene s = MakeScene(2, 10);
  for (double noise_mm : {0.5, 1.0, 2.0}) {
    cv::Mat noisy = s.depth.clone();
    cv::Mat n(noisy.size(), CV_32F);
    cv::randn(n, 0, noise_mm * 1e-3);
    noisy += n;
    RgbdFitter fitter(Model());
    const RgbdFitResult fit = fitter.Fit(s.landmarks, noisy, s.camera);
    ASSERT_TRUE(fit.ok) << fit.problem;
    const double face_mm = FaceErrorMm(s, fit);
    std::printf("depth noise %.1f mm: accuracy %.3f mm, visible face vs truth %.3f mm\n", noise_mm,
                1e3 * fit.accuracy_m, face_mm);
    // The accuracy measures the residual, which is the noise itself; the surface stays much closer to the truth.
    EXPECT_LT(fit.accuracy_m, 1.3 * noise_mm * 1e-3 + 0.1e-3);
    EXPECT_LT(face_mm, 0.6 * noise_mm + 0.8);
  }
}

// Stereo fattens the background into the face border: the outer ring of the
// head takes the wall's depth, so contour landmarks there read 1.4 m.
TEST(RgbdFitter, BackgroundDepthAtTheContourIsHandled) {
  const RgbdScene s = MakeScene(3, 15);
  cv::Mat eroded;
  cv::erode(s.mask, eroded, cv::getStructuringElement(cv::MORPH_ELLIPSE, {13, 13}));
  cv::Mat leaked = s.depth.clone();
  leaked.setTo(1.4f, eroded == 0);
  double errors[2];
  for (int reject = 0; reject < 2; ++reject) {
    RgbdFitOptions o;
    o.reject_background_contour = reject == 1;
    RgbdFitter fitter(Model(), o);
    const RgbdFitResult fit = fitter.Fit(s.landmarks, leaked, s.camera);
    ASSERT_TRUE(fit.ok) << fit.problem;
    errors[reject] = FaceErrorMm(s, fit);
    std::printf(
        "background leak, contour check %s: %d contour landmarks rejected, accuracy %.3f mm, visible face vs truth "
        "%.3f mm\n",
        reject ? "on " : "off", fit.contour_rejected, 1e3 * fit.accuracy_m, errors[reject]);
    if (reject) {
      EXPECT_GT(fit.contour_rejected, 3);
    }
  }
  EXPECT_LT(errors[1], 0.6);
  EXPECT_LE(errors[1], errors[0]);
}

TEST(RgbdFitter, FrozenIdentityAndWarmStart) {
  const RgbdScene s = MakeScene(4, -10);
  RgbdFitOptions o;
  o.fit_shape = false;
  RgbdFitter fitter(Model(), o);
  fitter.SetIdentity(s.params.shape);
  const RgbdFitResult first = fitter.Fit(s.landmarks, s.depth, s.camera);
  ASSERT_TRUE(first.ok) << first.problem;
  EXPECT_LT((first.params.shape - s.params.shape).cwiseAbs().maxCoeff(), 1e-9);  // frozen
  const RgbdFitResult second = fitter.Fit(s.landmarks, s.depth, s.camera, &first);
  ASSERT_TRUE(second.ok);
  EXPECT_LT(second.accuracy_m, 0.2e-3);
  EXPECT_LT(FaceErrorMm(s, second), 1.0);
}

TEST(RgbdFitter, BadInputIsAStatusNotACrash) {
  const RgbdScene s = MakeScene(5, 0);
  RgbdFitter fitter(Model());
  EXPECT_FALSE(fitter.Fit(s.landmarks, cv::Mat(), s.camera).ok);
  const RgbdFitResult wrong = fitter.Fit(s.landmarks, cv::Mat(240, 320, CV_32F, 0.5f), s.camera);
  EXPECT_FALSE(wrong.ok);
  EXPECT_NE(wrong.problem.find("320x240"), std::string::npos) << wrong.problem;
  const RgbdFitResult empty = fitter.Fit(s.landmarks, cv::Mat(480, 640, CV_32F, 0.f), s.camera);
  EXPECT_FALSE(empty.ok);
  EXPECT_NE(empty.problem.find("landmarks have depth"), std::string::npos) << empty.problem;
  Landmarks2d nan = s.landmarks;
  for (auto& p : nan) p = Eigen::Vector2d(NAN, NAN);
  EXPECT_FALSE(fitter.Fit(nan, s.depth, s.camera).ok);
}

}  // namespace
}  // namespace headcast
