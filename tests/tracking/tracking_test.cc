// Tracking: the fitter recovers known parameters from projected landmarks; the
// face tracker finds real landmarks (human-annotated ground truth in
// ../shared/data) and reports frames without a face as a status.
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "common/core/image_io.h"
#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/ict_converter.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/frame_tracker.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/landmark_costs.h"
#include "common/tracking/tracked_fit.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

double AngleDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  const Eigen::Matrix3d R = AxisAngleToMatrix(a.cast<double>()).transpose() * AxisAngleToMatrix(b.cast<double>());
  return MatrixToAxisAngle(R).norm() * 180 / M_PI;
}

struct RecoveryErrors {
  double angle_deg = 0, lateral_m = 0, depth_m = 0, reprojection_px = 0;  // the worst trial
  double outside_range = 0;  // the farthest a fitted coefficient lies outside the model's expression range
  double angle_rms_deg = 0, depth_rms_m = 0;  // root mean square over the trials
  // 1 px Gaussian noise is unbounded, so no fit keeps every draw within a
  // limit: the 95th percentiles say how far a typical bad frame is off.
  double angle_p95_deg = 0, translation_p95_m = 0;
  double translation_m = 0;  // the worst trial's 3D translation error
  // The Cramer-Rao bound at the true parameters (RMS over the trials): the
  // least standard deviation any fit of these landmarks with this noise, these
  // free parameters and this expression prior can have.
  double angle_bound_deg = 0, depth_bound_m = 0;
};

double Percentile(std::vector<double> values, double p) {
  std::sort(values.begin(), values.end());
  return values[static_cast<size_t>(std::lround(p * (values.size() - 1)))];
}

// Information about the pose in 68 landmarks with 1 px noise: the inverse of
// the Fisher matrix J^T J (+ the priors' curvature, as the fit weighs them) of
// the projection with respect to rotation, translation, expression and jaw.
void CramerRaoBound(const HeadFitter& fitter, const HeadModel& model, const FrameParams& truth,
                    const PinholeCamera& cam, double* angle_sigma_deg, double* depth_sigma_m) {
  const HeadFitterOptions& o = fitter.options();
  const int E = static_cast<int>(truth.expression.size());
  const int P = 6 + E + (model.JointIsArticulated(kJawJoint) ? 3 : 0);
  auto param = [E](FrameParams& f, int i) -> float& {
    if (i < 3) return f.cam_rotation[i];
    if (i < 6) return f.cam_translation[i - 3];
    if (i < 6 + E) return f.expression[i - 6];
    return f.jaw[i - 6 - E];
  };
  Eigen::MatrixXd J(2 * kNumLandmarks, P);
  for (int i = 0; i < P; ++i) {
    FrameParams plus = truth, minus = truth;
    const float h = i >= 3 && i < 6 ? 1e-4f : 1e-3f;  // metres; radians and coefficients
    param(plus, i) += h;
    param(minus, i) -= h;
    const Landmarks2d a = fitter.Project(plus, cam), b = fitter.Project(minus, cam);
    for (int l = 0; l < kNumLandmarks; ++l)
      J.block<2, 1>(2 * l, i) = (l < kNumContourLandmarks ? o.contour_weight : 1.0) * (a[l] - b[l]) / (2.0 * h);
  }
  Eigen::MatrixXd fisher = J.transpose() * J;
  for (int k = 6; k < 6 + E; ++k) fisher(k, k) += o.expression_prior;
  for (int k = 6 + E; k < P; ++k) fisher(k, k) += o.jaw_prior;
  const Eigen::MatrixXd covariance = fisher.inverse();
  *angle_sigma_deg = std::sqrt(covariance.topLeftCorner<3, 3>().trace()) * 180 / M_PI;
  *depth_sigma_m = std::sqrt(covariance(5, 5));
}

// Where the synthetic heads are seen from. The landmarks' 1 px noise means
// less the more pixels the face spans, so the scene decides what a fit can
// recover (the Cramer-Rao bound below).
struct RecoveryScene {
  PinholeCamera camera;
  double distance_m;  // camera to the head's landmark centroid (+-0.1 m over the trials)
};

// A webcam's 640x480 at 45 degrees vertically, the head at 0.6 m: 86 px
// between the outer eye corners, a smaller face than in any of the real clips.
RecoveryScene WebcamScene() { return {PinholeCamera::FromFovY(640, 480, 45), 0.6}; }

// The real clips' framing (../shared/data/video): headcast-track --calibrate
// on talking_d9 (512x480) finds a focal length of 640 px and the head at a
// median 0.40 m, 141 px between the outer eye corners -- the smallest face
// of the four clips (the others: 144, 161 and 178 px).
RecoveryScene TalkingHeadScene() {
  PinholeCamera cam = PinholeCamera::FromFovY(512, 480, 45);
  cam.fx = cam.fy = 640;
  return {cam, 0.40};
}

// Projects known heads' landmarks (+1 px noise) and fits them cold, then warm;
// the worst errors over the trials. Blendshape models (ICT) get expressions in [0, 0.8].
RecoveryErrors RecoverSyntheticHeads(const HeadModel& model, int trials, bool blendshapes,
                                     const RecoveryScene& scene = WebcamScene()) {
  const PinholeCamera& cam = scene.camera;
  HeadFitterOptions options;
  options.expression_prior = 0.1;
  options.contour_weight = 1.0;
  HeadFitter fitter(model, options);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0, 1.0);  // 1 px
  std::uniform_real_distribution<double> u(-1, 1);
  RecoveryErrors worst;
  std::vector<double> angles, translations;
  for (int trial = 0; trial < trials; ++trial) {
    FrameParams truth;
    truth.expression = Eigen::VectorXf::Zero(model.num_expression());
    for (int k = 0; k < truth.expression.size(); ++k)
      truth.expression[k] = static_cast<float>(blendshapes ? 0.4 * (1 + u(rng)) * (u(rng) > 0.6) : 0.8 * u(rng));
    if (model.JointIsArticulated(kJawJoint)) truth.jaw = Eigen::Vector3f(static_cast<float>(0.15 * (1 + u(rng))), 0, 0);
    truth.SetCamFromHead(
        FrontalCamFromHead(scene.distance_m + 0.1 * u(rng), 25 * u(rng), 10 * u(rng), model.rest_landmark_centroid()));
    const Landmarks2d clean = fitter.Project(truth, cam);
    Landmarks2d observed;
    for (int l = 0; l < kNumLandmarks; ++l) observed[l] = clean[l] + Eigen::Vector2d(noise(rng), noise(rng));
    FrameParams fit;  // cold start: PnP, then the full fit
    fit.expression = Eigen::VectorXf::Zero(model.num_expression());
    const LandmarkFitResult r = fitter.Fit(observed, cam, &fit);
    EXPECT_TRUE(r.ok);
    LandmarkFitResult again = fitter.Fit(observed, cam, &fit);  // a warm-started frame
    EXPECT_TRUE(again.ok);
    const double angle = AngleDeg(fit.cam_rotation, truth.cam_rotation);
    worst.angle_deg = std::max(worst.angle_deg, angle);
    const Eigen::Vector3f dt = fit.cam_translation - truth.cam_translation;
    worst.lateral_m = std::max<double>(worst.lateral_m, dt.head<2>().norm());
    worst.depth_m = std::max<double>(worst.depth_m, std::abs(dt.z()));
    angles.push_back(angle);
    translations.push_back(dt.norm());
    double angle_bound, depth_bound;
    CramerRaoBound(fitter, model, truth, cam, &angle_bound, &depth_bound);
    worst.angle_rms_deg += angle * angle / trials;
    worst.depth_rms_m += dt.z() * dt.z() / trials;
    worst.angle_bound_deg += angle_bound * angle_bound / trials;
    worst.depth_bound_m += depth_bound * depth_bound / trials;
    const Landmarks2d reprojected = fitter.Project(fit, cam);
    double mean = 0;
    for (int l = 0; l < kNumLandmarks; ++l) mean += (reprojected[l] - clean[l]).norm() / kNumLandmarks;
    worst.reprojection_px = std::max(worst.reprojection_px, mean);  // mean over the 68, worst frame
    for (float e : fit.expression)
      worst.outside_range = std::max<double>(
          worst.outside_range,
          std::max(model.data().expression_min - e, e - model.data().expression_max));  // -inf for PCA models
  }
  for (double* rms : {&worst.angle_rms_deg, &worst.depth_rms_m, &worst.angle_bound_deg, &worst.depth_bound_m})
    *rms = std::sqrt(*rms);
  worst.angle_p95_deg = Percentile(angles, 0.95);
  worst.translation_p95_m = Percentile(translations, 0.95);
  worst.translation_m = *std::max_element(translations.begin(), translations.end());
  std::printf(
      "%s, worst of %d: angle %.2f deg, lateral %.2f mm, depth %.2f mm, reprojection %.2f px, %.3f outside the "
      "expression range\n  RMS over the trials: angle %.2f deg, depth %.2f mm; Cramer-Rao bound (RMS sigma): angle "
      "%.2f deg, depth %.2f mm\n  95th percentile: angle %.2f deg, translation %.2f mm (worst %.2f mm)\n",
      model.data().name.c_str(), trials, worst.angle_deg, 1e3 * worst.lateral_m, 1e3 * worst.depth_m,
      worst.reprojection_px, worst.outside_range, worst.angle_rms_deg, 1e3 * worst.depth_rms_m, worst.angle_bound_deg,
      1e3 * worst.depth_bound_m, worst.angle_p95_deg, 1e3 * worst.translation_p95_m, 1e3 * worst.translation_m);
  return worst;
}

TEST(HeadFitter, RecoversPoseAndExpressionFromNoisyLandmarks) {
  const RecoveryErrors worst = RecoverSyntheticHeads(Model(), 10, false);
  EXPECT_LT(worst.angle_deg, 1.0);
  EXPECT_LT(worst.lateral_m, 0.001);
  // Depth is the weak direction of a monocular fit. At 0.6 m in a 640x480,
  // 45-degree camera, 1 px noise leaves the depth a standard deviation of
  // 2.3-3.8 mm however it is fitted (the Cramer-Rao bound per trial), so a
  // worst of ten within 5 mm is beyond what the landmarks hold (measured 7.2 mm;
  // unchanged by expression priors 0.01..30). What the fit can do is reach
  // the bound: its RMS depth error sits at it (measured 3.15 against 2.98 mm).
  EXPECT_LT(worst.depth_rms_m, 0.005);
  EXPECT_LT(worst.depth_rms_m, 1.25 * worst.depth_bound_m);
  EXPECT_LT(worst.depth_m, 0.008);
  EXPECT_LT(worst.reprojection_px, 1.5);
}

TEST(HeadFitter, RecoversIctFaceKitHeads) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  IctConvertOptions io;
  io.folder = testing::DataDir() + "/head-models/ict-facekit";
  const HeadModel ict = ConvertIctFaceKit(io);
  const RecoveryErrors worst = RecoverSyntheticHeads(ict, 10, true);
  // 53 blendshapes absorb more of the noise than the built-in head's PCA:
  // worst of ten measured 1.52 deg and 5.1 mm, RMS 0.76 deg and 2.9 mm, below
  // the unbiased bound (1.29 deg, 4.49 mm) because the 0..1 box adds information.
  EXPECT_LT(worst.angle_rms_deg, 1.0);
  EXPECT_LT(worst.depth_rms_m, 0.005);
  EXPECT_LT(worst.angle_deg, 2.0);
  EXPECT_LT(worst.lateral_m, 0.002);
  EXPECT_LT(worst.depth_m, 0.015);
  EXPECT_LT(worst.reprojection_px, 1.5);
  EXPECT_LT(worst.outside_range, 0.1);  // ARKit coefficients stay in 0..1 (a soft box: measured 0.08)
}

// The figures (pose within 1 degree, translation within 5 mm,
// reprojection within 1.5 px) at the real clips' framing, over 100 heads each.
void CheckRecoveryAtTheClipsFraming(const RecoveryErrors& e) {
  EXPECT_LT(e.angle_p95_deg, 1.0);
  EXPECT_LT(e.translation_m, 0.005);
  EXPECT_LT(e.reprojection_px, 1.5);
  EXPECT_LT(e.angle_rms_deg, e.angle_bound_deg);  // the fit's prior adds what the landmarks lack
  EXPECT_LT(e.depth_rms_m, 1.25 * e.depth_bound_m);
}

TEST(HeadFitter, RecoversHeadsFramedAsInTheRealClips) {
  CheckRecoveryAtTheClipsFraming(RecoverSyntheticHeads(Model(), 100, false, TalkingHeadScene()));
}

TEST(HeadFitter, RecoversIctFaceKitHeadsFramedAsInTheRealClips) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  IctConvertOptions io;
  io.folder = testing::DataDir() + "/head-models/ict-facekit";
  CheckRecoveryAtTheClipsFraming(RecoverSyntheticHeads(ConvertIctFaceKit(io), 100, true, TalkingHeadScene()));
}

// The sender's and headcast-track's per-frame rule: warm while tracked, cold after a loss.
TEST(FitTrackedFace, WarmWhileTrackedColdAfterALoss) {
  const PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 45);
  HeadFitter fitter(Model());
  FrameParams truth;
  truth.expression = Eigen::VectorXf::Zero(Model().num_expression());
  truth.SetCamFromHead(FrontalCamFromHead(0.6, 10, 0, Model().rest_landmark_centroid()));
  FaceObservation face;
  face.status = FaceStatus::kDetected;
  face.landmarks = fitter.Project(truth, cam);
  FrameParams p;
  p.cam_translation.setZero();
  ASSERT_TRUE(FitTrackedFace(fitter, face, cam, &p).ok);
  EXPECT_NEAR(p.cam_translation.z(), truth.cam_translation.z(), 1e-3);
  face.status = FaceStatus::kNoFace;  // lost: not fitted, and the next face starts cold
  EXPECT_FALSE(FitTrackedFace(fitter, face, cam, &p).ok);
  EXPECT_EQ(p.cam_translation.z(), 0.f);
  // A stale expression from before the loss: one solver iteration shows where
  // each start leads (a fresh detection starts neutral; a tracked face keeps it).
  HeadFitterOptions one;
  one.max_iterations = 1;
  one.expression_prior = 2e-3;  // weak: one iteration shows where each start leads, not where the prior pulls
  const HeadFitter short_fitter(Model(), one);
  FrameParams fresh = p, kept = p;
  fresh.cam_translation.setZero();
  fresh.expression.setConstant(3.f);
  kept.expression.setConstant(3.f);
  face.status = FaceStatus::kDetected;
  ASSERT_TRUE(FitTrackedFace(short_fitter, face, cam, &fresh).ok);
  face.status = FaceStatus::kTracked;
  FitTrackedFace(short_fitter, face, cam, &kept);
  std::printf("after one iteration: max |psi| %.3f from a fresh detection, %.3f warm from the stale one\n",
              fresh.expression.cwiseAbs().maxCoeff(), kept.expression.cwiseAbs().maxCoeff());
  EXPECT_LT(fresh.expression.cwiseAbs().maxCoeff(), 0.3f);
  EXPECT_GT(kept.expression.cwiseAbs().maxCoeff(), 0.3f);
}

// A model that declares a natural expression range (as ICT's blendshapes do)
// gets fits inside it: the built-in head with its coefficients declared 0..1.
TEST(HeadFitter, KeepsExpressionsInTheModelsRange) {
  HeadModelData d = Model().data();
  d.expression_min = 0;
  d.expression_max = 1;
  const HeadModel boxed(std::move(d));
  const RecoveryErrors worst = RecoverSyntheticHeads(boxed, 10, true);
  EXPECT_LT(worst.outside_range, 0.1);  // a soft box: measured 0.08
  EXPECT_LT(worst.angle_deg, 1.0);
  EXPECT_LT(worst.reprojection_px, 1.5);
}

// Identity calibration over key frames: a known shape and focal length, the
// head turning -35..35 degrees, 1 px landmark noise, the focal length guessed 20 % too short.
TEST(HeadFitter, CalibratesShapeAndFocalLengthOverKeyFrames) {
  const HeadModel& model = Model();
  const PinholeCamera truth_cam = PinholeCamera::FromFovY(640, 480, 40);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 1.0);
  std::uniform_real_distribution<double> u(-1, 1);
  HeadModelParams p;
  p.shape = Eigen::VectorXd(model.num_shape());
  for (auto& v : p.shape) v = u(rng);
  std::vector<Landmarks2d> key_frames;
  for (int f = 0; f < 9; ++f) {
    p.expression = Eigen::VectorXd::Zero(model.num_expression());
    for (int k = 0; k < 3; ++k) p.expression[k] = 0.3 * u(rng);
    const HeadModelOutput out = model.Forward(p);
    const RigidTransform cam_from_head =
        FrontalCamFromHead(0.6 + 0.1 * u(rng), -35 + 70.0 * f / 8, 10 * u(rng), model.rest_landmark_centroid());
    Landmarks2d l;
    for (int k = 0; k < kNumLandmarks; ++k)
      l[k] = truth_cam.Project(cam_from_head.Apply(out.landmarks.row(k).cast<double>().transpose())) +
             Eigen::Vector2d(noise(rng), noise(rng));
    key_frames.push_back(l);
  }
  PinholeCamera guess = truth_cam;
  guess.fx *= 0.8;
  guess.fy *= 0.8;
  HeadFitterOptions options;
  options.contour_weight = 1.0;
  HeadFitter fitter(model, options);
  const HeadFitter::Calibration c = fitter.CalibrateIdentity(key_frames, guess);
  ASSERT_TRUE(c.ok);
  // The shape judged by the landmarks it places (rest pose, neutral), relative to their spread.
  HeadModelParams fitted;
  fitted.shape = c.shape;
  HeadModelParams truth_neutral;
  truth_neutral.shape = p.shape;
  const auto a = model.Forward(fitted).landmarks, b = model.Forward(truth_neutral).landmarks;
  Eigen::RowVector3f ca = a.colwise().mean(), cb = b.colwise().mean();
  double err = 0;
  for (int k = 0; k < kNumLandmarks; ++k) err += ((a.row(k) - ca) - (b.row(k) - cb)).norm();
  err /= kNumLandmarks;
  const double focal_error = std::abs(c.camera.fx / truth_cam.fx - 1);
  std::printf(
      "calibration over %d frames: focal %.1f px (truth %.1f, start %.1f, error %.1f %%), landmark shape "
      "error %.2f mm, rms %.2f px\n",
      c.frames, c.camera.fx, truth_cam.fx, guess.fx, 100 * focal_error, 1e3 * err, c.rms_px);
  EXPECT_EQ(c.frames, 9);
  EXPECT_LT(focal_error, 0.06);
  EXPECT_LT(err, 2.5e-3);
  EXPECT_LT(c.rms_px, 1.6);
}

// What every key frame shows belongs to the identity: a person whose shape
// differs from the model's mean, neutral in every key frame. With a shape prior
// that makes shape dear against expression, the plain calibration holds part of
// the difference as an expression repeated in every frame; the penalty on the
// key frames' mean expression moves it into the shape.
TEST(HeadFitter, CalibrationMovesTheRepeatedExpressionIntoTheShape) {
  const HeadModel& model = Model();
  const PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 40);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  HeadModelParams p;
  p.shape = Eigen::VectorXd(model.num_shape());
  for (auto& v : p.shape) v = 1.5 * u(rng);
  const HeadModelOutput out = model.Forward(p);
  std::vector<Landmarks2d> key_frames;
  for (int f = 0; f < 7; ++f) {
    const RigidTransform cam_from_head = FrontalCamFromHead(0.6, -30 + 10.0 * f, 0, model.rest_landmark_centroid());
    Landmarks2d l;
    for (int k = 0; k < kNumLandmarks; ++k)
      l[k] = cam.Project(cam_from_head.Apply(out.landmarks.row(k).cast<double>().transpose()));
    key_frames.push_back(l);
  }
  struct Outcome {
    double mean_expression, shape_error;
  };
  auto calibrate = [&](double mean_weight) {
    HeadFitterOptions options;
    options.shape_prior = 0.3;
    // A per-frame prior as weak as the one the term was made against (the
    // default's is strong enough to keep most of the shape out of psi already).
    options.expression_prior = 2e-3;
    options.calibration_mean_expression = mean_weight;
    HeadFitter fitter(model, options);
    std::vector<FrameParams> frames;
    const HeadFitter::Calibration c = fitter.CalibrateIdentity(key_frames, cam, &frames, true);
    EXPECT_TRUE(c.ok);
    Eigen::VectorXf mean = Eigen::VectorXf::Zero(model.num_expression());
    for (const FrameParams& f : frames) mean += f.expression / static_cast<float>(frames.size());
    HeadModelParams fitted;
    fitted.shape = c.shape;
    const auto a = model.Forward(fitted).landmarks;  // neutral, rest pose
    double err = 0;
    for (int k = 0; k < kNumLandmarks; ++k) err += (a.row(k) - out.landmarks.row(k)).norm() / kNumLandmarks;
    return Outcome{mean.norm(), err};
  };
  const Outcome plain = calibrate(0), penalised = calibrate(100);
  std::printf("mean expression over the key frames %.3f -> %.3f, neutral landmark error %.2f -> %.2f mm\n",
              plain.mean_expression, penalised.mean_expression, 1e3 * plain.shape_error, 1e3 * penalised.shape_error);
  EXPECT_GT(plain.mean_expression, 0.05);  // the case this is about: without the penalty the frames hold it
  EXPECT_LT(penalised.mean_expression, 0.5 * plain.mean_expression);
  EXPECT_LT(penalised.shape_error, 0.92 * plain.shape_error);
}

// Landmarks that a wrong expression fit explains by sliding the head: the
// observed landmarks are the true ones moved 6 px up (as if the whole face had
// moved), while rigid points above the brows are seen where the true pose puts
// them. With the rigid points the fitted head stays near the truth.
TEST(HeadFitter, RigidPointsHoldTheHeadWhereTheLandmarksPullIt) {
  const HeadModel& model = Model();
  const PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 40);
  FrameParams truth;
  truth.expression = Eigen::VectorXf::Zero(model.num_expression());
  truth.SetCamFromHead(FrontalCamFromHead(0.6, 10, 5, model.rest_landmark_centroid()));
  HeadFitterOptions options;
  options.rigid_flow_weight = 1;
  const HeadFitter fitter(model, options);
  RigidObservations rigid;
  fitter.RigidPointsInView(truth, cam, &rigid.head, &rigid.observed);
  ASSERT_GE(rigid.head.size(), 20u) << "the built-in head has rigid points above the brows in view";
  Landmarks2d observed = fitter.Project(truth, cam);
  for (auto& l : observed) l.y() -= 6;
  // How far the rigid points above the brows land from where the true pose puts them (mean, px).
  auto fit = [&](const RigidObservations* r) {
    FrameParams f = truth;
    EXPECT_TRUE(fitter.Fit(observed, cam, &f, nullptr, r).ok);
    std::vector<Eigen::Vector2d> at;
    fitter.ProjectRigidPoints(f, cam, rigid.head, &at);
    double sum = 0;
    for (size_t i = 0; i < at.size(); ++i) sum += (at[i] - rigid.observed[i]).norm() / at.size();
    return sum;
  };
  const double plain = fit(nullptr), held = fit(&rigid);
  std::printf("rigid points off by: landmarks only %.2f px, with %zu rigid points %.2f px\n", plain, rigid.head.size(),
              held);
  EXPECT_GT(plain, 4.0);  // the landmarks alone move the head by ~6 px
  EXPECT_LT(held, 0.5 * plain);
}

// Pyramidal Lucas-Kanade from a reference frame: a textured image moved by a
// known sub-pixel offset is found within 0.1 px; a point on a flat patch
// (nothing to follow) is dropped; the head-frame points travel with their pixels.
TEST(FollowRigidPoints, FindsAKnownShiftAndDropsPointsWithoutTexture) {
  cv::Mat reference(240, 320, CV_8U);
  cv::RNG rng(3);
  rng.fill(reference, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(reference, reference, cv::Size(0, 0), 2.0);
  reference(cv::Rect(200, 20, 100, 100)).setTo(128);  // flat
  const cv::Point2d shift(2.4, -1.7);
  cv::Mat moved;
  const cv::Mat affine = (cv::Mat_<double>(2, 3) << 1, 0, shift.x, 0, 1, shift.y);
  cv::warpAffine(reference, moved, affine, reference.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
  RigidObservations seen;
  std::vector<Eigen::Vector2d> predicted;
  for (int i = 0; i < 6; ++i) {
    seen.head.emplace_back(i, 0, 0);
    seen.observed.emplace_back(60 + 20 * i, 150);
    predicted.push_back(seen.observed.back());  // no prior motion: the flow finds it
  }
  seen.head.emplace_back(99, 0, 0);
  seen.observed.emplace_back(250, 70);  // on the flat patch
  predicted.push_back(seen.observed.back());
  const RigidObservations found = FollowRigidPoints(seen, reference, moved, predicted);
  ASSERT_EQ(found.head.size(), 6u);
  for (size_t i = 0; i < found.head.size(); ++i) {
    EXPECT_EQ(found.head[i].x(), static_cast<double>(i));
    EXPECT_NEAR(found.observed[i].x(), seen.observed[i].x() + shift.x, 0.1);
    EXPECT_NEAR(found.observed[i].y(), seen.observed[i].y() + shift.y, 0.1);
  }
  EXPECT_TRUE(FollowRigidPoints(seen, reference, moved, {}).head.empty());  // a prediction per point or nothing
}

// Given intrinsics are a measurement: calibration must not move the focal length.
TEST(HeadFitter, CalibrationKeepsAKnownFocalLength) {
  const HeadModel& model = Model();
  const PinholeCamera truth_cam = PinholeCamera::FromFovY(640, 480, 40);
  std::vector<Landmarks2d> key_frames;
  HeadModelParams p;
  p.shape = Eigen::VectorXd::Zero(model.num_shape());
  for (int f = 0; f < 5; ++f) {
    const HeadModelOutput out = model.Forward(p);
    const RigidTransform cam_from_head = FrontalCamFromHead(0.6, -30 + 15.0 * f, 0, model.rest_landmark_centroid());
    Landmarks2d l;
    for (int k = 0; k < kNumLandmarks; ++k)
      l[k] = truth_cam.Project(cam_from_head.Apply(out.landmarks.row(k).cast<double>().transpose()));
    key_frames.push_back(l);
  }
  PinholeCamera given = truth_cam;
  given.fx *= 0.9;
  given.fy *= 0.9;
  HeadFitter fitter(model, HeadFitterOptions{});
  const HeadFitter::Calibration free = fitter.CalibrateIdentity(key_frames, given);
  HeadFitter fixed_fitter(model, HeadFitterOptions{});
  const HeadFitter::Calibration fixed = fixed_fitter.CalibrateIdentity(key_frames, given, nullptr, true);
  ASSERT_TRUE(free.ok);
  ASSERT_TRUE(fixed.ok);
  EXPECT_DOUBLE_EQ(fixed.camera.fx, given.fx);
  EXPECT_DOUBLE_EQ(fixed.camera.fy, given.fy);
  EXPECT_GT(std::abs(free.camera.fx - given.fx), 0.01 * given.fx);  // free calibration does move it
}

// ceres::GradientChecker on the landmark residuals (per-frame, written out; calibration, autodiff).
TEST(HeadFitter, LandmarkResidualJacobiansMatchNumericOnes) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-1, 1);
  const PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 40);
  const int E = 4, S = 3;
  Eigen::Matrix<double, 3, Eigen::Dynamic> edirs(3, E), sdirs(3, S), jdirs(3, S);
  for (int k = 0; k < E; ++k) edirs.col(k) = 0.01 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  for (int k = 0; k < S; ++k) {
    sdirs.col(k) = 0.01 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    jdirs.col(k) = 0.005 * Eigen::Vector3d(u(rng), u(rng), u(rng));
  }
  double rotation[3] = {M_PI + 0.1, 0.2, -0.05}, translation[3] = {0.01, -0.02, 0.6}, jaw[3] = {0.15, 0.01, 0};
  double expression[E] = {0.3, -0.2, 0.5, 0.1}, shape[S] = {0.5, -0.4, 0.2}, log_focal = 0.05;
  const Eigen::Vector3d base(0.02, -0.04, 0.08), joint(0, -0.02, -0.01);
  ceres::NumericDiffOptions numeric;
  {
    auto* cost = new LandmarkCost(base, edirs, 0.7, joint, Eigen::Vector2d(300, 260), cam, 1.0);
    std::unique_ptr<ceres::CostFunction> owned(cost);
    const std::vector<const ceres::Manifold*> none(4, nullptr);
    ceres::GradientChecker checker(cost, &none, numeric);
    ceres::GradientChecker::ProbeResults results;
    double* blocks[] = {rotation, translation, expression, jaw};
    EXPECT_TRUE(checker.Probe(blocks, 1e-5, &results)) << results.error_log;
    double closed_jaw[3] = {0, 0, 0};  // the rotation's small-angle branch
    double* closed[] = {rotation, translation, expression, closed_jaw};
    EXPECT_TRUE(checker.Probe(closed, 1e-5, &results)) << results.error_log;
  }
  {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<CalibrationResidual, 8>(
        new CalibrationResidual(base, edirs, sdirs, 0.7, joint, jdirs, Eigen::Vector2d(300, 260), cam, 1.0));
    for (int size : {3, 3, E, 3, S, 1}) cost->AddParameterBlock(size);
    cost->SetNumResiduals(2);
    std::unique_ptr<ceres::CostFunction> owned(cost);
    const std::vector<const ceres::Manifold*> none(6, nullptr);
    ceres::GradientChecker checker(cost, &none, numeric);
    ceres::GradientChecker::ProbeResults results;
    double* blocks[] = {rotation, translation, expression, jaw, shape, &log_focal};
    EXPECT_TRUE(checker.Probe(blocks, 1e-5, &results)) << results.error_log;
  }
}

TEST(OneEuroFilter, SmoothsNoiseAndFollowsMotion) {
  OneEuroFilter f(1.0, 0.05);
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0, 1);
  double raw_var = 0, filtered_var = 0;
  for (int i = 0; i < 300; ++i) {
    const double x = n(rng);
    const double y = f.Filter(x, i / 30.0);
    if (i > 30) raw_var += x * x, filtered_var += y * y;
  }
  EXPECT_LT(filtered_var, 0.3 * raw_var);
  OneEuroFilter g(1.0, 0.05);
  double y = 0;
  for (int i = 0; i < 60; ++i) y = g.Filter(100.0 * (i >= 10), i / 30.0);
  EXPECT_NEAR(y, 100.0, 2.0);  // a step is followed within 1.5 s
}

// A face moving at constant speed with noisy landmarks: the two-sided
// smoothing follows it without the forward filter's lag and with less noise
// than the raw points; a frame without a face splits the runs.
TEST(SmoothTrackTwoSided, NoLagLessNoiseAndRunsSplitAtLostFaces) {
  const int n = 240;
  const double speed = 60;  // pixels a second
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 1.0);
  std::vector<FaceObservation> track(n);
  std::vector<double> times(n);
  OneEuroFilter forward(1.5, 0.05);
  double lag_forward = 0, lag_two_sided = 0, raw_error = 0, smooth_error = 0, forward_x = 0;
  for (int i = 0; i < n; ++i) {
    times[i] = i / 30.0;
    FaceObservation& o = track[i];
    o.status = i == 120 ? FaceStatus::kNoFace : FaceStatus::kTracked;
    for (int l = 0; l < kNumLandmarks; ++l) o.raw[l] = Eigen::Vector2d(speed * times[i] + l + noise(rng), 5.0 * l);
    o.irises.left.found = i % 2 == 0;
    o.irises.left.center = Eigen::Vector2d(7, 8);
  }
  SmoothTrackTwoSided(&track, times, 1.5, 0.05);
  for (int i = 0; i < n; ++i) {
    forward_x = forward.Filter(track[i].raw[0].x(), times[i]);
    if (i < 30 || (i > 90 && i < 150) || i > 210) continue;  // away from the runs' ends
    const double truth = speed * times[i];
    lag_forward += (truth - forward_x) / 60;
    lag_two_sided += (truth - track[i].landmarks[0].x()) / 60;
    raw_error += std::pow(track[i].raw[0].x() - truth, 2);
    smooth_error += std::pow(track[i].landmarks[0].x() - truth, 2);
  }
  EXPECT_GT(lag_forward, 1.0);                                  // the forward filter draws the face over a pixel behind
  EXPECT_LT(std::abs(lag_two_sided), 0.25);                     // the two-sided one where it is
  EXPECT_LT(smooth_error, 0.5 * raw_error);                     // and steadier than the points found
  EXPECT_EQ(track[120].landmarks[0], Eigen::Vector2d::Zero());  // the lost frame is left alone
  // Irises found every other frame: runs of one frame, kept as found.
  EXPECT_EQ(track[10].irises.left.center, Eigen::Vector2d(7, 8));
  std::vector<double> backwards = times;
  std::swap(backwards[3], backwards[4]);
  EXPECT_THROW(SmoothTrackTwoSided(&track, backwards, 1.5, 0.05), std::invalid_argument);
  EXPECT_THROW(SmoothTrackTwoSided(&track, std::vector<double>(5), 1.5, 0.05), std::invalid_argument);
}

Landmarks2d ReadPts(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  Landmarks2d pts{};
  int n = 0;
  while (std::getline(in, line) && n < kNumLandmarks) {
    double x, y;
    if (std::sscanf(line.c_str(), "%lf %lf", &x, &y) == 2) pts[n++] = Eigen::Vector2d(x - 1, y - 1);  // .pts is 1-based
  }
  return pts;
}

TEST(FaceTracker, LandmarksMatchHumanAnnotations) {
  HEADCAST_REQUIRE_DATA("landmarks/einstein.jpg");
  FaceTracker tracker;
  for (const std::string name : {"einstein.jpg", "takeo.ppm"}) {
    const std::string base = testing::DataDir() + "/landmarks/" + name;
    const cv::Mat image = ReadImage(base);
    tracker.Reset();
    const FaceObservation obs = tracker.Track(image, 0);
    ASSERT_EQ(obs.status, FaceStatus::kDetected) << name;
    const Landmarks2d truth = ReadPts(base.substr(0, base.rfind('.')) + ".pts");
    const double err = LandmarkErrorIod(obs.raw, truth);
    RecordProperty(name + "_error_iod", std::to_string(err));
    EXPECT_LT(err, 0.08) << name;
  }
}

TEST(FaceTracker, MirroredLandmarksPairTheSides) {
  for (int l = 0; l < kNumLandmarks; ++l) EXPECT_EQ(MirroredLandmark(MirroredLandmark(l)), l) << l;
  EXPECT_EQ(MirroredLandmark(0), 16);   // the jaw's ends
  EXPECT_EQ(MirroredLandmark(8), 8);    // the chin
  EXPECT_EQ(MirroredLandmark(17), 26);  // the brows' outer ends
  EXPECT_EQ(MirroredLandmark(30), 30);  // the nose tip
  EXPECT_EQ(MirroredLandmark(36), 45);  // the eyes' outer corners
  EXPECT_EQ(MirroredLandmark(39), 42);  // and inner ones
  EXPECT_EQ(MirroredLandmark(37), 44);  // upper lids
  EXPECT_EQ(MirroredLandmark(41), 46);  // lower lids
  EXPECT_EQ(MirroredLandmark(48), 54);  // the mouth's corners
  EXPECT_EQ(MirroredLandmark(57), 57);  // the lower lip's middle
  EXPECT_EQ(MirroredLandmark(60), 64);  // the inner corners
  EXPECT_EQ(MirroredLandmark(65), 67);
  EXPECT_THROW(MirroredLandmark(68), std::out_of_range);
  EXPECT_THROW(MirroredLandmark(-1), std::out_of_range);
}

// Several views of the face: on the annotated pictures the median of the
// views stays as close to the human points as the box alone (the figures are
// in the test's properties), and the points found in a mirrored picture,
// mirrored back, come closer to those of the picture itself: with the box and
// its mirror among the views only the detector's box differs between the two.
TEST(FaceTracker, PredictorViewsKeepTheLandmarksAndMirrorWithThePicture) {
  HEADCAST_REQUIRE_DATA("landmarks/einstein.jpg");
  const std::array<int, 3> counts = {1, 2, kMaxPredictorViews};
  std::vector<std::unique_ptr<FaceTracker>> trackers;
  for (const int views : counts) {
    FaceTrackerOptions o;
    o.predictor_views = views;
    trackers.push_back(std::make_unique<FaceTracker>(o));
  }
  int mirrors_found = 0;
  for (const std::string name : {"einstein.jpg", "takeo.ppm"}) {
    const std::string base = testing::DataDir() + "/landmarks/" + name;
    const cv::Mat image = ReadImage(base);
    cv::Mat mirrored;
    cv::flip(image, mirrored, 1);
    const Landmarks2d truth = ReadPts(base.substr(0, base.rfind('.')) + ".pts");
    double one_view_asymmetry = -1;
    for (size_t k = 0; k < counts.size(); ++k) {
      FaceTracker& tracker = *trackers[k];
      tracker.Reset();
      const FaceObservation obs = tracker.Track(image, 0);
      ASSERT_EQ(obs.status, FaceStatus::kDetected) << name;
      const double err = LandmarkErrorIod(obs.raw, truth);
      RecordProperty(name + "_views" + std::to_string(counts[k]) + "_error_iod", std::to_string(err));
      EXPECT_LT(err, 0.08) << name << " " << counts[k];
      tracker.Reset();
      const FaceObservation back = tracker.Track(mirrored, 0);
      if (back.status != FaceStatus::kDetected) {  // HOG is not mirror-symmetric: it misses Einstein's mirror
        std::printf("%s, %d views: %.4f IOD from the annotation; no face found in the mirror\n", name.c_str(),
                    counts[k], err);
        continue;
      }
      Landmarks2d unmirrored;
      for (int l = 0; l < kNumLandmarks; ++l)
        unmirrored[MirroredLandmark(l)] = Eigen::Vector2d(image.cols - 1 - back.raw[l].x(), back.raw[l].y());
      const double asymmetry = LandmarkErrorIod(unmirrored, obs.raw);
      std::printf("%s, %d views: %.4f IOD from the annotation, %.4f between picture and mirror\n", name.c_str(),
                  counts[k], err, asymmetry);
      if (k == 0)
        one_view_asymmetry = asymmetry, ++mirrors_found;
      else
        EXPECT_LT(asymmetry, 0.75 * one_view_asymmetry) << name << " " << counts[k];
    }
  }
  EXPECT_GT(mirrors_found, 0);
}

// predictor_views_points: the points it names are the views' median (those
// of the six-view tracker that takes it for all), the others the box's own
// (the one-view tracker's).
TEST(FaceTracker, PredictorViewsPointsChooseWhichTakeTheMedian) {
  HEADCAST_REQUIRE_DATA("landmarks/takeo.ppm");
  const cv::Mat image = ReadImage(testing::DataDir() + "/landmarks/takeo.ppm");
  auto found = [&image](int views, const std::string& points) {
    FaceTrackerOptions o;
    o.predictor_views = views;
    o.predictor_views_points = points;
    FaceTracker tracker(o);
    const FaceObservation obs = tracker.Track(image, 0);
    EXPECT_EQ(obs.status, FaceStatus::kDetected) << points;
    return obs.raw;
  };
  const Landmarks2d box = found(1, "all"), all = found(kMaxPredictorViews, "all");
  for (const std::string points : {"no-eyes", "outline"}) {
    const Landmarks2d mixed = found(kMaxPredictorViews, points);
    double box_points_moved_by_the_views = 0;
    int median_points = 0;
    for (int l = 0; l < kNumLandmarks; ++l) {
      const bool eye = l >= 36 && l <= 47, outline = l <= 16 || (l >= 27 && l <= 35);
      const bool median = points == "no-eyes" ? !eye : outline;
      median_points += median;
      EXPECT_EQ(mixed[l], median ? all[l] : box[l]) << points << " " << l;
      if (!median) box_points_moved_by_the_views += (all[l] - box[l]).norm();
    }
    EXPECT_EQ(median_points, points == "no-eyes" ? 56 : 26);
    EXPECT_GT(box_points_moved_by_the_views, 0) << points << ": the views' median should differ from the box here";
  }
  FaceTrackerOptions o;
  o.predictor_views_points = "eyes";
  EXPECT_THROW(o.Check(), std::invalid_argument);
}

// A face that moved: the filtered landmarks lag behind the found ones, the
// unfiltered (FaceTrackerOptions::filter off, what prep uses) are the found ones.
TEST(FaceTracker, UnfilteredLandmarksDoNotLagAMovedFace) {
  HEADCAST_REQUIRE_DATA("landmarks/einstein.jpg");
  const cv::Mat image = ReadImage(testing::DataDir() + "/landmarks/einstein.jpg");
  cv::Mat moved;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 8, 0, 1, 0);
  cv::warpAffine(image, moved, shift, image.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  for (const bool filter : {true, false}) {
    FaceTrackerOptions o;
    o.filter = filter;
    FaceTracker tracker(o);
    ASSERT_EQ(tracker.Track(image, 0).status, FaceStatus::kDetected);
    const FaceObservation obs = tracker.Track(moved, 1 / 30.0);
    ASSERT_NE(obs.status, FaceStatus::kNoFace);
    double lag = 0;
    for (int l = 0; l < kNumLandmarks; ++l) lag += (obs.raw[l].x() - obs.landmarks[l].x()) / kNumLandmarks;
    if (filter)
      EXPECT_GT(lag, 3.0);  // of the 8 pixels moved, the filter shows less than 5
    else
      EXPECT_EQ(lag, 0.0);
  }
}

// Tracking a still face from its own landmarks must stay where the detector
// put it. A box of another convention than the detector's makes the shape
// predictor see a bigger face every frame: on talking_d9 fixed margins let the
// landmarks drift up to 0.32 of the eye distance before the next detection.
TEST(FaceTracker, TrackedBoxDoesNotDriftOnAStillFace) {
  HEADCAST_REQUIRE_DATA("landmarks/einstein.jpg");
  const cv::Mat image = ReadImage(testing::DataDir() + "/landmarks/einstein.jpg");
  auto drift_after = [&](bool box_from_detection) {
    FaceTrackerOptions o;
    o.box_from_detection = box_from_detection;
    o.redetect_interval = 1000;
    o.max_scale_change_since_detection = 10;  // measured here: the drift, not its recovery
    FaceTracker tracker(o);
    const FaceObservation first = tracker.Track(image, 0);
    EXPECT_EQ(first.status, FaceStatus::kDetected);
    FaceObservation last;
    for (int i = 1; i <= 20; ++i) last = tracker.Track(image, i / 30.0);
    EXPECT_EQ(last.status, FaceStatus::kTracked);
    return LandmarkErrorIod(last.raw, first.raw);
  };
  const double calibrated = drift_after(true), fixed = drift_after(false);
  RecordProperty("drift_iod_box_from_detection", std::to_string(calibrated));
  RecordProperty("drift_iod_fixed_margins", std::to_string(fixed));
  std::printf("drift after 20 tracked frames of a still face: %.4f IOD (fixed margins %.4f)\n", calibrated, fixed);
  EXPECT_LT(calibrated, 0.01);
}

// Followed boxes can creep off a face a few percent a frame until the
// landmarks sit on the mouth (the shipped demo sequence did at its frame 146,
// and the fit and the avatar followed; at its frames 142-147 the landmarks
// shrank onto the lower face within 25 % of the last detection's extent). The
// tracker notices the landmarks' width or height leaving that of the last
// detection by 10 % and detects again: on the whole sequence the extent stays
// within the face's own.
TEST(FaceTracker, ABoxCreepingOffTheFaceIsDetectedAgain) {
  const char* src = std::getenv("HEADCAST_SOURCE_DIR");
  const std::string video = std::string(src ? src : ".") + "/models/demo/demo_sequence.mp4";
  if (!std::filesystem::exists(video)) GTEST_SKIP() << "no " << video;
  VideoReader reader(video);
  FaceTracker tracker;
  std::vector<double> widths, heights;
  int recovered = 0;
  cv::Mat frame;
  for (int i = 0; reader.Read(&frame); ++i) {
    const FaceObservation obs = tracker.Track(frame, i / 30.0);
    ASSERT_NE(obs.status, FaceStatus::kNoFace) << "frame " << i;
    double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
    for (const auto& p : obs.raw) {
      x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x());
      y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
    }
    widths.push_back(x1 - x0);
    heights.push_back(y1 - y0);
    recovered += obs.recovered;
  }
  ASSERT_GT(widths.size(), 100u);
  std::vector<double> sorted = widths;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::printf("demo sequence: %zu frames, %d recovered, face width %.0f px (min %.0f, max %.0f)\n", widths.size(),
              recovered, median, sorted.front(), sorted.back());
  EXPECT_GT(sorted.front(), 0.8 * median);
  EXPECT_LT(sorted.back(), 1.25 * median);
  // The creep shrinks the landmarks onto the lower face: their height shows it first.
  std::sort(heights.begin(), heights.end());
  const double median_height = heights[heights.size() / 2];
  std::printf("landmark height %.0f px (min %.0f, max %.0f)\n", median_height, heights.front(), heights.back());
  EXPECT_GT(heights.front(), 0.85 * median_height);
}

TEST(FaceTracker, NoFaceTwoFacesAndGarbageAreStatuses) {
  FaceTrackerOptions o;
  FaceTracker tracker(o);
  EXPECT_EQ(tracker.Track(cv::Mat::zeros(480, 640, CV_8UC3), 0).status, FaceStatus::kNoFace);
  EXPECT_EQ(tracker.Track(cv::Mat(), 0.1).status, FaceStatus::kNoFace);
  EXPECT_EQ(tracker.Track(cv::Mat::zeros(10, 10, CV_8UC1), 0.2).status, FaceStatus::kNoFace);
  o.predictor_path = "/nonexistent/predictor.dat";
  EXPECT_THROW(FaceTracker bad(o), std::runtime_error);
  if (testing::DataDir().empty()) GTEST_SKIP() << "two-face part needs ../shared/data";
  const cv::Mat face = ReadImage(testing::DataDir() + "/landmarks/einstein.jpg");
  cv::Mat two;
  cv::hconcat(face, face, two);
  tracker.Reset();
  const FaceObservation first = tracker.Track(two, 0.3);
  ASSERT_NE(first.status, FaceStatus::kNoFace);
  EXPECT_EQ(first.faces_detected, 2);
  // Following the same face: the box stays on the side it started.
  const bool left = first.box.x < face.cols;
  for (int i = 1; i < 5; ++i) {
    const FaceObservation next = tracker.Track(two, 0.3 + i / 30.0);
    ASSERT_NE(next.status, FaceStatus::kNoFace);
    EXPECT_EQ(next.box.x < face.cols, left);
  }
}

}  // namespace
}  // namespace headcast
