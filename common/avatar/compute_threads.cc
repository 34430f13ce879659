#include "common/avatar/compute_threads.h"

#include <ATen/Parallel.h>
#include <ATen/core/grad_mode.h>
#include <c10/core/InferenceMode.h>
#include <dlfcn.h>

namespace headcast {

void SetComputeThreads(int threads) {
  at::set_num_threads(threads);
  // Looked up rather than linked: a libtorch built on another BLAS has no such setter.
  using SetThreads = void (*)(int);
  if (auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) set(1);
}

ParallelTasks TorchParallelTasks() {
  return [](int n, const std::function<void(int)>& task) {
    const bool grad = at::GradMode::is_enabled(), inference = c10::InferenceMode::is_enabled();
    at::parallel_for(0, n, 1, [&](int64_t begin, int64_t end) {
      const c10::InferenceMode inference_mode(inference);
      const at::AutoGradMode grad_mode(grad);
      for (int64_t k = begin; k < end; ++k) task(static_cast<int>(k));
    });
  };
}

}  // namespace headcast
