// How many threads the avatar's tensor maths may use in this process.
#pragma once

namespace headcast {

// libtorch's intra-op threads become `threads`; OpenBLAS (Debian's libtorch
// multiplies matrices in it) gets one. OpenBLAS keeps a spinning thread pool
// of its own that ignores libtorch's setting: beside libtorch's two threads on
// two cores the two pools fight, and a frame's time turned from steady into
// long tails (bench/DEFAULTS.md has the figures).
void SetComputeThreads(int threads);

}  // namespace headcast
