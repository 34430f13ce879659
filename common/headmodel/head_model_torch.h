// The batched, differentiable libtorch forward pass of HeadModel (for training).
// It agrees with the Eigen single-frame path to ~1e-5 and is autograd-friendly.
#pragma once

#include <ATen/core/Tensor.h>

#include <memory>

#include "common/headmodel/head_model.h"

namespace headcast {

struct HeadModelTensors {
  at::Tensor vertices;   // (B, N, 3)
  at::Tensor landmarks;  // (B, 68, 3)
  at::Tensor joints;     // (B, 5, 3) posed
};

class HeadModelTorch {
 public:
  // Copies the model's arrays into tensors of `dtype` (at::kFloat or at::kDouble) on the CPU.
  explicit HeadModelTorch(const HeadModel& model, at::ScalarType dtype = at::kFloat);
  ~HeadModelTorch();
  HeadModelTorch(HeadModelTorch&&) noexcept;

  // shape (B, S'), expression (B, E'), pose (B, 15); S' <= S and E' <= E
  // (the leading components). Gradients flow to all three.
  HeadModelTensors Forward(const at::Tensor& shape, const at::Tensor& expression, const at::Tensor& pose) const;

  at::ScalarType dtype() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Batched Rodrigues: (B, 3) axis-angle -> (B, 3, 3), smooth at zero.
at::Tensor AxisAngleToMatrixTorch(const at::Tensor& axis_angle);

}  // namespace headcast
