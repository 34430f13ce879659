// The surface texture's lookup for inference, on texel-major planes.
#pragma once

#include <cstdint>

namespace headcast {

// Three square feature planes stored texel after texel (plane, row, column,
// channel), as the surface texture keeps them for inference.
struct TexelMajorPlanes {
  const float* data = nullptr;  // 3 * resolution * resolution * channels
  int64_t resolution = 0;
  int64_t channels = 0;
};

// For each point (count x 3, coordinates in [-1, 1]): the bilinear lookup of
// the xy, xz and yz planes (the first coordinate along a plane's columns, the
// second along its rows; texel centres, edges repeated beyond the border),
// summed over the planes, into `features` (count x channels). The same values
// as libtorch's grid_sample (bilinear, border padding, align_corners false)
// on the planes channel-major, up to float rounding. grid_sample walks the
// planes channel after channel; a texel's channels side by side are read once
// per tap here. Runs on libtorch's intra-op threads.
void LookUpTriplanes(const TexelMajorPlanes& planes, const float* points, int64_t count, float* features);

}  // namespace headcast
