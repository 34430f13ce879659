// How many threads the avatar's tensor maths may use in this process.
#pragma once

#include "common/core/parallel_tasks.h"

namespace headcast {

// libtorch's intra-op threads become `threads`; OpenBLAS (Debian's libtorch
// multiplies matrices in it) gets one. OpenBLAS keeps a spinning thread pool
// of its own that ignores libtorch's setting: beside libtorch's two threads on
// two cores the two pools fight, and a frame's time turned from steady into
// long tails (bench/DEFAULTS.md has the figures).
void SetComputeThreads(int threads);

// Tasks on libtorch's own intra-op threads (at::parallel_for): beside its
// pool, a thread of ours would fight its threads for the two cores (they
// spin between regions, and a region waits for its slowest thread). Tensor
// operations inside a task run on that one thread; each task keeps the
// caller's grad and inference modes. One thread: the tasks run in order.
ParallelTasks TorchParallelTasks();

}  // namespace headcast
