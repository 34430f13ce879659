// Ray and depth sampling.
#include "common/avatar/ray_sampler.h"

#include <algorithm>
#include <limits>

namespace headcast {

RaySampler::RaySampler(const AvatarConfig& config) : config_(config) { config.Check(); }

void RaySampler::AddRay(const PinholeCamera& cam, int x, int y, float z_near, float z_far, std::mt19937* rng,
                        RayBatch* out) const {
  out->pixel.push_back(y * cam.width + x);
  out->directions.push_back(static_cast<float>((x - cam.cx) / cam.fx));
  out->directions.push_back(static_cast<float>((y - cam.cy) / cam.fy));
  out->directions.push_back(1.f);
  const int s = config_.samples_per_ray;
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int k = 0; k < s; ++k) {
    const float offset = rng ? u(*rng) : 0.5f;  // stratified: one sample per stratum
    out->depths.push_back(z_near + (z_far - z_near) * (k + offset) / s);
  }
}

void RaySampler::Sample(const RasterVertices& vertices_in_cam, const RasterFaces& faces, const PinholeCamera& cam,
                        const RigidTransform& cam_from_head, std::mt19937* rng, RayBatch* out) {
  out->width = cam.width;
  out->height = cam.height;
  out->samples_per_ray = config_.samples_per_ray;
  out->pixel.clear();
  out->directions.clear();
  out->depths.clear();
  if (config_.sampling == SamplingMode::kUniform) {
    const float centre = static_cast<float>(cam_from_head.translation.z());
    const float z_near = std::max(0.01f, centre - static_cast<float>(config_.uniform_near));
    const float z_far = centre + static_cast<float>(config_.uniform_far);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) AddRay(cam, x, y, z_near, z_far, rng, out);
    return;
  }
  RasterOptions raster;
  raster.cull_back_faces = true;
  Rasterize(vertices_in_cam, faces, cam, raster, &buffers_);
  // Depth for rays near the silhouette (hair, ears, a margin for the fit's
  // error): the nearest surface depth within hair_margin_px.
  const int w = cam.width, h = cam.height, m = config_.hair_margin_px;
  const float inf = std::numeric_limits<float>::infinity();
  surface_depth_.assign(static_cast<size_t>(w) * h, inf);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      if (buffers_.face[p] >= 0) {
        surface_depth_[p] = buffers_.depth[p];
        continue;
      }
      float best = inf;
      for (int dy = -m; dy <= m; ++dy)
        for (int dx = -m; dx <= m; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const size_t q = static_cast<size_t>(yy) * w + xx;
          if (buffers_.face[q] >= 0) best = std::min(best, buffers_.depth[q]);
        }
      surface_depth_[p] = best;
    }
  const float front = static_cast<float>(config_.shell_front), back = static_cast<float>(config_.shell_back);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float d = surface_depth_[static_cast<size_t>(y) * w + x];
      if (d == inf) continue;  // misses the head: background, no samples
      AddRay(cam, x, y, std::max(0.01f, d - front), d + back, rng, out);
    }
}

}  // namespace headcast
