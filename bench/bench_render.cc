// Benchmark suite "render": the receiver's avatar synthesis on the CPU.
#include <sys/resource.h>

#include <cmath>

#include "bench/bench.h"
#include "common/avatar/avatar_renderer.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"

namespace headcast::bench {
namespace {

double PeakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss / 1024.0;
}
long MinorFaults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// A talking, slightly moving head in front of the camera: frame i of a loop.
// With `skin_colour`, the frame carries the camera's skin colour as a sender's
// frames do (a warm tone drifting a little), so that the receiver matches its
// picture to it.
FrameParams MovingHead(const HeadModel& model, int i, bool skin_colour = false) {
  FrameParams p;
  if (skin_colour) p.skin_colour = Eigen::Vector3f(0.72f + 0.05f * std::sin(0.02f * i), 0.52f, 0.42f);
  p.expression = Eigen::VectorXf::Zero(model.num_expression());
  for (int e = 0; e < model.num_expression(); ++e) p.expression[e] = 0.5f * std::sin(0.1f * i + e);
  p.jaw = Eigen::Vector3f(0.15f * (1 + std::sin(0.3f * i)), 0, 0);
  p.SetCamFromHead(FrontalCamFromHead(0.62, 15 * std::sin(0.05 * i), 5 * std::sin(0.07 * i)));
  return p;
}

nlohmann::json MeasureConfig(const std::shared_ptr<const HeadModel>& model, const BenchOptions& options,
                             const AvatarConfig& config, int frames, AvatarRendererOptions renderer_options = {},
                             bool skin_colour = false) {
  Avatar avatar = Avatar::CreateRandom(config, *model, DefaultSubject(*model, config.output_size), 1);
  renderer_options.threads = options.threads;
  AvatarRenderer renderer(model, std::move(avatar), renderer_options);
  cv::Mat image;
  AvatarTimings t;
  for (int i = 0; i < std::min(options.warmup, 5); ++i) renderer.Render(MovingHead(*model, i, skin_colour), &image, &t);
  SampleStats total, head, sample, surface, texture, mlp, composite, upsample, convert, rays, samples;
  const long faults_before = MinorFaults();
  for (int i = 0; i < frames; ++i) {
    if (!renderer.Render(MovingHead(*model, i, skin_colour), &image, &t))
      throw std::runtime_error("render refused its parameters");
    total.Add(t.total_ms);
    head.Add(t.head_model_ms);
    sample.Add(t.sample_ms);
    surface.Add(t.surface_ms);
    texture.Add(t.texture_ms);
    mlp.Add(t.mlp_ms);
    composite.Add(t.composite_ms);
    upsample.Add(t.upsample_ms);
    convert.Add(t.convert_ms);
    rays.Add(t.rays);
    samples.Add(t.samples);
  }
  nlohmann::json out;
  out["config"] = config.ToJson();
  out["frames"] = frames;
  out["threads"] = options.threads;
  out["ms_median"] = total.Median();
  out["ms_p95"] = total.Percentile(95);
  out["fps_median"] = 1000.0 / total.Median();
  out["stage_ms_median"] = {{"head_model", head.Median()},   {"sample", sample.Median()},
                            {"surface", surface.Median()},   {"texture", texture.Median()},
                            {"mlp", mlp.Median()},           {"composite", composite.Median()},
                            {"upsample", upsample.Median()}, {"convert", convert.Median()}};
  out["rays_median"] = rays.Median();
  out["samples_median"] = samples.Median();
  out["minor_page_faults_per_frame"] = static_cast<double>(MinorFaults() - faults_before) / frames;
  out["peak_rss_mb"] = PeakRssMb();
  return out;
}

}  // namespace

nlohmann::json RunRenderSuite(const BenchOptions& options) {
  nlohmann::json out;
  out["suite"] = "render";
  // A real head model's expression count sets what the texture's blendshapes
  // and the head model's pass cost (ICT-FaceKit: 53 against the builtin's 13).
  const auto model = std::make_shared<const HeadModel>(LoadHeadModelSpec(options.head_model));
  out["what"] = "AvatarRenderer::Render on a random-initialised avatar, one frame end to end, ms";
  out["head_model"] = model->data().name;
  out["head_model_expressions"] = model->num_expression();
  out["resolution"] = options.resolution;
  const int frames = std::max(1, std::min(options.repeats, 1000));
  const nlohmann::json ours = MeasureConfig(model, options, AvatarConfig::Default(options.resolution), frames);
  for (auto& [k, v] : ours.items()) out[k] = v;
  // A variant's timings, with `extra` fields that say what it is.
  auto timings = [](const nlohmann::json& m, nlohmann::json extra) {
    for (const char* k : {"ms_median", "ms_p95", "fps_median", "stage_ms_median"}) extra[k] = m[k];
    return extra;
  };
  // The same frames with the other libtorch thread count, side by side.
  BenchOptions other = options;
  other.threads = options.threads == 1 ? 2 : 1;
  out["other_thread_count"] = timings(MeasureConfig(model, other, AvatarConfig::Default(options.resolution), frames),
                                      {{"threads", other.threads}});
  // The same frames with the surface texture a subject's avatar adds (its
  // raster at output resolution, texture look-up and per-pixel branch).
  AvatarConfig surface = AvatarConfig::Default(options.resolution);
  surface.surface_features = kSubjectSurfaceFeatures;
  out["with_surface"] =
      timings(MeasureConfig(model, options, surface, frames), {{"surface_features", surface.surface_features}});
  // And a subject's default avatar: the texture, its conditioned branch and
  // expression blendshapes (as many as the head model's coefficients), and
  // the bounded matte (its bound's dilations and polygon per frame, the
  // coverage's convolutions).
  AvatarConfig subject = AvatarConfig::Default(options.resolution);
  ApplySubjectDefaults(&subject);
  out["subject_default"] =
      timings(MeasureConfig(model, options, subject, frames), {{"surface_features", subject.surface_features},
                                                               {"surface_conditioned", subject.surface_conditioned},
                                                               {"surface_blend", subject.surface_blend},
                                                               {"matte", MatteModeName(subject.matte)}});
  // A subject's avatar with a two-level renderer: the feature map at output/4
  // (four times the rays, with the same reach beyond the silhouette) and half
  // the samples per ray.
  AvatarConfig two_levels = subject;
  ApplyTwoLevelRenderer(&two_levels);
  out["subject_two_levels"] =
      timings(MeasureConfig(model, options, two_levels, frames), {{"renderer_channels", two_levels.renderer_channels},
                                                                  {"feature_size", two_levels.feature_size()},
                                                                  {"samples_per_ray", two_levels.samples_per_ray}});
  // The subject's default without the covered parts apart (the thesis's
  // head-frame samples keep them together), side by side: what the covered
  // faces' look-up and move cost per frame.
  AvatarConfig together = subject;
  together.covered_apart = false;
  out["subject_covered_together"] =
      timings(MeasureConfig(model, options, together, frames), {{"covered_apart", together.covered_apart}});
  // The subject's default with frames that carry the camera's skin colour, as
  // a default sender's do: the receiver measures its picture's skin and scales
  // the head to match (in the "convert" stage).
  out["subject_default_skin_colour"] =
      timings(MeasureConfig(model, options, subject, frames, {}, true), {{"skin_colour", true}});
  // The subject's default again with the convolutions on images in libtorch's
  // default layout (channels first), side by side: what channels-last buys.
  AvatarRendererOptions channels_first;
  channels_first.channels_last = false;
  out["subject_default_channels_first"] =
      timings(MeasureConfig(model, options, subject, frames, channels_first), nlohmann::json::object());
  if (options.threads > 1) {
    // And with the stages one after the other (AvatarBackendOptions::parallel_stages off).
    AvatarRendererOptions serial;
    serial.parallel_stages = false;
    out["subject_default_serial_stages"] =
        timings(MeasureConfig(model, options, subject, frames, serial), nlohmann::json::object());
  }
  if (options.compare_headnerf) {
    // The same pipeline at HeadNeRF's size (only defined at 256: 32x32 feature map).
    out["headnerf_sized"] =
        MeasureConfig(model, options, AvatarConfig::HeadNeRFSized(), std::max(1, std::min(frames, 3)));
    out["speedup_vs_headnerf_sized"] =
        out["headnerf_sized"]["ms_median"].get<double>() / ours["ms_median"].get<double>();
  }
  return out;
}

}  // namespace headcast::bench
