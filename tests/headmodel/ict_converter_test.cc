// ICT-FaceKit conversion on the real model in ../shared/data (skipped without it).
#include "common/headmodel/ict_converter.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "common/headmodel/head_model_io.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Ict() {
  static const HeadModel model = [] {
    IctConvertOptions o;
    o.folder = testing::DataDir() + "/head-models/ict-facekit";
    return ConvertIctFaceKit(o);
  }();
  return model;
}

Eigen::RowVector3f EyeCentre(const HeadModelOutput& out, int first) {
  Eigen::RowVector3f s = Eigen::RowVector3f::Zero();
  for (int i = first; i < first + 6; ++i) s += out.landmarks.row(i);
  return s / 6;
}

TEST(IctConverter, ConvertsTheSharedSubset) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  const HeadModel& m = Ict();
  EXPECT_EQ(m.num_vertices(), 24591);  // every part but the 2128 vertices of eye_accessories
  EXPECT_EQ(m.num_expression(), 53);
  EXPECT_EQ(m.num_shape(), 20);
  EXPECT_GE(m.ExpressionIndex("jawOpen"), 0);
  EXPECT_TRUE(m.JointIsArticulated(kRootJoint));
  for (int j : {kNeckJoint, kJawJoint}) EXPECT_FALSE(m.JointIsArticulated(j));
  for (int j : {kLeftEyeJoint, kRightEyeJoint}) EXPECT_TRUE(m.JointIsArticulated(j));
  const HeadModelOutput rest = m.Forward(HeadModelParams{});
  // Metres: eye centres 5-8 cm apart, outer eye corners ~8.9 cm as upstream says.
  const float iod = (EyeCentre(rest, 42) - EyeCentre(rest, 36)).norm();
  EXPECT_GT(iod, 0.05f);
  EXPECT_LT(iod, 0.08f);
  EXPECT_NEAR((rest.landmarks.row(45) - rest.landmarks.row(36)).norm(), 0.089, 0.005);
  // Landmarks on the face, in the project's head frame: left eye at +x, nose out at +z.
  EXPECT_GT(EyeCentre(rest, 42).x(), EyeCentre(rest, 36).x());
  EXPECT_GT(rest.landmarks(30, 2), rest.landmarks(36, 2));
  EXPECT_GT(rest.landmarks(27, 1), rest.landmarks(8, 1));
}

TEST(IctConverter, JawOpenMovesTheChinDown) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  const HeadModel& m = Ict();
  HeadModelParams p;
  p.expression = Eigen::VectorXd::Zero(m.num_expression());
  const HeadModelOutput rest = m.Forward(p);
  p.expression[m.ExpressionIndex("jawOpen")] = 1;
  const HeadModelOutput open = m.Forward(p);
  EXPECT_LT(open.landmarks(8, 1), rest.landmarks(8, 1) - 0.015);  // ~2.8 cm down upstream
  EXPECT_NEAR(open.landmarks(27, 1), rest.landmarks(27, 1), 0.002);
}

// Gaze is the eye joints' rotation: each eyeball turns about its centre, the
// pupil (its front) moves the way the eye looks, and nothing else moves.
TEST(IctConverter, EyeJointsTurnTheEyeballsAboutTheirCentres) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  const HeadModel& m = Ict();
  const int left = m.PupilVertex(kLeftEyeJoint), right = m.PupilVertex(kRightEyeJoint);
  ASSERT_GE(left, 0);
  ASSERT_GE(right, 0);
  const HeadModelOutput rest = m.Forward(HeadModelParams{});
  EXPECT_GT(rest.vertices(left, 0), 0.02f);  // the subject's left eye is +x
  EXPECT_LT(rest.vertices(right, 0), -0.02f);
  // The pupil sits an eyeball radius in front of the pivot, on its axis
  // (ICT-FaceKit's eyeball with its shells is ~31 mm across, more than a real eye's 24).
  const float radius = (rest.vertices.row(left) - rest.joints.row(kLeftEyeJoint)).norm();
  EXPECT_NEAR(radius, 0.0155, 0.0015);
  EXPECT_NEAR(rest.vertices(left, 0), rest.joints(kLeftEyeJoint, 0), 0.002);
  EXPECT_NEAR(rest.vertices(left, 1), rest.joints(kLeftEyeJoint, 1), 0.002);
  HeadModelParams p;
  p.pose.segment<3>(3 * kLeftEyeJoint) << 0, 0.3, 0;  // about +y: the pupil moves to +x
  const HeadModelOutput turned = m.Forward(p);
  EXPECT_NEAR(turned.vertices(left, 0) - rest.vertices(left, 0), radius * std::sin(0.3), 4e-4);
  EXPECT_NEAR((turned.vertices.row(left) - turned.joints.row(kLeftEyeJoint)).norm(), radius, 1e-5);
  EXPECT_LT((turned.vertices.row(right) - rest.vertices.row(right)).norm(), 1e-7);
  EXPECT_LT((turned.landmarks - rest.landmarks).cwiseAbs().maxCoeff(), 1e-7);
}

TEST(IctConverter, PartsRestrictionAndRoundTrip) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  IctConvertOptions o;
  o.folder = testing::DataDir() + "/head-models/ict-facekit/FaceXModel";
  o.parts = {"face", "head"};
  o.max_identity = 5;
  const HeadModel small = ConvertIctFaceKit(o);
  EXPECT_EQ(small.num_vertices(), 11248);
  EXPECT_EQ(small.num_shape(), 5);
  const std::string path = testing::TempDir("ict") + "/ict_face.npz";
  SaveHeadModel(small, path);
  const HeadModel back = LoadHeadModel(path);
  EXPECT_EQ(back.fingerprint(), small.fingerprint());
  EXPECT_EQ(back.data().expression_names, small.data().expression_names);
  EXPECT_EQ(back.data().expression_min, 0.f);  // ARKit coefficients, kept by the file
  EXPECT_EQ(back.data().expression_max, 1.f);
  // Landmarks survive the reindexing.
  EXPECT_LT(
      (back.Forward(HeadModelParams{}).landmarks - Ict().Forward(HeadModelParams{}).landmarks).cwiseAbs().maxCoeff(),
      1e-6);
}

TEST(IctConverter, KeepsTheEyeAccessoriesOnlyWhenAsked) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  const std::vector<std::string> defaults = IctDefaultParts();
  EXPECT_EQ(defaults.size(), IctParts().size() - 1);
  EXPECT_EQ(std::count(defaults.begin(), defaults.end(), "eye_accessories"), 0);
  IctConvertOptions o;
  o.folder = testing::DataDir() + "/head-models/ict-facekit";
  o.max_identity = 0;
  o.parts.clear();  // every part
  const HeadModel all = ConvertIctFaceKit(o);
  EXPECT_EQ(all.num_vertices(), 26719);
  // The accessories are the last part: dropping them keeps every other vertex where it was.
  const HeadModelOutput with = all.Forward(HeadModelParams{});
  const HeadModelOutput without = Ict().Forward(HeadModelParams{});
  ASSERT_EQ(without.vertices.rows(), 24591);
  EXPECT_LT((with.vertices.topRows(24591) - without.vertices).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((with.landmarks - without.landmarks).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(IctConverter, RefusesBadFolders) {
  IctConvertOptions o;
  o.folder = testing::TempDir("empty");
  try {
    ConvertIctFaceKit(o);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("not an ICT-FaceKit folder"), std::string::npos);
  }
  o.parts = {"tentacles"};
  EXPECT_THROW(ConvertIctFaceKit(o), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
