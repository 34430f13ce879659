#include "common/avatar/compute_threads.h"

#include <ATen/Parallel.h>
#include <dlfcn.h>

namespace headcast {

void SetComputeThreads(int threads) {
  at::set_num_threads(threads);
  // Looked up rather than linked: a libtorch built on another BLAS has no such setter.
  using SetThreads = void (*)(int);
  if (auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) set(1);
}

}  // namespace headcast
