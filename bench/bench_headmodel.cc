// Benchmark suite "headmodel": the single-frame Eigen forward pass.
#include <random>
#include <thread>

#include "bench/bench.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_model_io.h"

namespace headcast::bench {
namespace {

// A FLAME-sized model (5023 vertices, 300 shape, 100 expression, dense pose
// correctives) with random bases: FLAME itself cannot be shipped, but its cost
// depends only on these sizes.
HeadModel FlameSizedModel(const HeadModel& builtin) {
  HeadModelData d = builtin.data();
  const int n = 5023;
  std::mt19937 rng(7);
  std::normal_distribution<float> g(0.f, 1e-3f);
  d.v_template.conservativeResize(n, 3);
  for (int i = builtin.num_vertices(); i < n; ++i) d.v_template.row(i) = d.v_template.row(i % builtin.num_vertices());
  auto random = [&](int rows, int cols) {
    Eigen::MatrixXf m(rows, cols);
    for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = g(rng);
    return m;
  };
  d.shapedirs = random(3 * n, 300);
  d.expressiondirs = random(3 * n, 100);
  d.posedirs = random(3 * n, kNumPoseFeatures);
  d.j_regressor = Eigen::MatrixXf::Constant(kNumHeadJoints, n, 1.f / n);
  d.weights.resize(n, kNumHeadJoints);
  for (int i = 0; i < n; ++i) {
    d.weights.row(i).setZero();
    d.weights(i, i % 3) = 0.5f;
    d.weights(i, 1 + i % 4) += 0.5f;
  }
  d.faces = d.faces.topRows(9976).unaryExpr([n](int v) { return v % n; }).eval();
  d.uvs.resize(0, 2);
  d.uv_faces.resize(0, 3);
  d.texture_mean.clear();
  d.texture_basis.resize(0, 0);
  d.shape_names.clear();
  d.expression_names.clear();
  d.lmk_faces = d.lmk_faces.unaryExpr([](int f) { return f % 9976; }).eval();
  return HeadModel(std::move(d));
}

void Measure(const BenchOptions& options, const HeadModel& model, const std::string& prefix, nlohmann::json* out) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd shape(model.num_shape()), expr(model.num_expression());
  for (auto& v : shape) v = u(rng);
  for (auto& v : expr) v = u(rng);
  PoseVector pose;
  for (auto& v : pose) v = 0.2 * u(rng);
  const HeadIdentity id = model.MakeIdentity(shape);
  HeadModelOutput result;
  AddStats(out, prefix + "forward_us", TimeUs(options, [&] { model.Forward(id, expr, pose, &result); }));
  // Two halves of the vertices on two threads (the receiver's pass shares
  // libtorch's; here threads of their own, started per call).
  const ParallelTasks two_threads = [](int n, const std::function<void(int)>& task) {
    std::vector<std::thread> threads;
    for (int k = 1; k < n; ++k) threads.emplace_back([&task, k] { task(k); });
    task(0);
    for (std::thread& t : threads) t.join();
  };
  AddStats(out, prefix + "forward_two_threads_us",
           TimeUs(options, [&] { model.Forward(id, expr, pose, &result, &two_threads); }));
  AddStats(out, prefix + "identity_us", TimeUs(options, [&] { (void)model.MakeIdentity(shape); }));
  (*out)[prefix + "vertices"] = model.num_vertices();
  (*out)[prefix + "shape_components"] = model.num_shape();
  (*out)[prefix + "expression_components"] = model.num_expression();
  (*out)[prefix + "pose_correctives"] = model.has_posedirs();
}

}  // namespace

nlohmann::json RunHeadModelSuite(const BenchOptions& options) {
  nlohmann::json out;
  out["suite"] = "headmodel";
  out["what"] = "HeadModel::Forward (Eigen, float, one frame, identity precomputed), microseconds";
  const HeadModel builtin = MakeBuiltinHead();
  Measure(options, builtin, "", &out);  // headline: forward_us_median on the built-in head
  Measure(options, FlameSizedModel(builtin), "flame_sized_", &out);
  if (options.head_model != "builtin") Measure(options, LoadHeadModelSpec(options.head_model), "given_", &out);
  return out;
}

}  // namespace headcast::bench
