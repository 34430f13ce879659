// The differentiable avatar pipeline in libtorch: the one frame-preparation
// and render path shared by the trainer, evaluation and the receiver's
// AvatarRenderer, so that the quality a report measures is what a call shows.
#pragma once

#include <optional>
#include <random>

#include "common/avatar/avatar_model.h"
#include "common/avatar/avatar_renderer.h"
#include "common/avatar/motion_blur.h"
#include "common/avatar/ray_sampler.h"
#include "common/core/parallel_tasks.h"

namespace headcast {

// (1, D) conditioning tensors from the subject and one frame's parameters.
AvatarConditioning MakeConditioning(const AvatarConfig& config, const SubjectParams& subject, const FrameParams& frame);

struct AvatarOutput {
  torch::Tensor image;        // (1, 3, H, W) RGB in [0, 1]
  torch::Tensor coverage;     // with a matte: (1, 1, H, W) in [0, 1], the head's share of each pixel
  torch::Tensor feature_map;  // (1, F, h, w)
  torch::Tensor opacity;      // (1, 1, h, w)
  // With a surface texture: (P, Cs), the texture's features at each of the
  // surface's covered output pixels (RunAvatarSurfaceFeatures).
  torch::Tensor surface_features;
};

// (1, 3, H, W) RGB in [0, 1] <-> H x W BGR bytes (CV_8UC3); `out` is reused.
void ImageTensorToBgr(const torch::Tensor& image, cv::Mat* out);
torch::Tensor BgrToImageTensor(const cv::Mat& image_bgr);

// One frame's inputs to the networks; the posed-mesh buffers are reused when
// the same object serves frame after frame.
struct AvatarFrameInputs {
  RayBatch rays;
  SurfaceBatch surface;             // empty unless the avatar has surface features or a bounded matte
  std::vector<float> to_canonical;  // with canonical_samples: 12 per ray (CanonicalTransforms)
  std::vector<float> hair_rays;     // with hair_conditioning: 1 per ray (HairRays)
  cv::Mat matte_bound;              // with a bounded matte: H x W CV_8U, 255 where the head may show (MatteBound)
  cv::Mat matte_core;               // and with a core: 255 where it always shows (MatteCore)
  double coverage_scale = 0;  // with a matte: the coverage logit's scale this frame (0: AvatarConfig::matte_scale)
  RigidTransform cam_from_head;
  AvatarConditioning conditioning;
  HeadModelOutput posed;
  RasterVertices v_cam;
  // The frame drawn before with these buffers (RenderAvatarFrame): its posed
  // vertices in the camera frame and its sequence number, for the motion
  // AvatarConfig::motion_blur smears along.
  RasterVertices previous_v_cam;
  std::optional<uint64_t> previous_sequence;
};

// The head's image motion per frame interval from the frame `buffers` drew
// before to the one they hold now (PrepareAvatarRays made it), when that frame
// was one of the last kMotionBlurMaxGap before this one: a receiver that
// dropped a frame still knows how the head moves; a new session or a jump does not.
inline constexpr uint64_t kMotionBlurMaxGap = 3;
std::optional<ImageMotion> MotionSincePrevious(const AvatarFrameInputs& buffers, const FrameParams& frame,
                                               const PinholeCamera& camera);

// The posed model's 68 landmarks seen through `camera` (pixels): where the
// frame's fit puts them in the picture the avatar draws.
Landmarks2d ProjectLandmarks(const HeadModelOutput& posed, const RigidTransform& cam_from_head,
                             const PinholeCamera& camera);

// Runs CNeRF on the frame's samples, composites the feature map, looks up the
// surface texture (when the avatar has one) and upsamples; with a matte, the
// RGB is composited over the background colour by the coverage.
// RunAvatarFeatures then RunAvatarUpsampling.
AvatarOutput RunAvatar(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarTimings* timings = nullptr);
// The feature map and opacity: needs only the rays, the conditioning and the
// placement of `inputs` (what PrepareAvatarRays makes).
void RunAvatarFeatures(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                       AvatarTimings* timings = nullptr);
// The surface texture's features at the surface's covered pixels (nothing
// without a texture): needs the surface (PrepareAvatarSurface) and the
// conditioning, not the feature map, so it may run beside RunAvatarFeatures.
void RunAvatarSurfaceFeatures(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                              AvatarTimings* timings = nullptr);
// The image (and coverage) from out's feature map: needs the surface and the
// bound too (PrepareAvatarSurface); the surface's features when
// RunAvatarSurfaceFeatures has not looked them up.
void RunAvatarUpsampling(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                         AvatarTimings* timings = nullptr);

// The head model posed by `frame` with `identity` (the subject's shape), seen
// through the subject's intrinsics at feature resolution: rays and depths
// (jittered within their strata when `rng` is given: training), placement
// and conditioning; with surface features, the covered output pixels on the
// canonical mesh (`identity`'s neutral shape); with a bounded matte, its bound.
// PrepareAvatarRays then PrepareAvatarSurface.
void PrepareAvatarFrame(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                        const SubjectParams& subject, const FrameParams& frame, RaySampler* sampler, std::mt19937* rng,
                        AvatarFrameInputs* out, AvatarTimings* timings = nullptr);
// The posed head, rays, canonical maps and conditioning (`parallel`: the head
// model's pass in two tasks).
void PrepareAvatarRays(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                       const SubjectParams& subject, const FrameParams& frame, RaySampler* sampler, std::mt19937* rng,
                       AvatarFrameInputs* out, AvatarTimings* timings = nullptr,
                       const ParallelTasks* parallel = nullptr);
// From out's posed head: the output-size surface lookup and the matte bound
// and core. Touches only those fields of `out` and the sampler's surface
// buffers, so it may run beside RunAvatarFeatures.
void PrepareAvatarSurface(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                          const SubjectParams& subject, RaySampler* sampler, AvatarFrameInputs* out,
                          AvatarTimings* timings = nullptr);

// What the receiver shows for `frame`: PrepareAvatarFrame, RunAvatar, then
// 8-bit BGR in *image_bgr (reused). With `parallel`, the head model's pass
// runs as two tasks, then the surface preparation and its texture lookup as
// one task beside the network.
// A frame that carries the camera's skin colour (FrameParams::skin_colour)
// has its picture matched to it (MatchSkinColour).
void RenderAvatarFrame(AvatarModules& modules, const AvatarConfig& config, const HeadModel& model,
                       const HeadIdentity& identity, const SubjectParams& subject, const FrameParams& frame,
                       RaySampler* sampler, AvatarFrameInputs* buffers, cv::Mat* image_bgr,
                       AvatarTimings* timings = nullptr, const ParallelTasks* parallel = nullptr);

// The head in `out`'s picture scaled per channel so that its skin colour
// (SkinColour in the region `landmarks` give) becomes `target`: the camera's
// exposure, white balance and light, which the networks cannot know. The gain
// is bounded by kMinSkinGain..kMaxSkinGain; the background stays. Writes
// *image_bgr, which must hold `out`'s picture; false (nothing changed) when
// the region is not in the picture.
constexpr float kMinSkinGain = 0.5f, kMaxSkinGain = 2.f;
bool MatchSkinColour(const AvatarOutput& out, const Eigen::Vector3f& target, const Landmarks2d& landmarks,
                     cv::Mat* image_bgr);

}  // namespace headcast
