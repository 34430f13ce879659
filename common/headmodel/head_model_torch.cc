// Batched differentiable head model in libtorch.
#include "common/headmodel/head_model_torch.h"

#include <ATen/ATen.h>

#include <stdexcept>

namespace headcast {

at::Tensor AxisAngleToMatrixTorch(const at::Tensor& w) {
  const auto b = w.size(0);
  // theta^2 + eps keeps the gradient finite at zero; the eps (1e-16) is far
  // below float precision so values match the exact formula.
  const at::Tensor theta2 = (w * w).sum(1, true) + 1e-16;
  const at::Tensor theta = theta2.sqrt();
  const at::Tensor k = w / theta;
  const at::Tensor zeros = at::zeros({b, 1}, w.options());
  const at::Tensor kx = k.narrow(1, 0, 1), ky = k.narrow(1, 1, 1), kz = k.narrow(1, 2, 1);
  const at::Tensor K = at::cat({zeros, -kz, ky, kz, zeros, -kx, -ky, kx, zeros}, 1).view({b, 3, 3});
  const at::Tensor eye = at::eye(3, w.options()).unsqueeze(0);
  const at::Tensor s = theta.sin().view({b, 1, 1}), c = theta.cos().view({b, 1, 1});
  return eye + s * K + (1 - c) * at::bmm(K, K);
}

struct HeadModelTorch::Impl {
  at::ScalarType dtype;
  int64_t n = 0, s = 0, e = 0;
  at::Tensor v_template;      // (N*3)
  at::Tensor shapedirs;       // (N*3, S)
  at::Tensor expressiondirs;  // (N*3, E)
  at::Tensor posedirs;        // (36, N*3) or undefined
  at::Tensor j_regressor;     // (5, N)
  at::Tensor weights;         // (N, 5)
  at::Tensor faces;           // (F, 3) long
  at::Tensor lmk_faces;       // (68) long
  at::Tensor lmk_bary;        // (68, 3)
  at::Tensor dyn_faces;       // (79, 17) long, or undefined
  at::Tensor dyn_bary;        // (79, 17, 3)
  std::array<int, kNumHeadJoints> parents;
};

namespace {
at::Tensor FromEigen(const float* data, std::vector<int64_t> sizes, at::ScalarType dtype) {
  return at::from_blob(const_cast<float*>(data), sizes, at::kFloat).clone().to(dtype);
}
}  // namespace

HeadModelTorch::HeadModelTorch(const HeadModel& model, at::ScalarType dtype) : impl_(std::make_unique<Impl>()) {
  if (dtype != at::kFloat && dtype != at::kDouble)
    throw std::invalid_argument("HeadModelTorch: dtype must be float or double");
  const HeadModelData& d = model.data();
  Impl& m = *impl_;
  m.dtype = dtype;
  m.n = model.num_vertices();
  m.s = model.num_shape();
  m.e = model.num_expression();
  m.parents = d.parents;
  m.v_template = FromEigen(d.v_template.data(), {m.n * 3}, dtype);
  // Eigen stores bases column-major: (3N, K) column-major is (K, 3N) row-major.
  m.shapedirs = FromEigen(d.shapedirs.data(), {m.s, m.n * 3}, dtype).t().contiguous();
  m.expressiondirs = FromEigen(d.expressiondirs.data(), {m.e, m.n * 3}, dtype).t().contiguous();
  if (model.has_posedirs()) m.posedirs = FromEigen(d.posedirs.data(), {kNumPoseFeatures, m.n * 3}, dtype);
  m.j_regressor = FromEigen(d.j_regressor.data(), {m.n, kNumHeadJoints}, dtype).t().contiguous();
  m.weights = FromEigen(d.weights.data(), {m.n, kNumHeadJoints}, dtype);
  m.faces = at::from_blob(const_cast<int*>(d.faces.data()), {d.faces.rows(), 3}, at::kInt).to(at::kLong);
  m.lmk_faces = at::from_blob(const_cast<int*>(d.lmk_faces.data()), {kNumLandmarks}, at::kInt).to(at::kLong);
  m.lmk_bary = FromEigen(d.lmk_bary.data(), {kNumLandmarks, 3}, dtype);
  if (model.has_dynamic_contour()) {
    // dyn_lmk_faces is column-major 79 x 17.
    m.dyn_faces = at::from_blob(const_cast<int*>(d.dyn_lmk_faces.data()), {kNumContourLandmarks, kNumYawBins}, at::kInt)
                      .t()
                      .to(at::kLong)
                      .contiguous();
    // dyn_lmk_bary is column-major (79*17) x 3.
    m.dyn_bary = FromEigen(d.dyn_lmk_bary.data(), {3, kNumYawBins * kNumContourLandmarks}, dtype)
                     .t()
                     .reshape({kNumYawBins, kNumContourLandmarks, 3})
                     .contiguous();
  }
}

HeadModelTorch::~HeadModelTorch() = default;
HeadModelTorch::HeadModelTorch(HeadModelTorch&&) noexcept = default;
at::ScalarType HeadModelTorch::dtype() const { return impl_->dtype; }

HeadModelTensors HeadModelTorch::Forward(const at::Tensor& shape, const at::Tensor& expression,
                                         const at::Tensor& pose) const {
  const Impl& m = *impl_;
  const int64_t b = pose.size(0);
  if (pose.dim() != 2 || pose.size(1) != kNumPoseParams)
    throw std::invalid_argument("HeadModelTorch: pose must be (B, 15)");
  if (shape.dim() != 2 || shape.size(0) != b || shape.size(1) > m.s)
    throw std::invalid_argument("HeadModelTorch: shape must be (B, <=S)");
  if (expression.dim() != 2 || expression.size(0) != b || expression.size(1) > m.e)
    throw std::invalid_argument("HeadModelTorch: expression must be (B, <=E)");

  at::Tensor v = m.v_template.unsqueeze(0).expand({b, m.n * 3});
  if (shape.size(1) > 0) v = v + at::matmul(shape.to(m.dtype), m.shapedirs.narrow(1, 0, shape.size(1)).t());
  if (expression.size(1) > 0)
    v = v + at::matmul(expression.to(m.dtype), m.expressiondirs.narrow(1, 0, expression.size(1)).t());
  const at::Tensor v_shaped = v.view({b, m.n, 3});
  const at::Tensor J = at::matmul(m.j_regressor, v_shaped);  // (B, 5, 3)

  const at::Tensor R =
      AxisAngleToMatrixTorch(pose.to(m.dtype).reshape({b * kNumHeadJoints, 3})).view({b, kNumHeadJoints, 3, 3});
  at::Tensor v_posed = v_shaped;
  if (m.posedirs.defined()) {
    const at::Tensor feature =
        (R.narrow(1, 1, kNumHeadJoints - 1) - at::eye(3, R.options())).reshape({b, kNumPoseFeatures});
    v_posed = v_posed + at::matmul(feature, m.posedirs).view({b, m.n, 3});
  }
  // Kinematic chain.
  std::vector<at::Tensor> GR(kNumHeadJoints), Gt(kNumHeadJoints);
  for (int k = 0; k < kNumHeadJoints; ++k) {
    const at::Tensor Rk = R.select(1, k);
    const at::Tensor jk = J.select(1, k).unsqueeze(2);  // (B, 3, 1)
    const int p = m.parents[k];
    if (p < 0) {
      GR[k] = Rk;
      Gt[k] = jk;
    } else {
      GR[k] = at::bmm(GR[p], Rk);
      Gt[k] = at::bmm(GR[p], jk - J.select(1, p).unsqueeze(2)) + Gt[p];
    }
  }
  std::vector<at::Tensor> A;
  for (int k = 0; k < kNumHeadJoints; ++k) {
    const at::Tensor t = Gt[k] - at::bmm(GR[k], J.select(1, k).unsqueeze(2));
    A.push_back(at::cat({GR[k], t}, 2).view({b, 12}));
  }
  const at::Tensor A_all = at::stack(A, 1);                                // (B, 5, 12)
  const at::Tensor T = at::matmul(m.weights, A_all).view({b, m.n, 3, 4});  // (B, N, 3, 4)
  const at::Tensor verts = at::matmul(T.narrow(3, 0, 3), v_posed.unsqueeze(3)).squeeze(3) + T.select(3, 3);

  // Landmarks: static embedding, with the contour swapped per sample for FLAME.
  at::Tensor lmk_faces = m.lmk_faces.unsqueeze(0).repeat({b, 1});  // (B, 68)
  at::Tensor lmk_bary = m.lmk_bary.unsqueeze(0).repeat({b, 1, 1});
  if (m.dyn_faces.defined()) {
    const at::Tensor pose_cpu = pose.detach().to(at::kDouble).contiguous();
    const double* pp = pose_cpu.data_ptr<double>();
    std::vector<int64_t> bins(b);
    for (int64_t i = 0; i < b; ++i) {
      PoseVector pv = Eigen::Map<const PoseVector>(pp + i * kNumPoseParams);
      bins[i] = HeadModel::ContourYawBin(pv);
    }
    const at::Tensor bin_t = at::tensor(bins, at::kLong);
    lmk_faces.narrow(1, 0, kNumContourLandmarks).copy_(m.dyn_faces.index_select(0, bin_t));
    lmk_bary.narrow(1, 0, kNumContourLandmarks).copy_(m.dyn_bary.index_select(0, bin_t));
  }
  const at::Tensor corner_ids = m.faces.index_select(0, lmk_faces.reshape(-1)).view({b, kNumLandmarks * 3});
  const at::Tensor corners =
      at::gather(verts, 1, corner_ids.unsqueeze(2).expand({b, kNumLandmarks * 3, 3})).view({b, kNumLandmarks, 3, 3});
  const at::Tensor landmarks = (corners * lmk_bary.unsqueeze(3)).sum(2);

  std::vector<at::Tensor> joints;
  for (int k = 0; k < kNumHeadJoints; ++k) joints.push_back(Gt[k].squeeze(2));
  return {verts, landmarks, at::stack(joints, 1)};
}

}  // namespace headcast
