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
#include "common/headmodel/head_model.h"
#include "common/raster/rasterizer.h"

namespace headcast {

struct RayBatch {
  int width = 0, height = 0;  // feature map size
  int samples_per_ray = 0;
  std::vector<int32_t> pixel;     // ray -> y * width + x
  std::vector<float> directions;  // 3 per ray, camera frame, z = 1
  std::vector<float> depths;      // samples_per_ray per ray: camera z, increasing
  // mesh-guided: the triangle under the ray, or in the margin the nearest in
  // front (-1 there with AvatarConfig::rigid_margin); uniform: -1
  std::vector<int32_t> face;
  int num_rays() const { return static_cast<int>(pixel.size()); }
};

// Pixels of the output image that the posed mesh covers, each with the point
// of the canonical (neutral) mesh under it: the same triangle and barycentrics
// on the canonical vertices. What the surface texture is looked up with.
// With a shell (AvatarConfig::surface_shell), the pixels only the inflated
// mesh covers follow the mesh's, with points on the inflated canonical mesh.
struct SurfaceBatch {
  int width = 0, height = 0;     // output image size
  std::vector<int32_t> pixel;    // covered pixel -> y * width + x; the mesh's first, then the shell's
  std::vector<float> canonical;  // 3 per covered pixel, model frame, metres
  // With posed vertices given: 3 per mesh pixel, the posed surface point there
  // (model frame, metres); empty otherwise.
  std::vector<float> posed;
  std::vector<int32_t> face;  // per covered pixel, the triangle under it (the inflated mesh's for a shell pixel)
  int mesh_pixels = 0;        // the first this many pixels are the mesh's: its silhouette
  int num_pixels() const { return static_cast<int>(pixel.size()); }
};

// Per ray, the affine map from the posed head (model frame) to the canonical
// (neutral) one through the local frame of the ray's triangle: its two edges
// and unit normal posed, to the same on the canonical triangle (INSTA's
// idea: the mesh carries the motion, a point off the surface keeps its
// distance along the normal). 12 floats per ray, row-major A then o, with
// p_canonical = A p + o; rays without a triangle (or a degenerate one) get
// the identity. `canonical_vertices`: 3N, x y z per vertex. With `covered`
// (CoveredFaces), the rays of a covered triangle are carried on to the
// covered parts' place (kCoveredApartTo).
void CanonicalTransforms(const RayBatch& rays, const RowMatrixX3f& posed_vertices, const RasterFaces& faces,
                         const Eigen::VectorXf& canonical_vertices, std::vector<float>* out,
                         const std::vector<uint8_t>* covered = nullptr);

// Per face of a mesh (`canonical_vertices`: 3N, the neutral head, model frame:
// y up, z out of the face), 1 where, seen from the front, the face looks
// forward, shows in no pixel, and another surface lies in front of its centre
// by more than 2 mm (plus the face's slope times a pixel of the 1024² view)
// and less than `depth` metres: what the neutral head covers (the mouth's
// inside behind the closed lips, the eyeballs under the lids).
std::vector<uint8_t> CoveredFaces(const Eigen::VectorXf& canonical_vertices, const RasterFaces& faces, float depth);

// Where AvatarConfig::covered_apart carries the covered faces' points:
// p -> kCoveredApartTo + kCoveredApartScale (p - kCoveredApartFrom), model
// frame, metres. Halved and set in front of the forehead and above it, where
// neither the rest of the head's CNeRF samples nor its points on any of the
// texture's three planes (xy, xz, yz) reach: a head model's neutral head
// lies within about 0.15 m of its origin, its face's front below y = 0.1.
inline const Eigen::Vector3f kCoveredApartFrom(0.f, -0.01f, 0.05f);
inline const Eigen::Vector3f kCoveredApartTo(0.1f, 0.17f, 0.17f);
constexpr float kCoveredApartScale = 0.5f;

// Carries the surface pixels whose triangle is `covered` (CoveredFaces) to the
// covered parts' place (kCoveredApartTo). Returns how many moved.
int MoveCoveredPointsApart(const std::vector<uint8_t>& covered, SurfaceBatch* surface);

// Moves every mesh pixel's canonical point that lies on an eyeball (a
// triangle whose three vertices are mostly skinned to an eye joint) about the
// eye's pivot (`identity`'s rest joint) to one meridian: the same distance
// from the pivot and the same angle from the pole (+z, the rest gaze), at
// azimuth zero. The texture is then a function of the angle from the pole:
// the sclera, iris and pupil a video shows beside the iris are drawn above and
// below it too, where the lids always covered the eyeball in training and a
// wide-eyed frame shows it. Returns how many points moved.
int FoldEyeballPoints(const HeadModel& model, const HeadIdentity& identity, SurfaceBatch* surface);

// Per face of `model`, 1 where the hair may lie over it: no expression
// coefficient moves any of its vertices by `reach` metres or more per unit,
// and none is skinned to the jaw or an eye (the scalp, the back of the head,
// the ears; the face, the jaw and the eyeballs are 0).
std::vector<uint8_t> HairFaces(const HeadModel& model, float reach);

// Per ray, 1 where its samples are the hair's (AvatarConfig::hair_conditioning):
// its triangle is a hair face, or it has none (a rigid margin ray); else 0.
void HairRays(const RayBatch& rays, const std::vector<uint8_t>& hair_faces, std::vector<float>* out);

class RaySampler {
 public:
  explicit RaySampler(const AvatarConfig& config);

  // `vertices_in_cam`/`faces` (the posed head model) are used by mesh-guided
  // sampling; `feature_camera` is the output intrinsics resized to the feature
  // map. With `rng`, depths are jittered within their strata (training).
  void Sample(const RasterVertices& vertices_in_cam, const RasterFaces& faces, const PinholeCamera& feature_camera,
              const RigidTransform& cam_from_head, std::mt19937* rng, RayBatch* out);

  // Rasterises the posed mesh at `output_camera`'s size and maps every covered
  // pixel to the canonical mesh (`canonical_vertices`: 3N, x y z per vertex);
  // with a shell, then the pixels only the inflated mesh covers. With
  // `posed_vertices` (the same mesh in the model frame), each mesh pixel's
  // posed point too (SurfaceBatch::posed).
  void SampleSurface(const RasterVertices& vertices_in_cam, const RasterFaces& faces,
                     const Eigen::VectorXf& canonical_vertices, const PinholeCamera& output_camera, SurfaceBatch* out,
                     const RowMatrixX3f* posed_vertices = nullptr);

  // CoveredFaces of `canonical_vertices` at the config's shell depth
  // (shell_front + shell_back: how far a ray's samples reach), kept while
  // the canonical mesh stays the one they are of.
  const std::vector<uint8_t>& Covered(const Eigen::VectorXf& canonical_vertices, const RasterFaces& faces);
  // HairFaces of `model` at the config's hair_reach, kept while the model
  // (its expression basis and faces, which a program loads once) is the same.
  const std::vector<uint8_t>& Hair(const HeadModel& model);

 private:
  void AddRay(const PinholeCamera& camera, int x, int y, float z_near, float z_far, int face, std::mt19937* rng,
              RayBatch* out) const;

  // Appends the pixels covered by the mesh inflated by `shell` metres that
  // `surface_buffers_` (the mesh) leaves empty.
  void AppendShell(const RasterVertices& vertices_in_cam, const RasterFaces& faces,
                   const Eigen::VectorXf& canonical_vertices, const PinholeCamera& output_camera, float shell,
                   SurfaceBatch* out);

  AvatarConfig config_;
  RasterBuffers buffers_, surface_buffers_, shell_buffers_;
  RasterVertices inflated_;
  // The canonical mesh's vertex normals, kept while the canonical mesh (the
  // subject's neutral shape, the same every frame) stays the one they are of.
  Eigen::VectorXf normals_of_;
  RowMatrixX3f canonical_normals_;
  Eigen::VectorXf covered_of_;
  std::vector<uint8_t> covered_;
  const float* hair_of_ = nullptr;  // the expression basis HairFaces was made from
  std::vector<uint8_t> hair_;
  std::vector<float> surface_depth_;
  std::vector<int32_t> surface_face_;
};

}  // namespace headcast
