// HeadModel's forward pass: rest pose, skinning, linearity, landmarks, a shared pass.
#include <gtest/gtest.h>

#include <thread>

#include "common/core/rotation.h"
#include "tests/headmodel/test_models.h"

namespace headcast {
namespace {

using testing::Builtin;
using testing::RandomParams;

TEST(HeadModel, RestPoseIsTheTemplate) {
  const HeadModel& m = Builtin();
  const HeadModelOutput out = m.Forward(HeadModelParams{});
  EXPECT_LT((out.vertices - m.data().v_template).cwiseAbs().maxCoeff(), 1e-7);
}

TEST(HeadModel, JawMovesOnlyJawWeightedVertices) {
  const HeadModel& m = Builtin();
  HeadModelParams p = RandomParams(m, 1, 0.0);
  const HeadModelOutput rest = m.Forward(p);
  p.pose[3 * kJawJoint] = 0.25;
  p.pose[3 * kJawJoint + 1] = 0.05;
  const HeadModelOutput open = m.Forward(p);
  int moved = 0, still = 0;
  for (int i = 0; i < m.num_vertices(); ++i) {
    const float d = (open.vertices.row(i) - rest.vertices.row(i)).norm();
    if (m.data().weights(i, kJawJoint) == 0) {
      EXPECT_LT(d, 1e-6) << "vertex " << i;
      ++still;
    } else if (m.data().weights(i, kJawJoint) > 0.5) {
      EXPECT_GT(d, 1e-3) << "vertex " << i;
      ++moved;
    }
  }
  EXPECT_GT(moved, 100);
  EXPECT_GT(still, 1000);
}

TEST(HeadModel, EyeRotationMovesOnlyThatEyeball) {
  const HeadModel& m = Builtin();
  HeadModelParams p;
  const HeadModelOutput rest = m.Forward(p);
  p.pose.segment<3>(3 * kLeftEyeJoint) = Eigen::Vector3d(0, 0.3, 0);
  const HeadModelOutput look = m.Forward(p);
  for (int i = 0; i < m.num_vertices(); ++i) {
    const float d = (look.vertices.row(i) - rest.vertices.row(i)).norm();
    if (m.data().weights(i, kLeftEyeJoint) == 0) {
      EXPECT_LT(d, 1e-7);
    }
  }
  // The eyeball turns about its own centre: the joint stays put.
  EXPECT_LT((look.joints.row(kLeftEyeJoint) - rest.joints.row(kLeftEyeJoint)).norm(), 1e-6);
}

TEST(HeadModel, BasesAreLinear) {
  const HeadModel& m = Builtin();
  const HeadModelParams a = RandomParams(m, 2, 0), b = RandomParams(m, 3, 0);
  HeadModelParams sum;
  sum.shape = a.shape + b.shape;
  sum.expression = a.expression + b.expression;
  const auto base = m.Forward(HeadModelParams{}).vertices;
  const auto fa = m.Forward(a).vertices, fb = m.Forward(b).vertices, fs = m.Forward(sum).vertices;
  EXPECT_LT(((fs - base) - (fa - base) - (fb - base)).cwiseAbs().maxCoeff(), 2e-6);
  HeadModelParams twice = a;
  twice.expression *= 2;
  twice.shape *= 2;
  EXPECT_LT(((m.Forward(twice).vertices - base) - 2 * (fa - base)).cwiseAbs().maxCoeff(), 2e-6);
}

TEST(HeadModel, RootRotationIsRigid) {
  const HeadModel& m = Builtin();
  HeadModelParams p = RandomParams(m, 4, 0);
  const auto rest = m.Forward(p);
  const Eigen::Vector3d w(0.2, -0.4, 0.1);
  p.pose.segment<3>(0) = w;
  const auto turned = m.Forward(p);
  const Eigen::Matrix3f R = AxisAngleToMatrix(w).cast<float>();
  const Eigen::RowVector3f j = rest.joints.row(kRootJoint);
  for (int i = 0; i < m.num_vertices(); i += 97) {
    const Eigen::RowVector3f expected = (R * (rest.vertices.row(i) - j).transpose()).transpose() + j;
    EXPECT_LT((turned.vertices.row(i) - expected).norm(), 1e-6);
  }
}

TEST(HeadModel, IdentityCacheMatchesTheFullPass) {
  const HeadModel& m = Builtin();
  const HeadModelParams p = RandomParams(m, 5);
  const HeadIdentity id = m.MakeIdentity(p.shape);
  HeadModelOutput cached;
  m.Forward(id, p.expression, p.pose, &cached);
  EXPECT_LT((cached.vertices - m.Forward(p).vertices).cwiseAbs().maxCoeff(), 1e-7);
  // Fewer components than the model has are zero-padded.
  HeadModelParams short_params;
  short_params.expression = Eigen::VectorXd::Zero(2);
  short_params.expression[0] = 1;
  HeadModelParams full;
  full.expression = Eigen::VectorXd::Zero(m.num_expression());
  full.expression[0] = 1;
  EXPECT_LT((m.Forward(short_params).vertices - m.Forward(full).vertices).cwiseAbs().maxCoeff(), 1e-7);
}

TEST(HeadModel, TheTwoTaskPassGivesTheSameVertices) {
  const HeadModel& m = Builtin();
  // Tasks on threads of their own, the first started last: any order works.
  std::vector<int> ran;
  const ParallelTasks parallel = [&](int n, const std::function<void(int)>& task) {
    std::vector<std::thread> threads;
    for (int k = n - 1; k >= 0; --k) threads.emplace_back([&task, k] { task(k); });
    for (std::thread& t : threads) t.join();
    ran.push_back(n);
  };
  for (unsigned seed : {1u, 2u, 3u}) {
    const HeadModelParams p = RandomParams(m, seed);
    const HeadIdentity id = m.MakeIdentity(p.shape);
    HeadModelOutput alone, shared;
    m.Forward(id, p.expression, p.pose, &alone);
    m.Forward(id, p.expression, p.pose, &shared, &parallel);
    EXPECT_EQ(alone.vertices, shared.vertices) << "seed " << seed;
    EXPECT_EQ(alone.joints, shared.joints);
    EXPECT_EQ(alone.landmarks, shared.landmarks);
  }
  EXPECT_EQ(ran, (std::vector<int>{2, 2, 2}));
}

TEST(HeadModel, ContourYawBinsFollowFlame) {
  PoseVector p = PoseVector::Zero();
  EXPECT_EQ(HeadModel::ContourYawBin(p), 0);
  for (double deg : {10.0, -10.0, 39.0, -39.0, 60.0, -60.0}) {
    p.segment<3>(3) = Eigen::Vector3d(0, deg * M_PI / 180, 0);
    const int bin = HeadModel::ContourYawBin(p);
    EXPECT_GE(bin, 0);
    EXPECT_LE(bin, 78);
  }
  p.segment<3>(3) = Eigen::Vector3d(0, -20 * M_PI / 180, 0);  // yaw -20 deg -> +20 after FLAME's sign flip
  EXPECT_EQ(HeadModel::ContourYawBin(p), 20);
  p.segment<3>(3) = Eigen::Vector3d(0, 20 * M_PI / 180, 0);
  EXPECT_EQ(HeadModel::ContourYawBin(p), 59);
}

TEST(HeadModel, ValidationNamesTheField) {
  HeadModelData d = Builtin().data();
  d.weights(10, 0) += 0.5f;
  try {
    HeadModel bad(d);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("weights"), std::string::npos);
  }
  d = Builtin().data();
  d.faces(3, 1) = 1 << 28;
  EXPECT_THROW(HeadModel{d}, std::invalid_argument);
  d = Builtin().data();
  d.expressiondirs(5, 2) = std::nanf("");
  EXPECT_THROW(HeadModel{d}, std::invalid_argument);
}

}  // namespace
}  // namespace headcast
