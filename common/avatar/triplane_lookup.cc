#include "common/avatar/triplane_lookup.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace headcast {
namespace {

// One plane's bilinear taps for a point: texel offsets (in floats) and weights.
struct Taps {
  int64_t offset[4];
  float weight[4];
};

// A coordinate in [-1, 1] as a texel position in [0, resolution - 1]:
// grid_sample's unnormalisation (align_corners false) and border clipping, in
// its order of operations. Not a number reads the first texel rather than
// memory outside the plane.
inline __attribute__((always_inline)) float TexelPosition(float coordinate, int64_t resolution) {
  if (std::isnan(coordinate)) return 0;
  const float half = static_cast<float>(resolution) / 2, last = static_cast<float>(resolution - 1);
  return std::clamp((coordinate + 1) * half - 0.5f, 0.f, last);
}

// Inlined: called per point and plane, where a call returns the taps
// through memory.
inline __attribute__((always_inline)) Taps PlaneTaps(float a, float b, int64_t resolution, int64_t channels) {
  const float ix = TexelPosition(a, resolution), iy = TexelPosition(b, resolution);
  // Truncation is the floor of these positions (never negative), without
  // floor's call into the maths library on a baseline x86-64 build.
  const float x0 = static_cast<float>(static_cast<int64_t>(ix)), y0 = static_cast<float>(static_cast<int64_t>(iy));
  const float fx = ix - x0, fy = iy - y0;
  // At the last texel the far taps weigh nothing: clamped to stay in the plane.
  const int64_t c0 = static_cast<int64_t>(x0), r0 = static_cast<int64_t>(y0);
  const int64_t c1 = std::min(c0 + 1, resolution - 1), r1 = std::min(r0 + 1, resolution - 1);
  Taps t;
  t.offset[0] = (r0 * resolution + c0) * channels;
  t.offset[1] = (r0 * resolution + c1) * channels;
  t.offset[2] = (r1 * resolution + c0) * channels;
  t.offset[3] = (r1 * resolution + c1) * channels;
  t.weight[0] = (1 - fx) * (1 - fy);
  t.weight[1] = fx * (1 - fy);
  t.weight[2] = (1 - fx) * fy;
  t.weight[3] = fx * fy;
  return t;
}

// One point's features, summed over the three planes in grid_sample's order,
// written to `out` (kAdd: added to it). kChannels > 0: the count known at
// compile time (kept in registers).
template <int kChannels, bool kAdd = false>
void LookUpPoint(const float* planes, int64_t resolution, int64_t channels, const float* p, float* out) {
  const int64_t c = kChannels > 0 ? kChannels : channels, plane_size = resolution * resolution * c;
  const float pairs[3][2] = {{p[0], p[1]}, {p[0], p[2]}, {p[1], p[2]}};
  float sum[kChannels > 0 ? kChannels : 1];
  float* acc = kChannels > 0 ? sum : out;  // with kAdd and no count: added to `out` plane by plane
  if (kChannels > 0 || !kAdd) std::fill(acc, acc + c, 0.f);
  for (int k = 0; k < 3; ++k) {
    const Taps t = PlaneTaps(pairs[k][0], pairs[k][1], resolution, c);
    const float* plane = planes + k * plane_size;
    const float *v0 = plane + t.offset[0], *v1 = plane + t.offset[1], *v2 = plane + t.offset[2],
                *v3 = plane + t.offset[3];
    for (int64_t ch = 0; ch < c; ++ch)
      acc[ch] += v0[ch] * t.weight[0] + v1[ch] * t.weight[1] + v2[ch] * t.weight[2] + v3[ch] * t.weight[3];
  }
  if (kChannels > 0 && kAdd)
    for (int64_t ch = 0; ch < c; ++ch) out[ch] += sum[ch];
  else if (kChannels > 0)
    std::copy(sum, sum + c, out);
}

}  // namespace

void LookUpTriplanes(const TexelMajorPlanes& planes, const float* points, int64_t count, float* features) {
  if (!planes.data || planes.resolution < 1 || planes.channels < 1)
    throw std::invalid_argument("LookUpTriplanes: no planes");
  const int64_t r = planes.resolution, c = planes.channels;
  // Shipped avatars have 8 channels: that count gets its own loop.
  const auto point = c == 8 ? &LookUpPoint<8> : &LookUpPoint<0>;
  at::parallel_for(0, count, 256, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) point(planes.data, r, c, points + 3 * i, features + i * c);
  });
}

void AddBlendedLookUp(const TexelMajorBlendshapes& shapes, const float* weights, const float* points, int64_t count,
                      float* features) {
  if (!shapes.data || shapes.resolution < 1 || shapes.components < 1 || shapes.channels < 1)
    throw std::invalid_argument("AddBlendedLookUp: no blendshapes");
  const int64_t r = shapes.resolution, k = shapes.components, c = shapes.channels, texels = 3 * r * r;
  // The texels the taps read: the same taps as the lookup below (PlaneTaps),
  // so that no texel it reads is left unblended.
  std::vector<uint8_t> touched(texels, 0);
  for (int64_t i = 0; i < count; ++i) {
    const float* p = points + 3 * i;
    const float pairs[3][2] = {{p[0], p[1]}, {p[0], p[2]}, {p[1], p[2]}};
    for (int plane = 0; plane < 3; ++plane) {
      const Taps t = PlaneTaps(pairs[plane][0], pairs[plane][1], r, 1);
      for (const int64_t offset : t.offset) touched[plane * r * r + offset] = 1;
    }
  }
  std::vector<int32_t> list;
  for (int64_t t = 0; t < texels; ++t)
    if (touched[t]) list.push_back(static_cast<int32_t>(t));
  // Only touched texels are blended; the others, never read, keep zeros.
  std::vector<float> blended(texels * c);
  at::parallel_for(0, static_cast<int64_t>(list.size()), 64, [&](int64_t begin, int64_t end) {
    for (int64_t j = begin; j < end; ++j) {
      const int64_t t = list[j];
      const float* in = shapes.data + t * k * c;
      float* out = blended.data() + t * c;
      std::fill(out, out + c, 0.f);
      for (int64_t m = 0; m < k; ++m) {
        const float w = weights[m];
        for (int64_t ch = 0; ch < c; ++ch) out[ch] += w * in[m * c + ch];
      }
    }
  });
  const auto point = c == 8 ? &LookUpPoint<8, true> : &LookUpPoint<0, true>;
  at::parallel_for(0, count, 256, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) point(blended.data(), r, c, points + 3 * i, features + i * c);
  });
}

}  // namespace headcast
