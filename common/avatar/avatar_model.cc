// The neural avatar's networks.
#include "common/avatar/avatar_model.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/avatar/shuffle_blur.h"
#include "common/avatar/triplane_lookup.h"

namespace headcast {
namespace F = torch::nn::functional;

torch::Tensor PositionalEncoding(const torch::Tensor& xyz, int frequencies, double scale) {
  const torch::Tensor x = xyz / scale;
  if (frequencies == 0) return x;
  // (N, 3, L): x * 2^k * pi
  const torch::Tensor bands = torch::pow(2.0, torch::arange(frequencies, xyz.options())) * M_PI;
  const torch::Tensor scaled = (x.unsqueeze(2) * bands).flatten(1);  // (N, 3L)
  return torch::cat({x, scaled.sin(), scaled.cos()}, 1);
}

CNeRFImpl::CNeRFImpl(const AvatarConfig& config) : config_(config) {
  config.Check();
  const int enc = config.encoding_dim(), cond = config.conditioning_dim(), w = config.mlp_width;
  layers_ = register_module("layers", torch::nn::ModuleList());
  for (int k = 0; k < config.mlp_layers; ++k) {
    int in = k == 0 ? enc + cond : w;
    if (k == config.skip_layer) in += enc + cond;
    layers_->push_back(torch::nn::Linear(in, w));
  }
  density_ = register_module("density", torch::nn::Linear(w, 1));
  feature_ = register_module("feature", torch::nn::Linear(w, w));
  appearance_ = register_module("appearance", torch::nn::Linear(w + config.appearance_dim(), w / 2));
  out_ = register_module("out", torch::nn::Linear(w / 2, config.feature_channels));
  std::vector<float> keeps(cond);
  for (int i = 0; i < cond; ++i) keeps[i] = config.Tells(config.hair_conditioning, i) ? 1.f : 0.f;
  hair_keeps_ = torch::tensor(keeps).view({1, cond});
}

torch::Tensor CNeRFImpl::ConditionedLinear(torch::nn::Linear layer, const torch::Tensor& h, const torch::Tensor& enc,
                                           const torch::Tensor& cond, const torch::Tensor& hair) {
  const int64_t n = enc.size(0);
  const int64_t h_dim = h.defined() ? h.size(1) : 0, e_dim = enc.size(1), c_dim = cond.size(1);
  // What the hair's samples are told less: cond - hair_cond, one row.
  const torch::Tensor untold = hair.defined() ? cond * (1 - hair_keeps_) : torch::Tensor();
  if (!config_.precompute_conditioning) {
    std::vector<torch::Tensor> parts;
    if (h.defined()) parts.push_back(h);
    parts.push_back(enc);
    parts.push_back(hair.defined() ? cond - hair.unsqueeze(1) * untold : cond.expand({n, c_dim}));
    return layer->forward(torch::cat(parts, 1));
  }
  // The conditioning is the same for every sample of a frame: its product with
  // the weights is a per-frame bias (one row), not N rows; the hair's samples
  // have that row less the product of what they are not told.
  const torch::Tensor& weight = layer->weight;  // (out, h + e + c)
  const torch::Tensor cond_weight = weight.narrow(1, h_dim + e_dim, c_dim).t();
  const torch::Tensor bias = torch::addmm(layer->bias.unsqueeze(0), cond, cond_weight);
  torch::Tensor y = torch::addmm(bias, enc, weight.narrow(1, h_dim, e_dim).t());
  if (h.defined()) y = y.addmm(h, weight.narrow(1, 0, h_dim).t());
  if (hair.defined()) y = y.addmm(hair.unsqueeze(1), torch::mm(untold, cond_weight), 1, -1);
  return y;
}

std::pair<torch::Tensor, torch::Tensor> CNeRFImpl::forward(const torch::Tensor& points, const AvatarConditioning& cond,
                                                           const torch::Tensor& hair) {
  if (hair.defined() && (hair.dim() != 1 || hair.size(0) != points.size(0)))
    throw std::invalid_argument("CNeRF: the hair mask must have one value per sample");
  const torch::Tensor enc = PositionalEncoding(points, config_.pe_frequencies, config_.pe_scale);
  torch::Tensor h;
  for (int k = 0; k < config_.mlp_layers; ++k) {
    const auto& layer = layers_->ptr<torch::nn::LinearImpl>(k);
    torch::nn::Linear linear(layer);
    if (k == 0) {
      h = ConditionedLinear(linear, torch::Tensor(), enc, cond.geometry, hair);
    } else if (k == config_.skip_layer) {
      h = ConditionedLinear(linear, h, enc, cond.geometry, hair);
    } else {
      h = linear->forward(h);
    }
    h = torch::relu(h);
  }
  const torch::Tensor density = F::softplus(density_->forward(h).squeeze(1) - 1.0);
  const torch::Tensor feat = feature_->forward(h);
  // Appearance (light, texture) joins after the density, as in NeRF's view branch.
  const torch::Tensor a = torch::relu(ConditionedLinear(appearance_, torch::Tensor(), feat, cond.appearance));
  return {density, out_->forward(a)};
}

void CNeRFImpl::FreezeFirstLayers(int n) {
  for (int k = 0; k < std::min<int>(n, config_.mlp_layers); ++k)
    for (auto& p : layers_[k]->parameters()) p.set_requires_grad(false);
}

VolumeRenderResult VolumeRender(const torch::Tensor& density, const torch::Tensor& features, const torch::Tensor& z,
                                const torch::Tensor& ray_length) {
  const int64_t s = z.size(1);
  torch::Tensor delta;
  if (s > 1) {
    delta = z.narrow(1, 1, s - 1) - z.narrow(1, 0, s - 1);
    delta = torch::cat({delta, delta.narrow(1, s - 2, 1)}, 1);  // the last interval as long as the one before
  } else {
    delta = torch::ones_like(z) * 0.01;
  }
  delta = delta * ray_length.unsqueeze(1);
  const torch::Tensor alpha = 1 - torch::exp(-density * delta);
  // Transmittance before each sample: exclusive cumulative product of (1 - alpha).
  const torch::Tensor keep = torch::cat({torch::ones_like(alpha.narrow(1, 0, 1)), 1 - alpha + 1e-10}, 1);
  const torch::Tensor transmittance = torch::cumprod(keep, 1).narrow(1, 0, s);
  const torch::Tensor weights = alpha * transmittance;  // (R, S)
  VolumeRenderResult r;
  r.features = torch::bmm(weights.unsqueeze(1), features).squeeze(1);
  r.opacity = weights.sum(1);
  r.depth = (weights * z).sum(1);
  return r;
}

SqueezeExcitationImpl::SqueezeExcitationImpl(int channels, int reduction) {
  const int hidden = std::max(1, channels / reduction);
  down_ = register_module("down", torch::nn::Linear(channels, hidden));
  up_ = register_module("up", torch::nn::Linear(hidden, channels));
}

torch::Tensor SqueezeExcitationImpl::Scale(const torch::Tensor& x) { return ScaleOfMeans(x.mean({2, 3})); }

torch::Tensor SqueezeExcitationImpl::ScaleOfMeans(const torch::Tensor& means) {
  return torch::sigmoid(up_->forward(torch::relu(down_->forward(means)))).unsqueeze(2).unsqueeze(3);
}

torch::Tensor SqueezeExcitationImpl::forward(const torch::Tensor& x) { return x * Scale(x); }

namespace {

// The renderer's LeakyReLU slope, in libtorch's layers and in the one-pass kernels alike.
constexpr float kLeakySlope = 0.2f;

// A 1x1 convolution. Without gradients on a channels-last image, oneDNN's
// kernel: on one thread libtorch sends a small batch's 1x1 convolutions
// through im2col and a matrix product with layout copies around it, slower
// at these channel counts (on two it picks oneDNN itself).
torch::Tensor Conv1x1(torch::nn::Conv2dImpl& conv, const torch::Tensor& x) {
  if (at::hasMKLDNN() && !torch::GradMode::is_enabled() && x.dim() == 4 &&
      x.suggest_memory_format() == torch::MemoryFormat::ChannelsLast)
    return torch::mkldnn_convolution(x.contiguous(torch::MemoryFormat::ChannelsLast), conv.weight, conv.bias, {0, 0},
                                     {1, 1}, {1, 1}, 1);
  return conv.forward(x);
}

// `window` (even edges) of x (B, C, h, w) upsampled x2 bilinearly: the same
// pixels as the whole picture upsampled, from the source pixels under the
// window and one more on each side (the filter's reach).
torch::Tensor UpsampleWindow(const torch::Tensor& x, const ImageWindow& window) {
  const int64_t h = x.size(2), w = x.size(3);
  const int64_t sy0 = std::max<int64_t>(window.y0 / 2 - 1, 0), sy1 = std::min<int64_t>(window.y1 / 2 + 1, h);
  const int64_t sx0 = std::max<int64_t>(window.x0 / 2 - 1, 0), sx1 = std::min<int64_t>(window.x1 / 2 + 1, w);
  const torch::Tensor up =
      F::interpolate(x.slice(2, sy0, sy1).slice(3, sx0, sx1), F::InterpolateFuncOptions()
                                                                  .scale_factor(std::vector<double>{2.0, 2.0})
                                                                  .mode(torch::kBilinear)
                                                                  .align_corners(false));
  return up.slice(2, window.y0 - 2 * sy0, window.y1 - 2 * sy0).slice(3, window.x0 - 2 * sx0, window.x1 - 2 * sx0);
}

void CheckWindow(const ImageWindow& w, int64_t height, int64_t width) {
  if (w.y0 < 0 || w.x0 < 0 || w.y1 > height || w.x1 > width || w.height() <= 0 || w.width() <= 0 || w.y0 % 2 ||
      w.y1 % 2 || w.x0 % 2 || w.x1 % 2)
    throw std::invalid_argument("NeuralRenderer: a window needs even edges inside the " + std::to_string(height) +
                                " x " + std::to_string(width) + " output");
}

}  // namespace

UpsamplingBlockImpl::UpsamplingBlockImpl(int in_channels, int out_channels) {
  global_se_ = register_module("global_se", SqueezeExcitation(in_channels));
  local_se_ = register_module("local_se", SqueezeExcitation(in_channels));
  global_ = register_module(
      "global_branch",
      torch::nn::Conv2d(torch::nn::Conv2dOptions(in_channels, 4 * out_channels, 3).padding(2).dilation(2)));
  local_ =
      register_module("local_branch", torch::nn::Conv2d(torch::nn::Conv2dOptions(in_channels, 4 * out_channels, 1)));
  shuffle_ = register_module("shuffle", torch::nn::PixelShuffle(2));
  const torch::Tensor k1 = torch::tensor({1.f, 2.f, 1.f});
  const torch::Tensor k2 = torch::outer(k1, k1) / 16.f;
  blur_ = register_buffer("blur", k2.view({1, 1, 3, 3}).repeat({out_channels, 1, 1, 1}));
}

torch::Tensor UpsamplingBlockImpl::forward(const torch::Tensor& x, const ImageWindow& window) {
  const int64_t height = 2 * x.size(2), width = 2 * x.size(3);
  CheckWindow(window, height, width);
  // The blur reaches one output pixel beyond the window; the branches' pixels
  // under those (input resolution) are computed, the dilated 3x3 reading two
  // more input pixels on each side (zeros beyond the picture, as its padding).
  const int64_t uy0 = std::max<int64_t>(window.y0 - 1, 0), uy1 = std::min<int64_t>(window.y1 + 1, height);
  const int64_t ux0 = std::max<int64_t>(window.x0 - 1, 0), ux1 = std::min<int64_t>(window.x1 + 1, width);
  const int64_t cy0 = uy0 / 2, cy1 = (uy1 + 1) / 2, cx0 = ux0 / 2, cx1 = (ux1 + 1) / 2;
  const auto leaky = F::LeakyReLUFuncOptions().negative_slope(kLeakySlope);
  // The dilated 3x3 on the input pixels it reads, with its own zero padding:
  // right beyond the picture, and sliced off again where real pixels lay there.
  const int64_t h = x.size(2), w = x.size(3);
  const int64_t iy0 = std::max<int64_t>(cy0 - 2, 0), iy1 = std::min<int64_t>(cy1 + 2, h);
  const int64_t ix0 = std::max<int64_t>(cx0 - 2, 0), ix1 = std::min<int64_t>(cx1 + 2, w);
  const torch::Tensor means = x.mean({2, 3});  // both squeezes average the same picture
  const torch::Tensor global =
      global_->forward(x.slice(2, iy0, iy1).slice(3, ix0, ix1) * global_se_->ScaleOfMeans(means))
          .slice(2, cy0 - iy0, cy1 - iy0)
          .slice(3, cx0 - ix0, cx1 - ix0);
  const torch::Tensor local =
      Conv1x1(*local_, x.slice(2, cy0, cy1).slice(3, cx0, cx1) * local_se_->ScaleOfMeans(means));
  if (!torch::GradMode::is_enabled() && x.size(0) == 1 && global.scalar_type() == torch::kFloat &&
      local.scalar_type() == torch::kFloat && global.stride(1) == 1 && local.stride(1) == 1) {
    // Inference on channels-last images: the rest in one pass (ShuffleBlur),
    // not six libtorch operations each writing a picture.
    torch::Tensor out = torch::empty({1, global.size(1) / 4, window.height(), window.width()},
                                     global.options().memory_format(torch::MemoryFormat::ChannelsLast));
    const auto view = [](const torch::Tensor& t) {
      return ChannelsLastView{t.data_ptr<float>(), t.size(2), t.size(3), t.size(1), t.stride(2), t.stride(3)};
    };
    ShuffleBlur(view(global), view(local), kLeakySlope,
                {cy0, cx0, height, width, window.y0, window.y1, window.x0, window.x1}, out.data_ptr<float>());
    return out;
  }
  const torch::Tensor g = F::leaky_relu(global, leaky), l = F::leaky_relu(local, leaky);
  const torch::Tensor up =
      shuffle_->forward(g + l).slice(2, uy0 - 2 * cy0, uy1 - 2 * cy0).slice(3, ux0 - 2 * cx0, ux1 - 2 * cx0);
  // Anti-aliasing blur (depthwise binomial) against PixelShuffle's checkerboard,
  // the picture's edge pixels repeated beyond it (copied: a replication pad is
  // a slow loop on the CPU).
  auto repeat_edges = [](torch::Tensor t, int dim, bool before, bool after) {
    std::vector<torch::Tensor> parts;
    if (before) parts.push_back(t.narrow(dim, 0, 1));
    parts.push_back(t);
    if (after) parts.push_back(t.narrow(dim, t.size(dim) - 1, 1));
    return parts.size() == 1 ? t : torch::cat(parts, dim);
  };
  const torch::Tensor padded =
      repeat_edges(repeat_edges(up, 2, window.y0 == 0, window.y1 == height), 3, window.x0 == 0, window.x1 == width)
          .contiguous(up.suggest_memory_format());  // cat may change the layout
  return F::conv2d(padded, blur_, F::Conv2dFuncOptions().groups(up.size(1)));
}

SurfaceTextureImpl::SurfaceTextureImpl(const AvatarConfig& config) : extent_(config.surface_extent) {
  config.Check();
  const int64_t r = config.surface_resolution;
  planes_ = register_parameter("planes", torch::zeros({3, config.surface_features, r, r}));
  if (config.surface_rigid)
    rigid_planes_ = register_parameter("rigid_planes", torch::zeros({3, config.surface_features, r, r}));
  if (config.surface_blend > 0) {
    blend_resolution_ = config.surface_blend;
    num_expression_ = config.num_expression;
    const int64_t k = config.surface_blend_components, rows = k > 0 ? k : num_expression_;
    blend_ = register_parameter(
        "blend", torch::zeros({rows, 3 * blend_resolution_ * blend_resolution_ * config.surface_features}));
    if (k > 0) {
      blend_mean_ = register_buffer("blend_mean", torch::zeros({num_expression_}));
      blend_directions_ = register_buffer("blend_directions", torch::zeros({k, num_expression_}));
      blend_low_ = register_buffer("blend_low", torch::zeros({k}));
      blend_high_ = register_buffer("blend_high", torch::zeros({k}));
    }
  }
}

void SurfaceTextureImpl::SetBlendBasis(const torch::Tensor& mean, const torch::Tensor& directions,
                                       const torch::Tensor& low, const torch::Tensor& high) {
  if (!blend_directions_.defined())
    throw std::invalid_argument("SurfaceTexture: only blendshapes over principal directions take a basis");
  const int64_t k = blend_directions_.size(0);
  if (mean.sizes() != blend_mean_.sizes() || directions.sizes() != blend_directions_.sizes() ||
      low.sizes() != blend_low_.sizes() || high.sizes() != blend_high_.sizes())
    throw std::invalid_argument("SurfaceTexture: the blend basis must be (" + std::to_string(num_expression_) + "), (" +
                                std::to_string(k) + ", " + std::to_string(num_expression_) + "), (" +
                                std::to_string(k) + ") and (" + std::to_string(k) + ")");
  for (const torch::Tensor& t : {mean, directions, low, high})
    if (!torch::isfinite(t).all().item<bool>())
      throw std::invalid_argument("SurfaceTexture: the blend basis has values that are not finite");
  if ((low > high).any().item<bool>())
    throw std::invalid_argument("SurfaceTexture: a blend direction's range has low > high");
  torch::NoGradGuard no_grad;
  blend_mean_.copy_(mean);
  blend_directions_.copy_(directions);
  blend_low_.copy_(low);
  blend_high_.copy_(high);
}

torch::Tensor SurfaceTextureImpl::BlendWeights(const torch::Tensor& expression) const {
  if (!expression.defined() || expression.dim() != 2 || expression.size(0) != 1 ||
      expression.size(1) != num_expression_)
    throw std::invalid_argument("SurfaceTexture: a blended texture needs the frame's " +
                                std::to_string(num_expression_) + " expression coefficients (1, E)");
  const torch::Tensor e = expression.to(blend_.dtype());
  if (!blend_directions_.defined()) return e;
  return torch::max(torch::min(torch::mm(e - blend_mean_, blend_directions_.t()), blend_high_), blend_low_);
}

void SurfaceTextureImpl::UseChannelsLast() {
  torch::NoGradGuard no_grad;
  planes_.set_data(planes_.contiguous(torch::MemoryFormat::ChannelsLast));
  if (rigid()) rigid_planes_.set_data(rigid_planes_.contiguous(torch::MemoryFormat::ChannelsLast));
  channels_last_ = true;
}

torch::Tensor SurfaceTextureImpl::forward(const torch::Tensor& canonical, const torch::Tensor& posed,
                                          const torch::Tensor& expression) {
  // The canonical points in the planes' [-1, 1], once for the texture and its blendshapes.
  const torch::Tensor unit = UnitPoints(canonical);
  torch::Tensor features = LookUp(planes_, unit);
  if (rigid()) {
    if (!posed.defined() || posed.sizes() != canonical.sizes())
      throw std::invalid_argument("SurfaceTexture: a rigid texture needs the posed points of the canonical ones");
    features = features + LookUp(rigid_planes_, UnitPoints(posed));
  }
  if (!blended()) return features;
  if (channels_last_ && !torch::GradMode::is_enabled() && features.is_contiguous() &&
      features.scalar_type() == torch::kFloat) {
    const torch::Tensor& texels = BlendTexels();
    const torch::Tensor weights = BlendWeights(expression).to(torch::kFloat).contiguous();
    const torch::Tensor at = unit.to(torch::kFloat).contiguous();
    AddBlendedLookUp({texels.data_ptr<float>(), blend_resolution_, texels.size(1), texels.size(2)},
                     weights.data_ptr<float>(), at.data_ptr<float>(), at.size(0), features.data_ptr<float>());
    return features;
  }
  return features + LookUp(BlendedPlanes(expression), unit);
}

const torch::Tensor& SurfaceTextureImpl::BlendTexels() {
  if (blend_texels_.defined() && blend_texels_version_ == static_cast<int64_t>(blend_._version()) &&
      blend_texels_source_ == blend_.data_ptr())
    return blend_texels_;
  torch::NoGradGuard no_grad;
  const int64_t rows = blend_.size(0), c = planes_.size(1);
  blend_texels_ = blend_.detach().to(torch::kFloat).view({rows, -1, c}).permute({1, 0, 2}).contiguous();
  blend_texels_version_ = static_cast<int64_t>(blend_._version());
  blend_texels_source_ = blend_.data_ptr();
  return blend_texels_;
}

torch::Tensor SurfaceTextureImpl::BlendedPlanes(const torch::Tensor& expression) const {
  const int64_t b = blend_resolution_, c = planes_.size(1);
  // (1, E or K) x (E or K, 3BBC): texel-major planes; viewed as (3, C, B, B) with channels-last strides.
  return torch::mm(BlendWeights(expression), blend_).view({3, b, b, c}).permute({0, 3, 1, 2});
}

torch::Tensor SurfaceTextureImpl::UnitPoints(const torch::Tensor& points) const {
  return (points / extent_).clamp(-1, 1);  // grid_sample's [-1, 1]
}

torch::Tensor SurfaceTextureImpl::LookUp(const torch::Tensor& planes, const torch::Tensor& u) const {
  const int64_t p = u.size(0);
  if (channels_last_ && !torch::GradMode::is_enabled() && planes.is_contiguous(torch::MemoryFormat::ChannelsLast)) {
    const torch::Tensor at = u.to(torch::kFloat).contiguous();
    torch::Tensor features = torch::empty({p, planes.size(1)}, at.options());
    LookUpTriplanes({planes.data_ptr<float>(), planes.size(2), planes.size(1)}, at.data_ptr<float>(), p,
                    features.data_ptr<float>());
    return features;
  }
  const torch::Tensor x = u.select(1, 0), y = u.select(1, 1), z = u.select(1, 2);
  // (3, 1, P, 2): the point's coordinates in the xy, xz and yz planes.
  const torch::Tensor grid =
      torch::stack({torch::stack({x, y}, 1), torch::stack({x, z}, 1), torch::stack({y, z}, 1)}, 0).unsqueeze(1);
  const torch::Tensor sampled = F::grid_sample(
      planes, grid,
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
  return sampled.sum(0).view({-1, p}).t();  // (3, C, 1, P) -> (P, C)
}

NeuralRendererImpl::NeuralRendererImpl(const AvatarConfig& config) {
  config.Check();
  const auto& ch = config.renderer_channels;
  levels_ = config.renderer_levels();
  const int last = levels_ - 1;
  input_rgb_ = register_module("input_rgb", torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[0], 3, 1)));
  if (config.has_surface()) {
    const int hidden = config.surface_hidden_channels();
    surface_hidden_ = register_module(
        "surface_hidden", torch::nn::Conv2d(torch::nn::Conv2dOptions(config.surface_branch_inputs(), hidden, 1)));
    surface_out_ = register_module("surface_out", torch::nn::Conv2d(torch::nn::Conv2dOptions(hidden, ch[levels_], 1)));
    // Zero: a renderer given surface features starts as the one without (a
    // fine-tune from a general model starts where the general model is); the
    // texture gets gradients from the first step that moves these weights.
    if (config.surface_conditioned)
      surface_film_ = register_module("surface_film", torch::nn::Linear(config.motion_dim(), 2 * hidden));
    // Earlier levels get the surface term averaged to their size through
    // their own 1x1 layers, zero at first too.
    first_surface_level_ = levels_ - config.surface_levels;
    if (first_surface_level_ < last) {  // files with the last level only hold no such entry
      surface_early_ = register_module("surface_early", torch::nn::ModuleList());
      for (int k = first_surface_level_; k < last; ++k)
        surface_early_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[levels_], ch[k + 1], 1)));
    }
    torch::NoGradGuard no_grad;
    surface_out_->weight.zero_();
    surface_out_->bias.zero_();
    if (surface_early_)
      for (auto& p : surface_early_->parameters()) p.zero_();
    // Zero too: a conditioned branch starts as the unconditioned one.
    if (surface_film_)
      for (auto& p : surface_film_->parameters()) p.zero_();
  }
  blocks_ = register_module("blocks", torch::nn::ModuleList());
  post_ = register_module("post", torch::nn::ModuleList());
  to_rgb_ = register_module("to_rgb", torch::nn::ModuleList());
  for (int k = 0; k < levels_; ++k) {
    blocks_->push_back(UpsamplingBlock(ch[k], ch[k + 1]));
    post_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[k + 1], ch[k + 1], 1)));
    to_rgb_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[k + 1], 3, 1)));
  }
  if (config.has_matte()) {
    input_alpha_ = register_module("input_alpha", torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[0], 1, 1)));
    to_alpha_ = register_module("to_alpha", torch::nn::ModuleList());
    for (int k = 0; k < levels_; ++k)
      to_alpha_->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(ch[k + 1], 1, 1)));
    // Covered everywhere at first: a matte added to a renderer without one
    // starts from the picture it drew (the weights still get gradients).
    torch::NoGradGuard no_grad;
    input_alpha_->weight.zero_();
    input_alpha_->bias.fill_(kInitialCoverageLogit);
    for (const auto& m : *to_alpha_)
      for (auto& p : m->parameters()) p.zero_();
  }
}

namespace {

// Four floats side by side (GCC's and Clang's vector extension, on any
// target): the branch's layers four outputs at a time.
using Float4 = float __attribute__((vector_size(16)));

// Points [0, count): features x (count, kIn) through the branch into rows
// y[row_of[i]]. a (kIn, kHidden) and ab: the first layer, FiLM folded in; c
// (kHidden, kOut) and cb: the second; each row in Float4s.
template <int kIn, int kHidden, int kOut>
void BranchPoints(const float* __restrict x, const int64_t* __restrict row_of, int64_t count,
                  const Float4* __restrict a, const Float4* __restrict ab, const Float4* __restrict c,
                  const Float4* __restrict cb, float* __restrict y) {
  static_assert(kHidden % 4 == 0 && kOut % 4 == 0);
  constexpr int kH = kHidden / 4, kO = kOut / 4;
  for (int64_t i = 0; i < count; ++i) {
    Float4 h[kH], o[kO];
    for (int j = 0; j < kH; ++j) h[j] = ab[j];
    for (int k = 0; k < kIn; ++k) {
      const float s = x[i * kIn + k];
      const Float4 v = {s, s, s, s};
      for (int j = 0; j < kH; ++j) h[j] += v * a[k * kH + j];
    }
    for (int j = 0; j < kH; ++j) h[j] = h[j] > 0 ? h[j] : h[j] * kLeakySlope;  // LeakyReLU, without branches
    for (int m = 0; m < kO; ++m) o[m] = cb[m];
    for (int j = 0; j < kHidden; ++j) {
      const float s = h[j / 4][j % 4];
      const Float4 v = {s, s, s, s};
      for (int m = 0; m < kO; ++m) o[m] += v * c[j * kO + m];
    }
    std::memcpy(y + row_of[i] * kOut, o, sizeof(o));
  }
}

// Inference: the surface branch of each point (P, Cs) written to its row of
// `rows` (H W, C3) in one pass, where libtorch makes a tensor per layer, per
// FiLM operation and for the scatter. w1 (hidden, Cs), w2 (C3, hidden);
// scale and shift (1, hidden), or undefined when unconditioned; every other
// row is `background` (1, C3). Undefined for a branch of other sizes than the
// shipped 8 -> 16 -> 8.
torch::Tensor SurfaceBranchRows(const torch::Tensor& features, const torch::Tensor& pixels, int64_t num_rows,
                                const torch::Tensor& background, const torch::Tensor& w1, const torch::Tensor& b1,
                                const torch::Tensor& scale, const torch::Tensor& shift, const torch::Tensor& w2,
                                const torch::Tensor& b2) {
  constexpr int kIn = 8, kHidden = 16, kOut = 8;
  const int64_t p = features.size(0);
  if (w1.size(1) != kIn || w1.size(0) != kHidden || w2.size(0) != kOut || w2.size(1) != kHidden) return {};
  if (features.dim() != 2 || features.size(1) != kIn || pixels.numel() != p)
    throw std::invalid_argument("SurfaceTerm: features, pixels and the branch do not match");
  const auto floats = [](const torch::Tensor& t) { return t.detach().to(torch::kFloat).contiguous(); };
  // Transposed, so that a layer's outputs lie side by side; FiLM folded into
  // the first layer: (W1 x + b1) * s + t = (W1 s) x + (b1 s + t).
  torch::Tensor a = floats(w1.t()), ab = floats(b1);
  if (scale.defined()) {
    a = floats(a * scale.view({1, kHidden}));
    ab = floats(ab * scale.view({kHidden}) + shift.view({kHidden}));
  }
  const torch::Tensor c = floats(w2.t()), cb = floats(b2), f = floats(features),
                      index = pixels.to(torch::kLong).contiguous();
  // Float4 copies, aligned as the vector type needs.
  std::vector<Float4> packed((kIn * kHidden + kHidden + kHidden * kOut + kOut) / 4);
  Float4* pa = packed.data();
  Float4* pab = pa + kIn * kHidden / 4;
  Float4* pc = pab + kHidden / 4;
  Float4* pcb = pc + kHidden * kOut / 4;
  std::memcpy(pa, a.data_ptr<float>(), kIn * kHidden * sizeof(float));
  std::memcpy(pab, ab.data_ptr<float>(), kHidden * sizeof(float));
  std::memcpy(pc, c.data_ptr<float>(), kHidden * kOut * sizeof(float));
  std::memcpy(pcb, cb.data_ptr<float>(), kOut * sizeof(float));
  const int64_t* row_of = index.data_ptr<int64_t>();
  for (int64_t i = 0; i < p; ++i)
    if (row_of[i] < 0 || row_of[i] >= num_rows) throw std::invalid_argument("SurfaceTerm: a pixel outside the image");
  torch::Tensor rows = background.to(torch::kFloat).expand({num_rows, kOut}).contiguous();
  const float* x = f.data_ptr<float>();
  float* y = rows.data_ptr<float>();
  at::parallel_for(0, p, 1024, [&](int64_t begin, int64_t end) {
    BranchPoints<kIn, kHidden, kOut>(x + begin * kIn, row_of + begin, end - begin, pa, pab, pc, pcb, y);
  });
  return rows;
}

}  // namespace

torch::Tensor NeuralRendererImpl::SurfaceTerm(const torch::Tensor& features, const torch::Tensor& pixels, int height,
                                              int width, const torch::Tensor& motion) {
  if (!surface_out_) throw std::logic_error("SurfaceTerm: this renderer has no surface branch");
  const auto leaky = F::LeakyReLUFuncOptions().negative_slope(kLeakySlope);
  torch::Tensor scale, shift;  // (1, hidden) each, once per frame
  if (surface_film_) {
    if (!motion.defined() || motion.dim() != 2 || motion.size(1) != surface_film_->weight.size(1))
      throw std::invalid_argument("SurfaceTerm: a conditioned surface branch needs the frame's motion (1, " +
                                  std::to_string(surface_film_->weight.size(1)) + ")");
    const auto film = surface_film_->forward(motion).chunk(2, 1);
    scale = 1 + film[0];
    shift = film[1];
  }
  auto branch = [&](const torch::Tensor& f) {  // (P, Cs) -> (P, C3): the 1x1 convolutions as matrices
    torch::Tensor h = F::linear(f, surface_hidden_->weight.flatten(1), surface_hidden_->bias);
    if (surface_film_) h = h * scale + shift;
    h = F::leaky_relu(h, leaky);
    return F::linear(h, surface_out_->weight.flatten(1), surface_out_->bias);
  };
  const int64_t channels = surface_out_->weight.size(0), in = surface_hidden_->weight.size(1);
  const torch::Tensor background = branch(torch::zeros({1, in}));  // (1, C3)
  if (channels_last_ && !torch::GradMode::is_enabled()) {
    const torch::Tensor rows = SurfaceBranchRows(features, pixels, static_cast<int64_t>(height) * width, background,
                                                 surface_hidden_->weight.flatten(1), surface_hidden_->bias, scale,
                                                 shift, surface_out_->weight.flatten(1), surface_out_->bias);
    if (rows.defined()) return rows.view({1, height, width, channels}).permute({0, 3, 1, 2});
  }
  torch::Tensor rows = background.expand({static_cast<int64_t>(height) * width, channels});
  if (features.size(0) > 0) rows = rows.index_copy(0, pixels, branch(features));
  if (channels_last_) return rows.view({1, height, width, channels}).permute({0, 3, 1, 2});  // rows are pixels
  return rows.t().reshape({1, channels, height, width});
}

void NeuralRendererImpl::UseChannelsLast() {
  torch::NoGradGuard no_grad;
  for (auto& t : parameters())
    if (t.dim() == 4) t.set_data(t.contiguous(torch::MemoryFormat::ChannelsLast));
  for (auto& t : buffers())
    if (t.dim() == 4) t.set_data(t.contiguous(torch::MemoryFormat::ChannelsLast));
  channels_last_ = true;
}

torch::Tensor NeuralRendererImpl::forward(const torch::Tensor& feature_map, const torch::Tensor& surface_term,
                                          torch::Tensor* coverage_logit, const ImageWindow* window) {
  const int64_t height = feature_map.size(2) << levels_, width = feature_map.size(3) << levels_;
  const ImageWindow last = window ? *window : ImageWindow::Whole(height, width);
  CheckWindow(last, height, width);
  const bool matte = input_alpha_ && coverage_logit;
  const torch::Tensor features =
      channels_last_ ? feature_map.contiguous(torch::MemoryFormat::ChannelsLast) : feature_map;
  torch::Tensor rgb = Conv1x1(*input_rgb_, features), alpha;
  if (matte) alpha = Conv1x1(*input_alpha_, features);
  torch::Tensor x = features;
  for (int k = 0; k < levels_; ++k) {
    // The last level draws the window only; the ones before it the whole
    // picture (its squeeze averages all of theirs).
    const bool at_last = k == levels_ - 1;
    const ImageWindow w = at_last ? last : ImageWindow::Whole(2 * x.size(2), 2 * x.size(3));
    rgb = UpsampleWindow(rgb, w);
    x = blocks_[k]->as<UpsamplingBlockImpl>()->forward(x, w);
    if (surface_term.defined() && at_last) x = x + surface_term.slice(2, w.y0, w.y1).slice(3, w.x0, w.x1);
    if (surface_term.defined() && !at_last && k >= first_surface_level_) {
      const int64_t factor = int64_t{1} << (levels_ - 1 - k);
      const torch::Tensor pooled = F::avg_pool2d(surface_term, F::AvgPool2dFuncOptions(factor));
      x = x + Conv1x1(*surface_early_[k - first_surface_level_]->as<torch::nn::Conv2dImpl>(),
                      pooled.contiguous(x.suggest_memory_format()));
    }
    x = F::leaky_relu(Conv1x1(*post_[k]->as<torch::nn::Conv2dImpl>(), x),
                      F::LeakyReLUFuncOptions().negative_slope(kLeakySlope));
    rgb = rgb + Conv1x1(*to_rgb_[k]->as<torch::nn::Conv2dImpl>(), x);
    if (matte) alpha = UpsampleWindow(alpha, w) + Conv1x1(*to_alpha_[k]->as<torch::nn::Conv2dImpl>(), x);
  }
  if (matte) *coverage_logit = alpha;
  return torch::sigmoid(rgb);
}

std::vector<torch::Tensor> AvatarModules::parameters() const {
  std::vector<torch::Tensor> p = cnerf->parameters();
  for (auto& t : renderer->parameters()) p.push_back(t);
  if (surface)
    for (auto& t : surface->parameters()) p.push_back(t);
  return p;
}
void AvatarModules::eval() {
  cnerf->eval();
  renderer->eval();
  if (surface) surface->eval();
}
void AvatarModules::train() {
  cnerf->train();
  renderer->train();
  if (surface) surface->train();
}

}  // namespace headcast
