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

// Blendshapes of three such planes, stored texel after texel with each
// texel's components side by side (plane, row, column, component, channel).
struct TexelMajorBlendshapes {
  const float* data = nullptr;  // 3 * resolution * resolution * components * channels
  int64_t resolution = 0;
  int64_t components = 0;
  int64_t channels = 0;
};

// Adds to `features` (count x channels) the planes blended with `weights`
// (components: the sum of each component's planes times its weight) looked
// up at the points as LookUpTriplanes does: the same values as blending every
// texel first, up to float rounding. Only the texels the points' taps read
// are blended — a face covers a small part of each plane, and blending them
// all reads every component's planes each frame. Runs on libtorch's
// intra-op threads.
void AddBlendedLookUp(const TexelMajorBlendshapes& shapes, const float* weights, const float* points, int64_t count,
                      float* features);

}  // namespace headcast
