// The libtorch head-model path: agrees with the Eigen path; gradients are right.
#include "common/headmodel/head_model_torch.h"

#include <ATen/ATen.h>
#include <gtest/gtest.h>

#include "tests/headmodel/test_models.h"

namespace headcast {
namespace {

using testing::Builtin;

at::Tensor ToTensor(const Eigen::VectorXd& v) {
  return at::from_blob(const_cast<double*>(v.data()), {1, v.size()}, at::kDouble).clone();
}

// A model with a dynamic contour table, to test FLAME's yaw-dependent landmarks.
HeadModel WithDynamicContour() {
  HeadModelData d = Builtin().data();
  d.dyn_lmk_faces.resize(kNumYawBins, kNumContourLandmarks);
  d.dyn_lmk_bary.resize(kNumYawBins * kNumContourLandmarks, 3);
  for (int b = 0; b < kNumYawBins; ++b)
    for (int k = 0; k < kNumContourLandmarks; ++k) {
      d.dyn_lmk_faces(b, k) = (b * 37 + k * 101) % d.faces.rows();
      d.dyn_lmk_bary.row(b * kNumContourLandmarks + k) << 0.2f, 0.3f, 0.5f;
    }
  return HeadModel(std::move(d));
}

void ExpectAgrees(const HeadModel& m, double pose_scale) {
  const HeadModelTorch t(m);
  for (unsigned seed : {1u, 2u, 3u}) {
    const HeadModelParams p = testing::RandomParams(m, seed, pose_scale);
    const HeadModelOutput e = m.Forward(p);
    Eigen::VectorXd pose = p.pose;
    const HeadModelTensors out = t.Forward(ToTensor(p.shape), ToTensor(p.expression), ToTensor(pose));
    const at::Tensor v = out.vertices.squeeze(0).contiguous();
    const Eigen::Map<const RowMatrixX3f> tv(v.data_ptr<float>(), m.num_vertices(), 3);
    EXPECT_LT((tv - e.vertices).cwiseAbs().maxCoeff(), 1e-5) << "seed " << seed;
    const at::Tensor l = out.landmarks.squeeze(0).contiguous();
    const Eigen::Map<const RowMatrixX3f> tl(l.data_ptr<float>(), kNumLandmarks, 3);
    EXPECT_LT((tl - e.landmarks).cwiseAbs().maxCoeff(), 1e-5) << "seed " << seed;
    const at::Tensor j = out.joints.squeeze(0).contiguous();
    const Eigen::Map<const RowMatrixX3f> tj(j.data_ptr<float>(), kNumHeadJoints, 3);
    EXPECT_LT((tj - e.joints).cwiseAbs().maxCoeff(), 1e-5) << "seed " << seed;
  }
}

TEST(HeadModelTorch, AgreesWithEigen) { ExpectAgrees(Builtin(), 0.3); }

TEST(HeadModelTorch, AgreesWithEigenWithPoseCorrectivesAndDynamicContour) {
  HeadModelData d = WithDynamicContour().data();
  for (Eigen::Index i = 0; i < d.posedirs.size(); ++i) d.posedirs.data()[i] = 1e-3f * std::sin(0.37f * i);
  const HeadModel m(std::move(d));
  ASSERT_TRUE(m.has_posedirs());
  ExpectAgrees(m, 0.6);  // up to ~34 degrees of yaw: several contour bins
}

TEST(HeadModelTorch, BatchesIndependently) {
  const HeadModel& m = Builtin();
  const HeadModelTorch t(m);
  const at::Tensor shape = at::randn({3, m.num_shape()});
  const at::Tensor expr = at::randn({3, m.num_expression()});
  const at::Tensor pose = 0.2 * at::randn({3, kNumPoseParams});
  const at::Tensor batched = t.Forward(shape, expr, pose).vertices;
  for (int64_t i = 0; i < 3; ++i) {
    const at::Tensor single = t.Forward(shape.narrow(0, i, 1), expr.narrow(0, i, 1), pose.narrow(0, i, 1)).vertices;
    EXPECT_LT((single.squeeze(0) - batched.select(0, i)).abs().max().item<float>(), 1e-6);
  }
  EXPECT_THROW(t.Forward(shape, expr, at::zeros({3, 7})), std::invalid_argument);
}

TEST(HeadModelTorch, GradientsMatchFiniteDifferences) {
  HeadModelData d = Builtin().data();
  for (Eigen::Index i = 0; i < d.posedirs.size(); ++i) d.posedirs.data()[i] = 1e-3f * std::cos(0.11f * i);
  const HeadModel m(std::move(d));
  const HeadModelTorch t(m, at::kDouble);
  const HeadModelParams p0 = testing::RandomParams(m, 11, 0.4);
  at::Tensor shape = ToTensor(p0.shape).requires_grad_(true);
  at::Tensor expr = ToTensor(p0.expression).requires_grad_(true);
  Eigen::VectorXd pose0 = p0.pose;
  at::Tensor pose = ToTensor(pose0).requires_grad_(true);
  const at::Tensor weights = at::randn({1, m.num_vertices(), 3}, at::kDouble);
  const at::Tensor lmk_weights = at::randn({1, kNumLandmarks, 3}, at::kDouble);
  auto loss_of = [&](const at::Tensor& s, const at::Tensor& e, const at::Tensor& p) {
    const HeadModelTensors out = t.Forward(s, e, p);
    return (out.vertices * weights).sum() + (out.landmarks * lmk_weights).sum();
  };
  loss_of(shape, expr, pose).backward();
  const double h = 1e-6;
  for (auto* param : {&shape, &expr, &pose}) {
    const at::Tensor grad = param->grad();
    for (int64_t i = 0; i < std::min<int64_t>(param->size(1), 8); ++i) {
      at::Tensor plus = param->detach().clone(), minus = param->detach().clone();
      plus[0][i] += h;
      minus[0][i] -= h;
      auto eval = [&](const at::Tensor& x) {
        return loss_of(param == &shape ? x : shape.detach(), param == &expr ? x : expr.detach(),
                       param == &pose ? x : pose.detach())
            .item<double>();
      };
      const double numeric = (eval(plus) - eval(minus)) / (2 * h);
      const double analytic = grad[0][i].item<double>();
      EXPECT_NEAR(analytic, numeric, 1e-5 * std::max(1.0, std::abs(numeric))) << "component " << i;
    }
  }
}

TEST(HeadModelTorch, RodriguesIsSmoothAtZero) {
  at::Tensor w = at::zeros({1, 3}, at::kDouble).requires_grad_(true);
  const at::Tensor R = AxisAngleToMatrixTorch(w);
  EXPECT_LT((R.squeeze(0) - at::eye(3, at::kDouble)).abs().max().item<double>(), 1e-12);
  R.select(0, 0)[1][0].backward();  // dR10/dw_z = 1 at zero
  EXPECT_NEAR(w.grad()[0][2].item<double>(), 1.0, 1e-6);
  EXPECT_TRUE(at::isfinite(w.grad()).all().item<bool>());
}

}  // namespace
}  // namespace headcast
