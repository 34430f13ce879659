// Chooses the feature-map rays and the depths sampled along them for one frame.
// Mesh-guided sampling (headcast's CPU speed-up) rasterises the head model at
// feature-map resolution and samples a thin shell around the surface, skipping
// rays that miss the head; uniform sampling is NeRF's, for comparison.
#pragma once

#include <random>
#include <vector>

#include "common/avatar/avatar_config.h"
#include "common/core/camera.h"
#include "common/core/rigid_transform.h"
#include "common/raster/rasterizer.h"

namespace headcast {

struct RayBatch {
  int width = 0, height = 0;  // feature map size
  int samples_per_ray = 0;
  std::vector<int32_t> pixel;     // ray -> y * width + x
  std::vector<float> directions;  // 3 per ray, camera frame, z = 1
  std::vector<float> depths;      // samples_per_ray per ray: camera z, increasing
  int num_rays() const { return static_cast<int>(pixel.size()); }
};

class RaySampler {
 public:
  explicit RaySampler(const AvatarConfig& config);

  // `vertices_in_cam`/`faces` (the posed head model) are used by mesh-guided
  // sampling; `feature_camera` is the output intrinsics resized to the feature
  // map. With `rng`, depths are jittered within their strata (training).
  void Sample(const RasterVertices& vertices_in_cam, const RasterFaces& faces, const PinholeCamera& feature_camera,
              const RigidTransform& cam_from_head, std::mt19937* rng, RayBatch* out);

 private:
  void AddRay(const PinholeCamera& camera, int x, int y, float z_near, float z_far, std::mt19937* rng,
              RayBatch* out) const;

  AvatarConfig config_;
  RasterBuffers buffers_;
  std::vector<float> surface_depth_;
};

}  // namespace headcast
