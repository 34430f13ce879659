// Gaze: the iris locator on rendered eyes with known rotations, and the
// tracker's fit of the eye joints to the located irises. Rendered with the
// project's rasteriser: skin, white eyeballs and a dark iris disc of 6 mm.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/ict_converter.h"
#include "common/raster/rasterizer.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/iris_locator.h"
#include "common/tracking/landmark_costs.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Builtin() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

// ICT-FaceKit as converted by default: without its eye accessories (IctDefaultParts).
const HeadModel* Ict() {
  if (testing::DataDir().empty()) return nullptr;
  static const HeadModel m = [] {
    IctConvertOptions o;
    o.folder = testing::DataDir() + "/head-models/ict-facekit";
    o.max_identity = 0;
    return ConvertIctFaceKit(o);
  }();
  return &m;
}

std::vector<const HeadModel*> Models() {
  std::vector<const HeadModel*> models = {&Builtin()};
  if (const HeadModel* ict = Ict()) models.push_back(ict);
  return models;
}

struct Scene {
  cv::Mat gray;
  Landmarks2d landmarks;
  Eigen::Vector2d pupil[2];  // left, right: the projected pupil vertices
};

const PinholeCamera kCamera = PinholeCamera::FromFovY(640, 480, 45);

FrameParams Looking(const HeadModel& model, double pitch, double yaw) {
  FrameParams f;
  f.expression = Eigen::VectorXf::Zero(model.num_expression());
  f.SetCamFromHead(FrontalCamFromHead(0.4, 8, -4, model.rest_landmark_centroid()));
  f.left_eye = f.right_eye = Eigen::Vector3f(static_cast<float>(pitch), static_cast<float>(yaw), 0);
  return f;
}

Scene Render(const HeadModel& model, const FrameParams& f) {
  HeadModelParams p;
  p.expression = f.expression.cast<double>();
  p.pose = f.HeadPose();
  const HeadModelOutput out = model.Forward(p);
  RasterVertices in_cam;
  TransformToCamera(out.vertices, f.CamFromHead(), &in_cam);
  RasterBuffers buffers;
  Rasterize(in_cam, model.data().faces, kCamera, RasterOptions{}, &buffers);
  const HeadModelOutput rest = model.Forward(HeadModelParams{});
  // Per vertex: the cosine of its angle from its eye's axis (pivot to pupil) and an eyeball flag.
  Eigen::MatrixXf attribute = Eigen::MatrixXf::Zero(model.num_vertices(), 2);
  for (int i = 0; i < model.num_vertices(); ++i)
    for (int joint : {kLeftEyeJoint, kRightEyeJoint})
      if (model.data().weights(i, joint) > 0.5f) {
        const Eigen::RowVector3f axis =
            (rest.vertices.row(model.PupilVertex(joint)) - rest.joints.row(joint)).normalized();
        attribute(i, 0) = (rest.vertices.row(i) - rest.joints.row(joint)).normalized().dot(axis);
        attribute(i, 1) = 1;
      }
  const cv::Mat a = InterpolateVertexAttribute(buffers, model.data().faces, attribute);
  // A 6 mm iris radius on the model's own eyeball (builtin ~12 mm, ICT-FaceKit ~15.5 mm).
  const int pupil = model.PupilVertex(kLeftEyeJoint);
  const float ball = (rest.vertices.row(pupil) - rest.joints.row(kLeftEyeJoint)).norm();
  const float cos_iris = std::cos(std::asin(std::min(1.f, 0.006f / ball)));
  Scene s;
  s.gray.create(kCamera.height, kCamera.width, CV_8U);
  for (int y = 0; y < s.gray.rows; ++y)
    for (int x = 0; x < s.gray.cols; ++x) {
      uint8_t v = 60;  // background
      if (buffers.Covered(x, y)) {
        const cv::Vec2f c = a.at<cv::Vec2f>(y, x);
        v = c[1] < 0.99f ? 170 : c[0] > cos_iris ? 35 : 235;
      }
      s.gray.at<uint8_t>(y, x) = v;
    }
  cv::GaussianBlur(s.gray, s.gray, cv::Size(0, 0), 0.7);  // a camera's blur
  const RigidTransform cam_from_head = f.CamFromHead();
  for (int l = 0; l < kNumLandmarks; ++l)
    s.landmarks[l] = kCamera.Project(cam_from_head.Apply(out.landmarks.row(l).transpose().cast<double>()));
  const int joints[2] = {kLeftEyeJoint, kRightEyeJoint};
  for (int e = 0; e < 2; ++e)
    s.pupil[e] =
        kCamera.Project(cam_from_head.Apply(out.vertices.row(model.PupilVertex(joints[e])).transpose().cast<double>()));
  return s;
}

// Angle between the optical axes (+z at rest) of two eye rotations, degrees.
double AxisErrorDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  const Eigen::Vector3d za = AxisAngleToMatrix(a.cast<double>()).col(2);
  const Eigen::Vector3d zb = AxisAngleToMatrix(b.cast<double>()).col(2);
  return std::acos(std::clamp(za.dot(zb), -1.0, 1.0)) * 180 / M_PI;
}

// The coefficient named `name`, failing the test when the model has none.
int ExpressionIndexOrFail(const HeadModel& m, const char* name) {
  const int i = m.ExpressionIndex(name);
  EXPECT_GE(i, 0) << name;
  return i;
}

const double kGazes[][2] = {{0, 0}, {0, 0.3}, {0, -0.3}, {0.2, 0}, {-0.15, 0.2}, {0.1, -0.2}};

TEST(Gaze, ModelsHavePupilsInFrontOfTheirEyes) {
  for (const HeadModel* m : Models()) {
    SCOPED_TRACE(m->data().name);
    const HeadModelOutput rest = m->Forward(HeadModelParams{});
    for (int joint : {kLeftEyeJoint, kRightEyeJoint}) {
      const int pupil = m->PupilVertex(joint);
      ASSERT_GE(pupil, 0);
      EXPECT_GT(rest.vertices(pupil, 2), rest.joints(joint, 2) + 0.008);
      EXPECT_EQ(rest.vertices(pupil, 0) > 0, joint == kLeftEyeJoint);  // the subject's left is +x
    }
  }
}

// The tolerances are what the locator achieves on eyes ~33 px wide (a face at
// 40 cm through a 640x480 webcam): an iris half hidden by a lid is the hard case.
TEST(Gaze, IrisLocatorFindsRenderedIrises) {
  for (const HeadModel* m : Models()) {
    double sum = 0, worst = 0;
    int n = 0;
    for (const auto& g : kGazes) {
      SCOPED_TRACE(m->data().name + " gaze " + std::to_string(g[0]) + " " + std::to_string(g[1]));
      const Scene s = Render(*m, Looking(*m, g[0], g[1]));
      const EyeIrises irises = LocateIrises(s.gray, s.landmarks);
      ASSERT_TRUE(irises.left.found);
      ASSERT_TRUE(irises.right.found);
      for (double e : {(irises.left.center - s.pupil[0]).norm(), (irises.right.center - s.pupil[1]).norm()}) {
        EXPECT_LT(e, 3.5);
        sum += e;
        worst = std::max(worst, e);
        ++n;
      }
    }
    EXPECT_LT(sum / n, 1.5);
    std::cout << m->data().name << ": iris error mean " << sum / n << " px, worst " << worst << " px\n";
  }
}

TEST(Gaze, TrackerRecoversTheEyeRotation) {
  for (const HeadModel* m : Models()) {
    HeadFitter fitter(*m);
    double sum = 0, worst = 0;
    for (const auto& g : kGazes) {
      SCOPED_TRACE(m->data().name + " gaze " + std::to_string(g[0]) + " " + std::to_string(g[1]));
      const FrameParams truth = Looking(*m, g[0], g[1]);
      const Scene s = Render(*m, truth);
      const EyeIrises irises = LocateIrises(s.gray, s.landmarks);
      FrameParams fit = truth;
      fit.left_eye.setZero();
      fit.right_eye.setZero();
      ASSERT_TRUE(fitter.Fit(s.landmarks, kCamera, &fit, &irises).ok);
      const double error =
          std::max(AxisErrorDeg(fit.left_eye, truth.left_eye), AxisErrorDeg(fit.right_eye, truth.right_eye));
      EXPECT_LT(error, 8.0);
      sum += error;
      worst = std::max(worst, error);
      // What the overlay draws agrees with the model.
      Eigen::Vector2d left, right;
      ASSERT_TRUE(fitter.ProjectPupils(truth, kCamera, &left, &right));
      EXPECT_LT((left - s.pupil[0]).norm(), 1e-3);
      EXPECT_LT((right - s.pupil[1]).norm(), 1e-3);
    }
    const double mean = sum / std::size(kGazes);
    EXPECT_LT(mean, 5.0);
    std::cout << m->data().name << ": gaze error mean " << mean << " degrees, worst " << worst << " (gazes up to "
              << 0.3 * 180 / M_PI << " degrees)\n";
  }
}

TEST(Gaze, ClosedOrBrokenEyesGiveNoIrisAndTheFitHoldsTheGaze) {
  const HeadModel& m = Builtin();
  const FrameParams truth = Looking(m, 0.1, 0.2);
  const Scene s = Render(m, truth);
  Landmarks2d closed = s.landmarks;
  for (int first : {36, 42}) {  // lids together
    closed[first + 1] = closed[first + 5] = 0.5 * (s.landmarks[first + 1] + s.landmarks[first + 5]);
    closed[first + 2] = closed[first + 4] = 0.5 * (s.landmarks[first + 2] + s.landmarks[first + 4]);
  }
  const EyeIrises none = LocateIrises(s.gray, closed);
  EXPECT_FALSE(none.left.found);
  EXPECT_FALSE(none.right.found);
  EXPECT_LT(none.left.opening, 0.01);
  // Nothing to see: degenerate, non-finite and off-image eyes, an empty or colour image.
  Landmarks2d broken = s.landmarks;
  for (int l = 36; l < 42; ++l) broken[l] = Eigen::Vector2d(100, 100);
  for (int l = 42; l < 48; ++l) broken[l] = Eigen::Vector2d(NAN, 3);
  EXPECT_FALSE(LocateIrises(s.gray, broken).right.found);
  EXPECT_FALSE(LocateIrises(s.gray, broken).left.found);
  Landmarks2d away = s.landmarks;
  for (auto& p : away) p += Eigen::Vector2d(5000, -9000);
  EXPECT_FALSE(LocateIrises(s.gray, away).left.found);
  EXPECT_FALSE(LocateIrises(cv::Mat(), s.landmarks).left.found);
  EXPECT_FALSE(LocateIrises(cv::Mat(480, 640, CV_8UC3), s.landmarks).left.found);
  // A blink: the fit keeps the previous gaze rather than snapping to straight ahead.
  HeadFitter fitter(m);
  FrameParams f = truth;
  ASSERT_TRUE(fitter.Fit(closed, kCamera, &f, &none).ok);
  EXPECT_EQ(f.left_eye, truth.left_eye);
  EXPECT_EQ(f.right_eye, truth.right_eye);
}

// ICT's eyeLook shapes move the lids as a look would (eyeLookDown: the upper
// lid down most of the way to shut, the lower lid a little); a fit is free to
// close a lid with them instead of eyeBlink. Lids lowered by eyeLookDown, the
// eyes ahead and no iris found (as when dlib's lids meet): without the prior
// the fit finds eyeLookDown; with eye_look_prior the blink shapes take most of
// the lids (the lower lids' drop, which no blink shape makes, stays a residual).
TEST(Gaze, TheEyeLookPriorClosesLidsWithTheBlinkShapes) {
  const HeadModel* m = Ict();
  if (!m) GTEST_SKIP() << "needs ../shared/data (ICT-FaceKit)";
  const int blink[2] = {m->ExpressionIndex("eyeBlink_L"), m->ExpressionIndex("eyeBlink_R")};
  const int down[2] = {m->ExpressionIndex("eyeLookDown_L"), m->ExpressionIndex("eyeLookDown_R")};
  ASSERT_GE(std::min({blink[0], blink[1], down[0], down[1]}), 0);
  std::vector<int> look;
  for (int i = 0; i < m->num_expression(); ++i)
    if (m->data().expression_names[i].rfind("eyeLook", 0) == 0) look.push_back(i);
  ASSERT_EQ(look.size(), 8u);
  FrameParams truth = Looking(*m, 0, 0);
  for (int i : down) truth.expression[i] = 1;
  double fitted_blink[2], fitted_look[2];
  for (int with : {0, 1}) {
    HeadFitterOptions o;
    o.eye_look_prior = with ? 100 : 0;
    HeadFitter fitter(*m, o);
    FrameParams fit = truth;
    fit.expression.setZero();
    ASSERT_TRUE(fitter.Fit(fitter.Project(truth, kCamera), kCamera, &fit).ok);
    fitted_blink[with] = std::min(fit.expression[blink[0]], fit.expression[blink[1]]);
    fitted_look[with] = 0;
    for (int i : look) fitted_look[with] = std::max(fitted_look[with], std::abs(double(fit.expression[i])));
    std::cout << "eye_look_prior " << o.eye_look_prior << ": blink " << fitted_blink[with] << ", largest |eyeLook| "
              << fitted_look[with] << "\n";
  }
  EXPECT_GT(fitted_look[0], 0.7);  // the confusion the prior is for (0.78 with the default expression prior)
  EXPECT_LT(fitted_blink[0], 0.2);
  EXPECT_GT(fitted_blink[1], 0.4);  // measured 0.47 and 0.14
  EXPECT_LT(fitted_look[1], 0.2);
}

// The prior on the vertical eyeLook shapes only: lids lowered by eyeLookDown
// still close with the blink shapes, while the lids of a sideways look
// (eyeLookIn on one eye, eyeLookOut on the other) keep their own shapes,
// which the prior on all eight pulls toward zero.
TEST(Gaze, TheVerticalEyeLookPriorLeavesSidewaysLooks) {
  const HeadModel* m = Ict();
  if (!m) GTEST_SKIP() << "needs ../shared/data (ICT-FaceKit)";
  auto index = [&](const char* name) { return ExpressionIndexOrFail(*m, name); };
  const int blink = index("eyeBlink_L"), down = index("eyeLookDown_L");
  const int in = index("eyeLookIn_L"), out = index("eyeLookOut_R");
  auto fit = [&](const std::string& shapes, const std::vector<int>& truth_shapes) {
    HeadFitterOptions o;
    o.eye_look_prior = 100;
    o.eye_look_prior_shapes = shapes;
    HeadFitter fitter(*m, o);
    FrameParams truth = Looking(*m, 0, 0);
    for (int i : truth_shapes) truth.expression[i] = 1;
    FrameParams f = truth;
    f.expression.setZero();
    EXPECT_TRUE(fitter.Fit(fitter.Project(truth, kCamera), kCamera, &f).ok);
    return f.expression;
  };
  const Eigen::VectorXf lowered = fit("vertical", {index("eyeLookDown_L"), index("eyeLookDown_R")});
  const Eigen::VectorXf aside_all = fit("all", {in, out}), aside_vertical = fit("vertical", {in, out});
  std::cout << "lowered lids, vertical prior: blink " << lowered[blink] << ", eyeLookDown " << lowered[down]
            << "; a look aside: eyeLookIn_L / eyeLookOut_R " << aside_all[in] << " / " << aside_all[out] << " (all), "
            << aside_vertical[in] << " / " << aside_vertical[out] << " (vertical)\n";
  EXPECT_GT(lowered[blink], 0.4);
  EXPECT_LT(std::abs(lowered[down]), 0.2);
  EXPECT_GT(aside_vertical[in] + aside_vertical[out], aside_all[in] + aside_all[out] + 0.5);
  HeadFitterOptions wrong;
  wrong.eye_look_prior_shapes = "sideways";
  EXPECT_THROW(wrong.Check(), std::invalid_argument);
}

// The tie's target: the look's elevation over the shape's, within the
// shape's range 0..1; the residual's derivative is by the coefficient only.
TEST(Gaze, TheLidsTieTargetsTheLooksShareOfTheShape) {
  const LidGazeCost up(3, 1, Eigen::Vector3d(0, 0, 1), 1.0, 0.3, 10.0),
      down(3, 1, Eigen::Vector3d(0, 0, 1), -1.0, 0.6, 10.0);
  const double ahead[3] = {0, 0, 0}, raised[3] = {-0.15, 0, 0}, far_up[3] = {-0.6, 0, 0}, lowered[3] = {0.3, 0, 0};
  EXPECT_NEAR(up.Target(ahead), 0, 1e-9);
  EXPECT_NEAR(up.Target(raised), 0.5, 1e-6);  // +pitch turns the line of sight toward -y: down
  EXPECT_NEAR(up.Target(far_up), 1, 1e-9);
  EXPECT_NEAR(up.Target(lowered), 0, 1e-9);
  EXPECT_NEAR(down.Target(lowered), 0.5, 1e-6);
  const double expression[3] = {0.2, 0.7, -0.1};
  const double* blocks[2] = {expression, raised};
  double residual, d_expression[3], d_eye[3];
  double* jacobians[2] = {d_expression, d_eye};
  ASSERT_TRUE(up.Evaluate(blocks, &residual, jacobians));
  EXPECT_NEAR(residual, 10 * (0.7 - 0.5), 1e-6);
  EXPECT_EQ(d_expression[0], 0);
  EXPECT_EQ(d_expression[1], 10);
  EXPECT_EQ(d_expression[2], 0);
  for (double d : d_eye) EXPECT_EQ(d, 0);
}

// ICT's eyeLookUp raises the lids as a wide eye does; a fit free to choose
// takes raised lids over eyes that look ahead partly as a look up. With the
// lids tied to the pitch the irises show (lid_gaze_weight), wide eyes looking
// ahead are fitted with eyeWide and no eyeLookUp, while a real look up keeps
// the lids' eyeLookUp — which a prior toward zero (eye_look_prior) takes away.
TEST(Gaze, TheLidsFollowThePitchTheIrisesShow) {
  const HeadModel* m = Ict();
  if (!m) GTEST_SKIP() << "needs ../shared/data (ICT-FaceKit)";
  auto index = [&](const char* name) { return ExpressionIndexOrFail(*m, name); };
  const int wide[2] = {index("eyeWide_L"), index("eyeWide_R")}, up[2] = {index("eyeLookUp_L"), index("eyeLookUp_R")};
  struct Fitted {
    double wide, up;  // the two eyes' mean
    Eigen::Vector3f left_eye;
  };
  auto fit = [&](const FrameParams& truth, const HeadFitterOptions& o) {
    const Scene s = Render(*m, truth);
    const EyeIrises irises = LocateIrises(s.gray, s.landmarks);
    EXPECT_TRUE(irises.left.found && irises.right.found);
    HeadFitter fitter(*m, o);
    FrameParams f = truth;
    f.expression.setZero();
    f.left_eye.setZero();
    f.right_eye.setZero();
    EXPECT_TRUE(fitter.Fit(s.landmarks, kCamera, &f, &irises).ok);
    return Fitted{0.5 * (f.expression[wide[0]] + f.expression[wide[1]]),
                  0.5 * (f.expression[up[0]] + f.expression[up[1]]), f.left_eye};
  };
  FrameParams wide_ahead = Looking(*m, 0, 0);
  for (int i : wide) wide_ahead.expression[i] = 1;
  FrameParams looking_up = Looking(*m, -0.3, 0);  // +pitch turns the line of sight toward -y: down
  for (int i : up) looking_up.expression[i] = 0.7;
  HeadFitterOptions free, tied, zeroed;
  tied.lid_gaze_weight = 100;
  zeroed.eye_look_prior = 100;
  zeroed.eye_look_prior_shapes = "vertical";
  const Fitted wide_free = fit(wide_ahead, free), wide_tied = fit(wide_ahead, tied);
  const Fitted up_tied = fit(looking_up, tied), up_zeroed = fit(looking_up, zeroed);
  std::cout << "wide eyes ahead: eyeWide / eyeLookUp " << wide_free.wide << " / " << wide_free.up << " free, "
            << wide_tied.wide << " / " << wide_tied.up << " tied; a look up with its lids (eyeLookUp 0.7): eyeLookUp "
            << up_tied.up << " tied, " << up_zeroed.up << " with the vertical eyeLook prior\n";
  EXPECT_GT(wide_free.up, 0.2);  // the confusion the tie is for
  EXPECT_LT(wide_tied.up, 0.1);
  // The lids follow the gaze; they do not turn it toward a look that would explain them.
  EXPECT_LT(AxisErrorDeg(wide_tied.left_eye, wide_free.left_eye), 1.0);
  EXPECT_GT(wide_tied.wide, wide_free.wide + 0.1);
  EXPECT_GT(up_tied.up, 0.4);
  EXPECT_LT(up_zeroed.up, up_tied.up - 0.2);
  // Lids lowered by eyeLookDown over eyes that look ahead, no iris found (as
  // when dlib's lids meet): the held gaze is ahead, so the blink shapes shut them.
  FrameParams lowered = Looking(*m, 0, 0);
  const int blink = index("eyeBlink_L"), down = index("eyeLookDown_L");
  lowered.expression[down] = lowered.expression[index("eyeLookDown_R")] = 1;
  HeadFitter fitter(*m, tied);
  FrameParams f = lowered;
  f.expression.setZero();
  const EyeIrises none;
  ASSERT_TRUE(fitter.Fit(fitter.Project(lowered, kCamera), kCamera, &f, &none).ok);
  std::cout << "lids lowered by eyeLookDown, no iris, tied: eyeBlink_L " << f.expression[blink] << ", eyeLookDown_L "
            << f.expression[down] << "\n";
  EXPECT_GT(f.expression[blink], 0.4);
  EXPECT_LT(f.expression[down], 0.2);
  EXPECT_EQ(f.left_eye, lowered.left_eye);  // the held gaze is not moved by the lids
  HeadFitterOptions negative;
  negative.lid_gaze_weight = -1;
  EXPECT_THROW(HeadFitter(*m, negative), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
