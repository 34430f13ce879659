// ICT-FaceKit conversion on the real model in ../shared/data (skipped without it).
#include "common/headmodel/ict_converter.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/raster/shading.h"
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

// What the renders of the model are painted with: every pixel of a part takes
// its part's colour, an eyeball's the colour of its angle from the pole, and an
// open mouth shows its dark lining; unpainted, the model has no albedo at all.
TEST(IctConverter, PaintsEachPartAndTheEyesAboutTheirPoles) {
  HEADCAST_REQUIRE_DATA("head-models/ict-facekit");
  IctConvertOptions painted;  // the default
  painted.folder = testing::DataDir() + "/head-models/ict-facekit";
  painted.max_identity = 0;
  const HeadModel m = ConvertIctFaceKit(painted);
  ASSERT_TRUE(m.has_texture());
  EXPECT_EQ(m.num_texture(), 0);
  HeadModelParams p;
  p.expression = Eigen::VectorXd::Zero(m.num_expression());
  p.expression[m.ExpressionIndex("jawOpen")] = 1;
  const HeadModelOutput open = m.Forward(p);
  const PinholeCamera camera = PinholeCamera::FromFovY(512, 512, 12);
  RasterBuffers buffers;
  RenderHead(m, open.vertices, FrontalCamFromHead(0.9), camera, AlbedoTexture(m), {}, &buffers);
  const cv::Mat albedo = SampleTexture(buffers, m.data().uv_faces, m.data().uvs, AlbedoTexture(m));
  const auto& parts = IctParts();
  std::vector<int> pixels(parts.size(), 0);
  int eyeball_checked = 0, pupil = 0;
  for (int y = 0; y < buffers.height; ++y)
    for (int x = 0; x < buffers.width; ++x) {
      const int f = buffers.face[static_cast<size_t>(y) * buffers.width + x];
      if (f < 0) continue;
      size_t part = 0;
      while (m.data().faces(f, 0) > parts[part].last) ++part;
      ++pixels[part];
      const cv::Vec3f a = albedo.at<cv::Vec3f>(y, x);
      Eigen::Vector3f expected = IctPartAlbedo(parts[part].name);
      if (std::string(parts[part].name) == "eyeballs") {
        // The pixel's point on the ball, from the pivot of its eye's joint.
        const float* b = &buffers.bary[3 * (static_cast<size_t>(y) * buffers.width + x)];
        Eigen::Vector3f point = Eigen::Vector3f::Zero();
        for (int c = 0; c < 3; ++c) point += b[c] * open.vertices.row(m.data().faces(f, c)).transpose();
        const int joint = point.x() > 0 ? kLeftEyeJoint : kRightEyeJoint;
        const Eigen::Vector3f r = point - open.joints.row(joint).transpose();
        const double degrees = std::acos(r.z() / r.norm()) * 180 / M_PI;
        // Away from the rings' edges, where the ramp's texels (2.8 degrees) blend.
        if (std::min({std::abs(degrees - 8), std::abs(degrees - 21), std::abs(degrees - 26)}) < 4) continue;
        expected = IctEyeballAlbedo(degrees * M_PI / 180);
        ++eyeball_checked;
        pupil += degrees < 6;
      }
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(a[c], expected[c], 2e-3) << parts[part].name << " at " << x << "," << y;
    }
  for (const char* seen : {"face", "gums_tongue", "teeth", "eyeballs"})  // the mouth's lining lies behind the tongue
    EXPECT_GT(
        pixels[std::find_if(parts.begin(), parts.end(), [&](const IctPart& q) { return q.name == std::string(seen); }) -
               parts.begin()],
        20)
        << seen;
  EXPECT_GT(eyeball_checked, 100);
  EXPECT_GT(pupil, 4);
  // The mouth's lining and tongue are darker than skin, the sclera lighter than the iris.
  EXPECT_LT(IctPartAlbedo("mouth").sum(), IctPartAlbedo("face").sum() / 3);
  EXPECT_LT(IctPartAlbedo("gums_tongue").sum(), IctPartAlbedo("face").sum() / 2);
  EXPECT_GT(IctEyeballAlbedo(M_PI / 3).sum(), 3 * IctEyeballAlbedo(0.25).sum());

  IctConvertOptions unpainted = painted;
  unpainted.paint_parts = false;
  const HeadModel plain = ConvertIctFaceKit(unpainted);
  EXPECT_FALSE(plain.has_texture());
  EXPECT_TRUE(Ict().has_texture());  // the default
  // The same geometry: avatars and datasets of either fit both.
  EXPECT_EQ(plain.fingerprint(), m.fingerprint());
  // The painting travels in the file.
  const std::string path = testing::TempDir("ict_painted") + "/ict.npz";
  SaveHeadModel(m, path);
  const HeadModel back = LoadHeadModel(path);
  ASSERT_TRUE(back.has_texture());
  EXPECT_EQ(back.data().texture_mean, m.data().texture_mean);
  EXPECT_EQ(back.data().uv_faces, m.data().uv_faces);
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
