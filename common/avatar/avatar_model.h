// The neural avatar's networks in libtorch: CNeRF (conditional radiance field
// that outputs density and a feature vector), volume rendering into a feature
// map, and the 2D neural renderer that upsamples it x8 to RGB. METHOD §4.
// Shared by the receiver (inference) and the trainer.
#pragma once

#include <torch/torch.h>

#include "common/avatar/avatar_config.h"

namespace headcast {

// Per-frame conditioning, each (1, D).
struct AvatarConditioning {
  torch::Tensor geometry;    // beta, neck (3), jaw (3), eyes (6), psi: conditioning_dim
  torch::Tensor appearance;  // lambda (27), tau: appearance_dim
};

// xyz (N, 3) -> (N, 3 + 6L): [x, sin(2^k pi x), cos(2^k pi x) for k < L], x = xyz / scale.
torch::Tensor PositionalEncoding(const torch::Tensor& xyz, int frequencies, double scale);

class CNeRFImpl : public torch::nn::Module {
 public:
  explicit CNeRFImpl(const AvatarConfig& config);
  // points (N, 3) in the head frame -> density (N), features (N, F). `hair`
  // (N, 0 or 1), when defined: the samples told only what the config's
  // hair_conditioning keeps of the geometry conditioning where it is 1.
  std::pair<torch::Tensor, torch::Tensor> forward(const torch::Tensor& points, const AvatarConditioning& cond,
                                                  const torch::Tensor& hair = {});
  // Stops gradients into the first n MLP layers (subject fine-tuning freezes 4).
  void FreezeFirstLayers(int n);
  const AvatarConfig& config() const { return config_; }

 private:
  // y = [h, enc, cond] W^T + b, with the cond term either concatenated per
  // sample or (precompute) folded into the bias once per call.
  torch::Tensor ConditionedLinear(torch::nn::Linear layer, const torch::Tensor& h, const torch::Tensor& enc,
                                  const torch::Tensor& cond, const torch::Tensor& hair = {});

  AvatarConfig config_;
  torch::Tensor hair_keeps_;  // (1, conditioning_dim): 1 where hair_conditioning tells the element
  torch::nn::ModuleList layers_;
  torch::nn::Linear density_{nullptr}, feature_{nullptr}, appearance_{nullptr}, out_{nullptr};
};
TORCH_MODULE(CNeRF);

struct VolumeRenderResult {
  torch::Tensor features;  // (R, F)
  torch::Tensor opacity;   // (R)
  torch::Tensor depth;     // (R), expected z
};
// METHOD eq. 7, discretised: density (R, S), features (R, S, F), z (R, S)
// sample depths along rays whose directions have length `ray_length` (R) per unit z.
VolumeRenderResult VolumeRender(const torch::Tensor& density, const torch::Tensor& features, const torch::Tensor& z,
                                const torch::Tensor& ray_length);

// A window of an image, pixels: rows [y0, y1), columns [x0, x1).
struct ImageWindow {
  int64_t y0 = 0, y1 = 0, x0 = 0, x1 = 0;
  int64_t height() const { return y1 - y0; }
  int64_t width() const { return x1 - x0; }
  static ImageWindow Whole(int64_t height, int64_t width) { return {0, height, 0, width}; }
};

class SqueezeExcitationImpl : public torch::nn::Module {
 public:
  SqueezeExcitationImpl(int channels, int reduction = 4);
  torch::Tensor forward(const torch::Tensor& x);
  torch::Tensor Scale(const torch::Tensor& x);  // (B, C, 1, 1): what forward multiplies x by
  // The same from x's channel means (B, C), when another block shares them.
  torch::Tensor ScaleOfMeans(const torch::Tensor& means);

 private:
  torch::nn::Linear down_{nullptr}, up_{nullptr};
};
TORCH_MODULE(SqueezeExcitation);

// Two SE blocks feed a global (dilated 3x3) and a local (1x1) branch; their sum
// goes through PixelShuffle (x2 resolution, /4 channels) and a fixed blur.
class UpsamplingBlockImpl : public torch::nn::Module {
 public:
  UpsamplingBlockImpl(int in_channels, int out_channels);
  // `window` of the output (even edges, inside it; ImageWindow::Whole for all
  // of it): the same pixels there as the whole output's (the squeeze still
  // averages all of x).
  torch::Tensor forward(const torch::Tensor& x, const ImageWindow& window);

 private:
  SqueezeExcitation global_se_{nullptr}, local_se_{nullptr};
  torch::nn::Conv2d global_{nullptr}, local_{nullptr};
  torch::nn::PixelShuffle shuffle_{nullptr};
  torch::Tensor blur_;  // (C, 1, 3, 3) binomial, a buffer
};
TORCH_MODULE(UpsamplingBlock);

// A learned feature texture on the canonical (neutral) head surface: three
// axis-aligned planes (xy, xz, yz) over +-surface_extent, bilinearly sampled and
// summed. Starts at zero, so a renderer given it first draws what it drew without.
// With surface_rigid, a second set of planes looked up at the posed points.
class SurfaceTextureImpl : public torch::nn::Module {
 public:
  explicit SurfaceTextureImpl(const AvatarConfig& config);
  // canonical points (P, 3), model frame, metres [, posed points (P, 3), the
  // same pixels' posed surface points: needed with surface_rigid] [, the
  // frame's expression coefficients (1, E): needed with surface_blend] -> features (P, C).
  torch::Tensor forward(const torch::Tensor& canonical, const torch::Tensor& posed = torch::Tensor(),
                        const torch::Tensor& expression = torch::Tensor());
  bool rigid() const { return rigid_planes_.defined(); }
  bool blended() const { return blend_.defined(); }
  // With surface_blend_components: the principal directions the blendshapes
  // follow — the frames' mean expression (E), K orthonormal directions (K, E)
  // and each projection's range (K), (K) — kept with the weights. Until set, the
  // directions are zero and the blendshapes add nothing; throws on sizes that
  // do not match, values that are not finite, or low > high.
  void SetBlendBasis(const torch::Tensor& mean, const torch::Tensor& directions, const torch::Tensor& low,
                     const torch::Tensor& high);
  bool has_blend_basis() const {
    return blend_directions_.defined() && blend_directions_.abs().sum().item<double>() > 0;
  }
  // The blendshapes' weights for a frame's expression coefficients (1, E) -> (1, rows of blend_).
  torch::Tensor BlendWeights(const torch::Tensor& expression) const;
  // Inference: keeps the planes texel after texel (channels-last), so that a
  // lookup without gradients reads a texel's channels side by side
  // (LookUpTriplanes) instead of grid_sample's walk channel after channel,
  // and blends only the texels of the expression blendshapes the points read
  // (AddBlendedLookUp). The same features up to float rounding; training is
  // unchanged.
  void UseChannelsLast();

 private:
  double extent_;
  bool channels_last_ = false;
  torch::Tensor planes_;        // (3, C, R, R)
  torch::Tensor rigid_planes_;  // the same, with surface_rigid (else undefined)
  // With surface_blend: (E, 3 * B * B * C), each coefficient's planes texel
  // after texel, so that their weighted sum is already in the receiver's layout.
  torch::Tensor blend_;  // (E or K, 3 * B * B * C)
  int64_t blend_resolution_ = 0;
  int64_t num_expression_ = 0;
  // With surface_blend_components (buffers, in the file): (E), (K, E), (K), (K).
  torch::Tensor blend_mean_, blend_directions_, blend_low_, blend_high_;
  // Inference: blend_ as (3 * B * B, E or K, C), each texel's rows side by
  // side; remade when blend_ has changed since (its version counter).
  torch::Tensor blend_texels_;
  int64_t blend_texels_version_ = -1;
  const void* blend_texels_source_ = nullptr;
  const torch::Tensor& BlendTexels();
  torch::Tensor BlendedPlanes(const torch::Tensor& expression) const;  // -> (3, C, B, B), channels-last strides
  torch::Tensor UnitPoints(const torch::Tensor& points) const;         // model-frame metres -> the planes' [-1, 1]
  torch::Tensor LookUp(const torch::Tensor& planes, const torch::Tensor& u) const;  // u: UnitPoints
};
TORCH_MODULE(SurfaceTexture);

// The coverage logit a new matte starts with everywhere (sigmoid: 0.9975).
inline constexpr double kInitialCoverageLogit = 6;

// Two or three x2 levels (AvatarConfig::renderer_levels); at each, RGB from the previous level bilinearly upsampled
// plus RGB from the upsampled features; 1x1 convs and LeakyReLU elsewhere.
// With surface features, a per-pixel two-layer branch of the full-resolution
// surface image joins the last level's features (averaged, earlier levels'
// too when configured). With a matte, a coverage logit is built the same way
// as the RGB (its own 1x1 convs per level).
class NeuralRendererImpl : public torch::nn::Module {
 public:
  explicit NeuralRendererImpl(const AvatarConfig& config);
  // (B, C0, h, w) [, surface_term (B, C_last, s h, s w) from SurfaceTerm] -> (B, 3, s h, s w), RGB in [0, 1],
  // s = 2^levels. With a matte, `coverage_logit` gets (B, 1, s h, s w): where the head covers the picture.
  // With `window` (even edges, inside s h x s w), the last x2 level runs on that
  // window only and both outputs are its size: the same pixels as without.
  torch::Tensor forward(const torch::Tensor& feature_map, const torch::Tensor& surface_term = torch::Tensor(),
                        torch::Tensor* coverage_logit = nullptr, const ImageWindow* window = nullptr);
  // The surface branch (two 1x1 layers) on the covered pixels only: texture
  // features (P, Cs) at flat pixel indices `pixels` (P) of an h x w image ->
  // (1, C3, h, w). Uncovered pixels get the branch's value for zero features,
  // so this equals the branch run on the whole zero-filled surface image.
  // `motion` (1, motion_dim): the frame's pose and expression, which scale
  // and shift the hidden layer when the branch is conditioned (else unused).
  torch::Tensor SurfaceTerm(const torch::Tensor& features, const torch::Tensor& pixels, int height, int width,
                            const torch::Tensor& motion = torch::Tensor());
  // Inference: keeps the convolutions' weights and images channels-last
  // (pixel after pixel), the layout the CPU convolutions work in, instead of
  // reordering every image on every call. The same pixels either way.
  void UseChannelsLast();

 private:
  bool channels_last_ = false;
  int levels_ = 3;               // x2 levels
  int first_surface_level_ = 2;  // the first x2 level (0..levels_-1) the surface term joins
  torch::nn::Conv2d input_rgb_{nullptr}, surface_hidden_{nullptr}, surface_out_{nullptr}, input_alpha_{nullptr};
  torch::nn::Linear surface_film_{nullptr};  // motion -> (scale, shift) of the surface branch's hidden layer
  torch::nn::ModuleList blocks_, post_, to_rgb_, to_alpha_, surface_early_;
};
TORCH_MODULE(NeuralRenderer);

// The networks of one avatar (the surface texture only when configured).
struct AvatarModules {
  explicit AvatarModules(const AvatarConfig& config)
      : cnerf(config), renderer(config), surface(config.has_surface() ? SurfaceTexture(config) : nullptr) {}
  CNeRF cnerf;
  NeuralRenderer renderer;
  SurfaceTexture surface;
  std::vector<torch::Tensor> parameters() const;
  void eval();
  void train();
};

}  // namespace headcast
