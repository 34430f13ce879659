// The avatar pipeline and the real-time renderer.
#include "common/avatar/avatar_renderer.h"

#include <malloc.h>

#include <opencv2/imgproc.hpp>

#include "common/avatar/avatar_pipeline.h"
#include "common/avatar/compute_threads.h"
#include "common/avatar/outline_warp.h"
#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/core/timer.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/skin_colour.h"

namespace headcast {

AvatarConditioning MakeConditioning(const AvatarConfig& c, const SubjectParams& subject, const FrameParams& frame) {
  std::vector<float> g(c.conditioning_dim(), 0.f), a(c.appearance_dim(), 0.f);
  for (int i = 0; i < std::min<int>(c.num_shape, subject.shape.size()); ++i) g[i] = subject.shape[i];
  const Eigen::Vector3f neck = c.view_rotation
                                   ? MatrixToAxisAngle(AxisAngleToMatrix(ViewRotation(frame.CamFromHead().rotation)) *
                                                       AxisAngleToMatrix(frame.neck.cast<double>()))
                                         .cast<float>()
                                   : frame.neck;
  const Eigen::Vector3f* pose[] = {&neck, &frame.jaw, &frame.left_eye, &frame.right_eye};
  for (int j = 0; j < 4; ++j)
    for (int k = 0; k < 3; ++k) g[c.pose_offset() + 3 * j + k] = (*pose[j])[k];
  for (int i = 0; i < std::min<int>(c.num_expression, frame.expression.size()); ++i)
    g[c.expression_offset() + i] = c.ToldExpression(i, frame.expression[i]);
  for (int i = c.num_shape; i < c.conditioning_dim(); ++i)
    if (!c.Conditions(i)) g[i] = 0;
  for (int i = 0; i < 27; ++i) a[i] = subject.light[i];
  for (int i = 0; i < std::min<int>(c.num_texture, subject.texture.size()); ++i) a[27 + i] = subject.texture[i];
  if (c.has_conditioning_bias()) {
    for (int i = 0; i < c.conditioning_dim(); ++i)
      if (c.Conditions(i)) g[i] += c.bias_geometry[i];  // beta always
    for (int i = 0; i < c.appearance_dim(); ++i) a[i] += c.bias_appearance[i];
  }
  return {torch::tensor(g).view({1, -1}), torch::tensor(a).view({1, -1})};
}

namespace {

// (1, 3, 1, 1): the renders' background colour, RGB.
torch::Tensor BackgroundColour() {
  const cv::Vec3f rgb = HeadRenderOptions{}.background_rgb;
  return torch::tensor({rgb[0], rgb[1], rgb[2]}).view({1, 3, 1, 1});
}

// A bounded matte's bound and core: the silhouette of the covered output
// pixels and the posed landmarks projected, through the dataset's mask rules.
void MakeMatteBound(const AvatarConfig& config, const SurfaceBatch& surface, const HeadModelOutput& posed,
                    const RigidTransform& cam_from_head, const PinholeCamera& camera, AvatarFrameInputs* out) {
  cv::Mat silhouette(surface.height, surface.width, CV_8U, cv::Scalar(0));
  for (int i = 0; i < surface.mesh_pixels; ++i) silhouette.data[surface.pixel[i]] = 255;
  out->matte_bound = MatteBound(silhouette, ProjectLandmarks(posed, cam_from_head, camera), config.matte_rules);
  if (config.matte_core > 0)
    out->matte_core = MatteCore(silhouette, out->matte_bound, config.matte_core);
  else
    out->matte_core.release();
}

// (1, 1, h, w) in {0, 1} from `window` of a CV_8U mask.
torch::Tensor MaskTensor(const cv::Mat& m, const ImageWindow& window) {
  return torch::from_blob(m.data, {1, 1, m.rows, m.cols}, torch::kUInt8)
             .slice(2, window.y0, window.y1)
             .slice(3, window.x0, window.x1)
             .to(torch::kFloat) /
         255.f;
}

// The smallest window with even edges around the mask's pixels (a 2 x 2 one at
// the top left when it has none: everything is background then).
ImageWindow WindowAround(const cv::Mat& mask) {
  const cv::Rect box = cv::boundingRect(mask);
  if (box.empty()) return {0, 2, 0, 2};
  auto down = [](int v) { return static_cast<int64_t>(v - v % 2); };
  auto up = [](int v, int limit) { return static_cast<int64_t>(std::min(v + v % 2, limit)); };
  return {down(box.y), up(box.y + box.height, mask.rows), down(box.x), up(box.x + box.width, mask.cols)};
}

}  // namespace

void ImageTensorToBgr(const torch::Tensor& image, cv::Mat* out) {
  const torch::Tensor bytes =
      image.squeeze(0).flip({0}).permute({1, 2, 0}).mul(255.f).round().clamp(0, 255).to(torch::kUInt8).contiguous();
  out->create(static_cast<int>(bytes.size(0)), static_cast<int>(bytes.size(1)), CV_8UC3);
  std::memcpy(out->data, bytes.data_ptr<uint8_t>(), bytes.numel());
}

torch::Tensor BgrToImageTensor(const cv::Mat& bgr) {
  const cv::Mat contiguous = bgr.isContinuous() ? bgr : bgr.clone();
  return torch::from_blob(contiguous.data, {contiguous.rows, contiguous.cols, 3}, torch::kUInt8)
             .flip({2})
             .permute({2, 0, 1})
             .unsqueeze(0)
             .to(torch::kFloat) /
         255.f;
}

void RunAvatarFeatures(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                       AvatarTimings* timings) {
  const RayBatch& rays = inputs.rays;
  const RigidTransform& cam_from_head = inputs.cam_from_head;
  const AvatarConditioning& conditioning = inputs.conditioning;
  Stopwatch watch;
  const int64_t r = rays.num_rays(), s = rays.samples_per_ray;
  const int channels = modules.cnerf->config().feature_channels;
  torch::Tensor feature_rows = torch::zeros({static_cast<int64_t>(rays.width) * rays.height, channels});
  torch::Tensor opacity_rows = torch::zeros({static_cast<int64_t>(rays.width) * rays.height});
  if (r > 0) {
    const torch::Tensor dirs = torch::from_blob(const_cast<float*>(rays.directions.data()), {r, 3}, torch::kFloat);
    const torch::Tensor z = torch::from_blob(const_cast<float*>(rays.depths.data()), {r, s}, torch::kFloat);
    // Camera-frame samples to the head frame: p_head = R^T (p_cam - t).
    const torch::Tensor R =
        torch::tensor(std::vector<float>(cam_from_head.rotation.data(), cam_from_head.rotation.data() + 9))
            .view({3, 3})
            .t();  // Eigen is column-major: this is R (row-major)
    const torch::Tensor t = torch::tensor({static_cast<float>(cam_from_head.translation.x()),
                                           static_cast<float>(cam_from_head.translation.y()),
                                           static_cast<float>(cam_from_head.translation.z())});
    const torch::Tensor p_cam = (z.unsqueeze(2) * dirs.unsqueeze(1)).view({r * s, 3});
    torch::Tensor p_head = torch::matmul(p_cam - t, R);  // (p - t) R == (R^T (p - t))^T
    if (!inputs.to_canonical.empty()) {                  // per ray: p A^T + o
      const torch::Tensor to = torch::from_blob(const_cast<float*>(inputs.to_canonical.data()), {r, 12}, torch::kFloat);
      const torch::Tensor a = to.narrow(1, 0, 9).view({r, 3, 3}), o = to.narrow(1, 9, 3);
      p_head = (torch::bmm(p_head.view({r, s, 3}), a.transpose(1, 2)) + o.unsqueeze(1)).view({r * s, 3});
    }
    torch::Tensor hair;  // per sample: its ray's
    if (!inputs.hair_rays.empty())
      hair = torch::from_blob(const_cast<float*>(inputs.hair_rays.data()), {r}, torch::kFloat).repeat_interleave(s);
    auto [density, features] = modules.cnerf->forward(p_head, conditioning, hair);
    if (timings) timings->mlp_ms += watch.ElapsedMs();
    watch.Restart();
    const VolumeRenderResult vr =
        VolumeRender(density.view({r, s}), features.view({r, s, channels}), z, dirs.norm(2, 1));
    const torch::Tensor index =
        torch::from_blob(const_cast<int32_t*>(rays.pixel.data()), {r}, torch::kInt).to(torch::kLong);
    feature_rows = feature_rows.index_copy(0, index, vr.features);
    opacity_rows = opacity_rows.index_copy(0, index, vr.opacity);
  }
  out->feature_map = feature_rows.t().reshape({1, channels, rays.height, rays.width});
  out->opacity = opacity_rows.view({1, 1, rays.height, rays.width});
  if (timings) {
    timings->composite_ms += watch.ElapsedMs();
    timings->rays = static_cast<int>(r);
    timings->samples = static_cast<int>(r * s);
  }
}

void RunAvatarSurfaceFeatures(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                              AvatarTimings* timings) {
  if (!modules.surface) return;
  Stopwatch watch;
  const SurfaceBatch& surface = inputs.surface;
  const int64_t n = surface.num_pixels();
  const AvatarConfig& config = modules.cnerf->config();
  const torch::Tensor canonical = torch::from_blob(const_cast<float*>(surface.canonical.data()), {n, 3}, torch::kFloat);
  torch::Tensor posed;
  if (config.needs_posed_points()) {
    if (surface.posed.size() != surface.canonical.size())
      throw std::invalid_argument(
          "RunAvatarSurfaceFeatures: the rigid texture and the displacement need the surface's posed points");
    posed = torch::from_blob(const_cast<float*>(surface.posed.data()), {n, 3}, torch::kFloat);
  }
  // The blendshapes weighted by what the networks are told (within the avatar's span).
  const torch::Tensor expression =
      modules.surface->blended()
          ? inputs.conditioning.geometry.narrow(1, config.expression_offset(), config.num_expression)
          : torch::Tensor();
  torch::Tensor features =
      n > 0 ? modules.surface->forward(canonical, modules.surface->rigid() ? posed : torch::Tensor(), expression)
            : torch::zeros({0, config.surface_features});
  if (config.surface_displacement)
    features =
        torch::cat({features, n > 0 ? (posed - canonical) * kSurfaceDisplacementScale : torch::zeros({0, 3})}, 1);
  out->surface_features = features;
  if (timings) timings->texture_ms += watch.ElapsedMs();
}

void RunAvatarUpsampling(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarOutput* out,
                         AvatarTimings* timings) {
  if (modules.surface && !out->surface_features.defined()) RunAvatarSurfaceFeatures(modules, inputs, out, timings);
  Stopwatch watch;
  const AvatarConditioning& conditioning = inputs.conditioning;
  torch::Tensor surface_term;
  if (modules.surface) {
    const SurfaceBatch& surface = inputs.surface;
    const AvatarConfig& config = modules.cnerf->config();
    const torch::Tensor pixels =
        torch::from_blob(const_cast<int32_t*>(surface.pixel.data()), {surface.num_pixels()}, torch::kInt)
            .to(torch::kLong);
    const torch::Tensor motion = config.surface_conditioned
                                     ? conditioning.geometry.narrow(1, config.num_shape, config.motion_dim())
                                     : torch::Tensor();
    surface_term = modules.renderer->SurfaceTerm(out->surface_features, pixels, surface.height, surface.width, motion);
  }
  if (!modules.cnerf->config().has_matte()) {
    out->image = modules.renderer->forward(out->feature_map, surface_term);
  } else {
    // Beyond a bound the picture is the background whatever the networks say:
    // the last level draws only the window around it.
    const int64_t stride = modules.cnerf->config().feature_stride();
    const int64_t height = stride * out->feature_map.size(2), width = stride * out->feature_map.size(3);
    const ImageWindow window =
        inputs.matte_bound.empty() ? ImageWindow::Whole(height, width) : WindowAround(inputs.matte_bound);
    torch::Tensor logit;
    const torch::Tensor rgb = modules.renderer->forward(out->feature_map, surface_term, &logit, &window);
    const double scale = inputs.coverage_scale > 0 ? inputs.coverage_scale : modules.cnerf->config().matte_scale;
    torch::Tensor coverage = torch::sigmoid(scale == 1 ? logit : logit * scale);
    if (!inputs.matte_core.empty()) {
      const torch::Tensor core = MaskTensor(inputs.matte_core, window);
      coverage = core + (1 - core) * coverage;
    }
    if (!inputs.matte_bound.empty()) coverage = coverage * MaskTensor(inputs.matte_bound, window);
    const torch::Tensor background = BackgroundColour();
    const torch::Tensor image = coverage * rgb + (1 - coverage) * background;
    const std::vector<int64_t> beyond = {window.x0, width - window.x1, window.y0, height - window.y1};
    out->coverage = torch::constant_pad_nd(coverage, beyond);
    out->image = torch::constant_pad_nd(image - background, beyond) + background;
  }
  if (timings) timings->upsample_ms += watch.ElapsedMs();
}

AvatarOutput RunAvatar(AvatarModules& modules, const AvatarFrameInputs& inputs, AvatarTimings* timings) {
  AvatarOutput out;
  RunAvatarFeatures(modules, inputs, &out, timings);
  RunAvatarUpsampling(modules, inputs, &out, timings);
  return out;
}

Landmarks2d ProjectLandmarks(const HeadModelOutput& posed, const RigidTransform& cam_from_head,
                             const PinholeCamera& camera) {
  Landmarks2d landmarks;
  for (int l = 0; l < kNumLandmarks; ++l)
    landmarks[l] = camera.Project(cam_from_head.Apply(posed.landmarks.row(l).transpose().cast<double>()));
  return landmarks;
}

void PrepareAvatarRays(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                       const SubjectParams& subject, const FrameParams& frame, RaySampler* sampler, std::mt19937* rng,
                       AvatarFrameInputs* out, AvatarTimings* timings, const ParallelTasks* parallel) {
  Stopwatch watch;
  out->cam_from_head = frame.CamFromHead();
  model.Forward(identity, frame.expression.cast<double>(), frame.HeadPose(), &out->posed, parallel);
  TransformToCamera(out->posed.vertices, out->cam_from_head, &out->v_cam);
  if (timings) timings->head_model_ms = watch.ElapsedMs();
  watch.Restart();
  const int f = config.feature_size();
  sampler->Sample(out->v_cam, model.data().faces, subject.intrinsics.Resized(f, f), out->cam_from_head, rng,
                  &out->rays);
  out->to_canonical.clear();
  if (config.canonical_samples)
    CanonicalTransforms(out->rays, out->posed.vertices, model.data().faces, identity.v_shaped, &out->to_canonical,
                        config.covered_apart ? &sampler->Covered(identity.v_shaped, model.data().faces) : nullptr);
  out->hair_rays.clear();
  if (config.has_hair_conditioning()) HairRays(out->rays, sampler->Hair(model), &out->hair_rays);
  out->conditioning = MakeConditioning(config, subject, frame);
  if (timings) timings->sample_ms = watch.ElapsedMs();
}

void PrepareAvatarSurface(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                          const SubjectParams& subject, RaySampler* sampler, AvatarFrameInputs* out,
                          AvatarTimings* timings) {
  Stopwatch watch;
  // The bound needs the full-resolution silhouette the surface lookup makes.
  if (config.has_surface() || config.matte == MatteMode::kBounded) {
    sampler->SampleSurface(out->v_cam, model.data().faces, identity.v_shaped, subject.intrinsics, &out->surface,
                           config.needs_posed_points() ? &out->posed.vertices : nullptr);
    if (config.surface_eye_symmetry) FoldEyeballPoints(model, identity, &out->surface);
    // The rays' table (PrepareAvatarRays made it): read only here, beside the network.
    if (config.covered_apart && config.has_surface())
      MoveCoveredPointsApart(sampler->Covered(identity.v_shaped, model.data().faces), &out->surface);
  }
  if (config.matte == MatteMode::kBounded) {
    MakeMatteBound(config, out->surface, out->posed, out->cam_from_head, subject.intrinsics, out);
  } else {
    out->matte_bound.release();
    out->matte_core.release();
  }
  if (timings) timings->surface_ms = watch.ElapsedMs();
}

void PrepareAvatarFrame(const AvatarConfig& config, const HeadModel& model, const HeadIdentity& identity,
                        const SubjectParams& subject, const FrameParams& frame, RaySampler* sampler, std::mt19937* rng,
                        AvatarFrameInputs* out, AvatarTimings* timings) {
  PrepareAvatarRays(config, model, identity, subject, frame, sampler, rng, out, timings);
  PrepareAvatarSurface(config, model, identity, subject, sampler, out, timings);
}

void RenderAvatarFrame(AvatarModules& modules, const AvatarConfig& config, const HeadModel& model,
                       const HeadIdentity& identity, const SubjectParams& subject, const FrameParams& frame,
                       RaySampler* sampler, AvatarFrameInputs* buffers, cv::Mat* image_bgr, AvatarTimings* timings,
                       const ParallelTasks* parallel) {
  PrepareAvatarRays(config, model, identity, subject, frame, sampler, nullptr, buffers, timings, parallel);
  // The network needs only the rays; the output-size raster and the matte
  // bound, and the texture looked up there, only the upsampling: with
  // `parallel`, the pool's other thread does them meanwhile (each task's
  // operations then run on one thread).
  AvatarOutput out;
  auto surface = [&] {
    PrepareAvatarSurface(config, model, identity, subject, sampler, buffers, timings);
    RunAvatarSurfaceFeatures(modules, *buffers, &out, timings);
  };
  auto features = [&] { RunAvatarFeatures(modules, *buffers, &out, timings); };
  if (parallel && *parallel) {
    (*parallel)(2, [&](int k) { k == 0 ? features() : surface(); });
  } else {
    surface();
    features();
  }
  const bool moves_outline = config.outline_ramp > 0 && !frame.outline.empty();
  buffers->coverage_scale = moves_outline ? config.outline_matte_scale : 0;
  RunAvatarUpsampling(modules, *buffers, &out, timings);
  Stopwatch watch;
  if (config.motion_blur > 0) {
    if (const std::optional<ImageMotion> motion = MotionSincePrevious(*buffers, frame, subject.intrinsics)) {
      out.image = BlurAlongMotion(out.image, *motion, config.motion_blur);
      if (out.coverage.defined()) out.coverage = BlurAlongMotion(out.coverage, *motion, config.motion_blur);
    }
    buffers->previous_v_cam = buffers->v_cam;
    buffers->previous_sequence = frame.sequence;
  }
  if (moves_outline && out.coverage.defined()) {
    OutlineOptions outline;
    outline.bins = static_cast<int>(frame.outline.size());
    outline.centre_y_m = config.outline_centre_y;
    const double height = static_cast<double>(out.image.size(2));
    WarpToOutline(frame.outline, OutlineFrame::Of(subject.intrinsics, buffers->cam_from_head, outline), outline,
                  {config.outline_ramp * height, kOutlineMaxShift * height}, &out.image, &out.coverage);
  }
  ImageTensorToBgr(out.image, image_bgr);
  if (frame.skin_colour)
    MatchSkinColour(out, *frame.skin_colour,
                    ProjectLandmarks(buffers->posed, buffers->cam_from_head, subject.intrinsics), image_bgr);
  if (timings) timings->convert_ms = watch.ElapsedMs();
}

std::optional<ImageMotion> MotionSincePrevious(const AvatarFrameInputs& buffers, const FrameParams& frame,
                                               const PinholeCamera& camera) {
  if (!buffers.previous_sequence || frame.sequence <= *buffers.previous_sequence ||
      frame.sequence - *buffers.previous_sequence > kMotionBlurMaxGap)
    return std::nullopt;
  return MeasureImageMotion(buffers.previous_v_cam, buffers.v_cam, camera,
                            static_cast<int>(frame.sequence - *buffers.previous_sequence));
}

bool MatchSkinColour(const AvatarOutput& out, const Eigen::Vector3f& target, const Landmarks2d& landmarks,
                     cv::Mat* image_bgr) {
  const std::optional<Eigen::Vector3f> drawn = SkinColour(*image_bgr, landmarks);
  if (!drawn || !target.allFinite()) return false;
  // Per channel; bounded, so that a region the avatar draws dark (a hand, a
  // shadow the landmarks misplaced) cannot blow the picture up.
  std::array<float, 3> gain;
  for (int c = 0; c < 3; ++c)
    gain[c] = std::clamp(target[c] / std::max((*drawn)[c], 1.f / 255), kMinSkinGain, kMaxSkinGain);
  const torch::Tensor g = torch::tensor({gain[0], gain[1], gain[2]}).view({1, 3, 1, 1});
  const torch::Tensor background = BackgroundColour();
  // The head's own colour is scaled, not the background it is composited over:
  // with a matte the picture is coverage x rgb + (1 - coverage) x background.
  const torch::Tensor head =
      out.coverage.defined() ? out.image - (1 - out.coverage) * background : out.image - background;
  ImageTensorToBgr((out.image + (g - 1) * head).clamp(0, 1), image_bgr);
  return true;
}

void AvatarBackendOptions::Check() const {
  OptionsCheck c("avatar backend");
  c.InRange("threads", threads, 1, 256);
  c.ThrowIfErrors();
}

std::vector<std::string> AvatarBackendKinds() { return {AvatarRenderer::kKind}; }

std::unique_ptr<AvatarBackend> OpenAvatarBackend(const std::string& path, std::shared_ptr<const HeadModel> model,
                                                 const AvatarBackendOptions& options) {
  if (!model) throw std::invalid_argument("OpenAvatarBackend: no head model");
  const std::string kind = Avatar::ReadManifest(path).value("kind", std::string(AvatarRenderer::kKind));
  if (kind == AvatarRenderer::kKind)
    return std::make_unique<AvatarRenderer>(model, Avatar::Load(path, *model), options);
  std::string known;
  for (const std::string& k : AvatarBackendKinds()) known += (known.empty() ? "" : ", ") + k;
  throw std::runtime_error(path + ": avatar backend '" + kind + "' is not in this build (it has: " + known + ")");
}

struct AvatarRenderer::Impl {
  Impl(std::shared_ptr<const HeadModel> m, Avatar a)
      : model(std::move(m)), avatar(std::move(a)), sampler(avatar.config()) {}
  std::shared_ptr<const HeadModel> model;
  Avatar avatar;
  RaySampler sampler;
  HeadIdentity identity;
  AvatarFrameInputs buffers;
  ParallelTasks parallel;  // with two threads or more
};

AvatarRenderer::AvatarRenderer(std::shared_ptr<const HeadModel> model, Avatar avatar,
                               const AvatarRendererOptions& options) {
  options.Check();
  if (!model) throw std::invalid_argument("AvatarRenderer: no head model");
  if (avatar.head_model_fingerprint() != model->fingerprint())
    throw std::invalid_argument("AvatarRenderer: the avatar was made for head model " +
                                avatar.head_model_fingerprint() + ", not " + model->fingerprint() + " ('" +
                                model->data().name + "')");
  // Per-frame tensors are a few MB: keep them in the heap, reused, instead of
  // fresh mmap'd pages the kernel must zero every frame (DESIGN: performance).
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  SetComputeThreads(options.threads);
  impl_ = std::make_unique<Impl>(std::move(model), std::move(avatar));
  if (options.threads > 1 && options.parallel_stages) impl_->parallel = TorchParallelTasks();
  impl_->avatar.modules().eval();
  if (options.channels_last) {
    impl_->avatar.modules().renderer->UseChannelsLast();
    if (impl_->avatar.modules().surface) impl_->avatar.modules().surface->UseChannelsLast();
  }
  Eigen::VectorXd beta = impl_->avatar.subject().shape.cast<double>();
  impl_->identity = impl_->model->MakeIdentity(beta);
}

AvatarRenderer::~AvatarRenderer() = default;
const Avatar& AvatarRenderer::avatar() const { return impl_->avatar; }
const HeadModel& AvatarRenderer::head_model() const { return *impl_->model; }

bool AvatarRenderer::Render(const FrameParams& params, cv::Mat* image, AvatarTimings* timings, std::string* why) {
  if (!params.IsValid(why)) return false;
  Impl& m = *impl_;
  AvatarTimings local;
  AvatarTimings& t = timings ? *timings : local;
  t = AvatarTimings();
  Stopwatch total;
  torch::InferenceMode inference;
  RenderAvatarFrame(m.avatar.modules(), m.avatar.config(), *m.model, m.identity, m.avatar.subject(), params, &m.sampler,
                    &m.buffers, image, &t, &m.parallel);
  t.total_ms = total.ElapsedMs();
  return true;
}

const AvatarCommonConfig& AvatarRenderer::common_config() const { return impl_->avatar.config(); }
std::optional<CameraContract> AvatarRenderer::camera_contract() const { return impl_->avatar.camera_contract(); }
const SubjectParams& AvatarRenderer::subject() const { return impl_->avatar.subject(); }

}  // namespace headcast
