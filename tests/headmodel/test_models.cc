// Shared head-model test helpers.
#include "tests/headmodel/test_models.h"

#include <random>

namespace headcast {
namespace testing {

HeadModelParams RandomParams(const HeadModel& model, unsigned seed, double pose_scale) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  HeadModelParams p;
  p.shape = Eigen::VectorXd(model.num_shape());
  p.expression = Eigen::VectorXd(model.num_expression());
  for (auto& v : p.shape) v = u(rng);
  for (auto& v : p.expression) v = u(rng);
  for (auto& v : p.pose) v = pose_scale * u(rng);
  return p;
}

}  // namespace testing

}  // namespace headcast
