// A seam for running a few independent pieces of one computation at once on
// whichever thread pool the caller already keeps busy, so that code without a
// pool of its own (the head model) can share, say, libtorch's without
// depending on it, and without a third thread fighting the pool for a core.
#pragma once

#include <functional>

namespace headcast {

// Runs task(0) ... task(n - 1), some at the same time, and returns when all
// are done; an exception from a task reaches the caller.
using ParallelTasks = std::function<void(int n, const std::function<void(int)>& task)>;

}  // namespace headcast
