// The built-in procedural head: a closed, plausible, FLAME-layout head.
#include <gtest/gtest.h>

#include <map>
#include <set>

#include "tests/headmodel/test_models.h"

namespace headcast {

namespace {

using testing::Builtin;

TEST(BuiltinHead, SizesNamesAndParts) {
  const HeadModel& m = Builtin();
  EXPECT_GE(m.num_vertices(), 5000);  // benchmarks need a >= 5k-vertex head
  EXPECT_GE(m.num_shape(), 10);
  EXPECT_GE(m.num_expression(), 12);
  for (const char* name : {"smile", "pucker", "brow_raise", "brow_frown", "blink_left", "blink_right", "cheek_puff"})
    EXPECT_GE(m.ExpressionIndex(name), 0) << name;
  EXPECT_EQ(m.data().shape_names.size(), static_cast<size_t>(m.num_shape()));
  EXPECT_TRUE(m.has_texture());
  EXPECT_GE(m.num_texture(), 4);
  for (int j = 0; j < kNumHeadJoints; ++j) EXPECT_TRUE(m.JointIsArticulated(j)) << j;
  EXPECT_NE(m.data().description.find("NOT FLAME"), std::string::npos);
}

TEST(BuiltinHead, IsClosedAndOutwardFacing) {
  const HeadModel& m = Builtin();
  const auto& f = m.data().faces;
  // Closed 2-manifold (topologically): every directed edge has exactly one reverse.
  std::map<std::pair<int, int>, int> edges;
  for (Eigen::Index i = 0; i < f.rows(); ++i)
    for (int k = 0; k < 3; ++k) ++edges[{f(i, k), f(i, (k + 1) % 3)}];
  int bad = 0;
  for (const auto& [e, n] : edges) bad += n != 1 || edges.count({e.second, e.first}) != 1;
  EXPECT_EQ(bad, 0);
  // Positive signed volume per component (head, left eye, right eye): faces point outward.
  double volume[3] = {0, 0, 0};
  const auto& v = m.data().v_template;
  const auto& w = m.data().weights;
  for (Eigen::Index i = 0; i < f.rows(); ++i) {
    const int c = w(f(i, 0), kLeftEyeJoint) > 0 ? 1 : w(f(i, 0), kRightEyeJoint) > 0 ? 2 : 0;
    volume[c] +=
        v.row(f(i, 0)).cast<double>().dot(v.row(f(i, 1)).cast<double>().cross(v.row(f(i, 2)).cast<double>())) / 6;
  }
  EXPECT_GT(volume[0], 0.003);  // a head and neck: litres
  EXPECT_LT(volume[0], 0.008);
  for (int e : {1, 2}) EXPECT_NEAR(volume[e], 4.0 / 3 * M_PI * std::pow(0.0118, 3), 1e-6);
}

TEST(BuiltinHead, LandmarksAreWhereAFaceHasThem) {
  const HeadModel& m = Builtin();
  const HeadModelOutput rest = m.Forward(HeadModelParams{});
  const auto& l = rest.landmarks;
  auto mean = [&](int a, int b) {
    Eigen::RowVector3f s = Eigen::RowVector3f::Zero();
    for (int i = a; i <= b; ++i) s += l.row(i);
    return Eigen::RowVector3f(s / (b - a + 1));
  };
  const Eigen::RowVector3f right_eye = mean(36, 41), left_eye = mean(42, 47), nose_tip = l.row(30),
                           mouth = mean(48, 59), chin = l.row(8);
  EXPECT_GT(left_eye.x(), 0);  // the subject's left is +x
  EXPECT_LT(right_eye.x(), 0);
  const float iod = (left_eye - right_eye).norm();
  EXPECT_GT(iod, 0.05f);
  EXPECT_LT(iod, 0.08f);
  EXPECT_GT(right_eye.y(), nose_tip.y());
  EXPECT_GT(nose_tip.y(), mouth.y());
  EXPECT_GT(mouth.y(), chin.y());
  EXPECT_GT(nose_tip.z(), left_eye.z() + 0.01);  // the nose sticks out
  // Symmetric: landmark 0 mirrors 16, 36 mirrors 45.
  EXPECT_NEAR(l(0, 0), -l(16, 0), 0.004);
  EXPECT_NEAR(l(36, 0), -l(45, 0), 0.004);
  EXPECT_NEAR(l(36, 1), l(45, 1), 0.002);
}

TEST(BuiltinHead, BlinkCoversTheEyeAndJawOpensTheMouth) {
  const HeadModel& m = Builtin();
  HeadModelParams p;
  const auto open = m.Forward(p);
  p.expression = Eigen::VectorXd::Zero(m.num_expression());
  p.expression[m.ExpressionIndex("blink_left")] = 1;
  const auto blink = m.Forward(p);
  // The upper lid comes forward, in front of the eyeball's front (largest z on the left eyeball).
  float eye_front = -1;
  for (int i = 0; i < m.num_vertices(); ++i)
    if (m.data().weights(i, kLeftEyeJoint) > 0) eye_front = std::max(eye_front, open.vertices(i, 2));
  const Eigen::RowVector3f lid_open = 0.5f * (open.landmarks.row(43) + open.landmarks.row(44));
  const Eigen::RowVector3f lid_closed = 0.5f * (blink.landmarks.row(43) + blink.landmarks.row(44));
  EXPECT_LT(lid_closed.y(), lid_open.y());
  HeadModelParams jaw;
  jaw.pose[3 * kJawJoint] = 0.3;
  const auto opened = m.Forward(jaw);
  EXPECT_LT(opened.landmarks(8, 1), open.landmarks(8, 1) - 0.01);      // chin down by > 1 cm
  EXPECT_LT(opened.landmarks(66, 1), opened.landmarks(62, 1) - 0.01);  // inner lips apart
  EXPECT_NEAR(opened.landmarks(27, 1), open.landmarks(27, 1), 1e-6);   // nose bridge still
  EXPECT_GT(eye_front, 0);
}

TEST(BuiltinHead, IsDeterministic) {
  EXPECT_EQ(MakeBuiltinHead().fingerprint(), Builtin().fingerprint());
  BuiltinHeadOptions bad;
  bad.columns = 3;
  EXPECT_THROW(MakeBuiltinHead(bad), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
