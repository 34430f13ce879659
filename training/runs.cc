// headcast-train's subcommands.
#include "training/runs.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "common/avatar/avatar_pipeline.h"
#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/frame_tracker.h"
#include "common/tracking/mesh_fitter.h"
#include "proto/recording.h"
#include "training/landmark_agreement.h"
#include "training/run_report.h"
#include "training/temporal_agreement.h"

namespace headcast {
namespace fs = std::filesystem;

namespace {

// What every training run checks: its resolution and outputs.
void CheckRun(int resolution, const RunOutputs& o, OptionsCheck* c) {
  c->That(resolution == 128 || resolution == 256 || resolution == 512, "resolution is 128, 256 or 512");
  c->That(!o.out.empty(), "out is required").NonNegative("eval_every", o.eval_every);
  c->InRange("eval_frames", o.eval_frames, 1, 100000);
}

// The loop around TrainAvatar that people see: progress with ETA, the loss
// CSV, held-out figures every eval_every steps, plots at the end.
TrainResult TrainWithReports(Avatar& avatar, const HeadModel& model, const TrainingData& data, const FitOptions& fit,
                             const RunOutputs& out, const std::function<EvalResult(Avatar&)>& evaluate) {
  std::optional<ProgressLine> progress;
  CsvLog loss_log, eval_log;
  double last_psnr = NAN;
  if (fit.distributed.rank != 0) return TrainAvatar(avatar, model, data, fit);  // rank 0 reports
  const TrainResult fit_result = TrainAvatar(avatar, model, data, fit, [&](const StepInfo& s) {
    if (!progress) {  // the first step of this run (not 0 after a resume)
      progress.emplace(s.step, fit.iterations);
      if (!out.log_csv.empty()) loss_log = CsvLog(out.log_csv, "step,loss,mse,synthetic", fit.resume, s.step);
      if (!out.eval_csv.empty()) eval_log = CsvLog(out.eval_csv, "step,psnr,ssim", fit.resume, s.step);
    }
    loss_log.Row(std::to_string(s.step) + "," + std::to_string(s.loss) + "," + std::to_string(s.mse) + "," +
                 std::to_string(s.synthetic));
    const bool last = s.step + 1 == fit.iterations;
    if (out.eval_every > 0 && ((s.step + 1) % out.eval_every == 0 || last)) {
      const EvalResult e = evaluate(avatar);
      last_psnr = e.psnr_mean;
      eval_log.Row(std::to_string(s.step + 1) + "," + std::to_string(e.psnr_mean) + "," + std::to_string(e.ssim_mean));
    }
    if (s.step % 10 == 0 || last) {
      char figures[96];
      int n = std::snprintf(figures, sizeof(figures), "loss %.5f  mse %.5f", s.loss, s.mse);
      if (!std::isnan(last_psnr))  // none before the first evaluation (or ever, without --eval-every)
        std::snprintf(figures + n, sizeof(figures) - n, "  test PSNR %.2f dB", last_psnr);
      progress->Show(s.step, figures);
    }
  });
  if (progress) progress->Finish();
  if (!out.plot_dir.empty()) {
    fs::create_directories(out.plot_dir);
    if (!out.log_csv.empty())
      WritePlot((fs::path(out.plot_dir) / "losses.png").string(), "training loss", "step", "loss",
                ReadCsvColumns(out.log_csv, {"loss", "mse"}), true);
    if (!out.eval_csv.empty() && out.eval_every > 0)
      WritePlot((fs::path(out.plot_dir) / "psnr.png").string(), "held-out PSNR", "step", "dB",
                ReadCsvColumns(out.eval_csv, {"psnr"}));
  }
  return fit_result;
}

nlohmann::json EvalJson(const EvalResult& e, const std::string& what) {
  return {{"psnr_db", e.psnr_mean},
          {"ssim", e.ssim_mean},
          {"frames", e.count},
          {"ms_per_image", e.ms_median},
          {"on", what}};
}

nlohmann::json FitJson(const FitOptions& f, const TrainResult& r, bool real) {
  nlohmann::json j = {
      {"iterations", f.iterations},
      {"batch", f.batch},
      {"learning_rate", f.learning_rate},
      {"final_lr_fraction", f.final_lr_fraction},
      {"warmup_steps", f.warmup_steps},
      {"surface_lr_scale", f.surface_lr_scale},
      {"blend_lr_scale", f.blend_lr_scale},
      {"blend_decay", f.blend_decay},
      {"offset_lr_scale", f.offset_lr_scale},
      {"offset_segment", f.offset_segment},
      {"identity_offsets", f.identity_offsets},
      {"weight_average", f.weight_average},
      {"region_weight", f.loss.regions.weight},
      {"seconds", r.seconds},
      {"samples_per_s", r.samples_per_s},
      {"first_step", r.first_step},
      {"final_loss", r.steps.empty() ? 0.f : r.steps.back().loss},
      {"perceptual_term", r.perceptual == "ssim" ? "1 - SSIM (no VGG16 file given; the substitute)" : r.perceptual},
      {"processes", f.distributed.world_size},
      {"threads_per_process", f.threads}};
  if (real) {  // only real frames are augmented and get offsets
    j["z_augmentation"] = f.z_augmentation;
    j["roll_augmentation"] = f.roll_augmentation;
    j["roll_max_degrees"] = f.roll_max_degrees;
    j["learned_offsets"] = f.learn_offsets;
    j["rare_expressions"] = f.rare_expressions.strength;
  }
  if (real && f.frame_shift_rate > 0)
    j["frame_shift"] = {{"rate_px", f.frame_shift_rate},
                        {"weight", f.loss.frame_shift_weight},
                        {"mean_px", {r.frame_shift_mean[0], r.frame_shift_mean[1]}},
                        {"rms_px_about_mean", r.frame_shift_rms}};
  if (real && r.exposure >= 0) j["motion_blur"] = {{"exposure_learnt", r.exposure}, {"rate", f.exposure_rate}};
  if (!r.mean_offset_geometry.empty()) {
    double square = 0;
    for (const std::vector<float>* m : {&r.mean_offset_geometry, &r.mean_offset_appearance})
      for (float v : *m) square += double{v} * v;
    j["offsets"] = {{"mean_norm", std::sqrt(square)}, {"rms_about_mean", r.offset_rms}};
  }
  return j;
}

void Finish(Avatar& avatar, const nlohmann::json& summary, const cv::Mat& preview, const RunOutputs& out) {
  avatar.training_summary() = summary;
  avatar.Save(out.out, preview);
  if (!out.preview.empty()) WriteImage(out.preview, preview);
  if (!out.report.empty()) std::ofstream(out.report) << summary.dump(2) << "\n";
}

cv::Mat Stack(const std::vector<cv::Mat>& rows) {
  cv::Mat sheet;
  cv::vconcat(rows, sheet);
  return sheet;
}

}  // namespace

void PretrainOptions::Check() const {
  OptionsCheck c("PretrainOptions");
  CheckRun(resolution, outputs, &c);
  for (size_t i = 0; i < real_datasets.size(); ++i)
    c.That(std::find(real_datasets.begin(), real_datasets.begin() + i, real_datasets[i]) == real_datasets.begin() + i,
           "real dataset " + real_datasets[i] + " is given twice");
  c.ThrowIfErrors();
  fit.Check();
}

namespace {

// The run-time switches of how CNeRF samples are placed and what they are
// told: the run's choice, whatever the avatar it starts from had.
void TakeSampleSwitches(const AvatarConfig& from, AvatarConfig* to) {
  to->canonical_samples = from.canonical_samples;
  to->rigid_margin = from.rigid_margin;
  to->covered_apart = from.covered_apart;
  to->motion_conditioning = from.motion_conditioning;
  to->hair_conditioning = from.hair_conditioning;
  to->hair_reach = from.hair_reach;
  to->view_rotation = from.view_rotation;
  to->motion_blur = from.motion_blur;
}

}  // namespace

nlohmann::json RunPretrain(PretrainOptions o) {
  o.Check();
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  o.config.output_size = o.resolution;  // CreateRandom fits the conditioning sizes to the model
  const SubjectParams base = DefaultSubject(model, o.resolution);
  Avatar avatar = [&] {
    if (o.init.empty()) return Avatar::CreateRandom(o.config, model, base, o.fit.seed);
    // Continued with its own networks, texture and matte (their sizes fitted
    // to the head model when it was made), at this resolution.
    const Avatar init = Avatar::Load(o.init, model);
    AvatarConfig c = init.config();
    c.output_size = o.resolution;
    TakeSampleSwitches(o.config, &c);
    c.ClearExpressionSpan();  // a person's span, bias and outline (an avatar as the start) are not a general model's
    c.ClearConditioningBias();
    c.matte_scale = 1;
    return init.WithRuntimeSwitches(c);
  }();
  o.synthetic.image_size = o.resolution;
  SyntheticData synthetic(model, o.synthetic, base, o.fit.seed + 100);
  std::vector<PreparedDataset> real;
  for (const std::string& dir : o.real_datasets) real.push_back(PreparedDataset::Load(dir, model, o.resolution));
  TrainingData data{&synthetic, {}};
  for (const PreparedDataset& d : real) data.real.push_back(&d);
  const int eval_frames = o.outputs.eval_frames;
  const TrainResult fitted = TrainWithReports(avatar, model, data, o.fit, o.outputs, [&](Avatar& a) {
    return EvaluateOnSynthetic(a, model, synthetic, eval_frames);
  });
  if (o.fit.distributed.rank != 0) return {{"rank", o.fit.distributed.rank}, {"written_by", "rank 0"}};
  const EvalResult eval = EvaluateOnSynthetic(avatar, model, synthetic, eval_frames);
  std::vector<cv::Mat> rows;
  for (int i = 0; i < 4; ++i) {
    const SyntheticSample s = synthetic.At((uint64_t{1} << 41) + i);  // neither training nor evaluation
    cv::Mat row;
    cv::hconcat(s.image_bgr, RenderAvatarBgr(avatar, model, s.subject, s.frame), row);
    rows.push_back(row);
  }
  nlohmann::json summary = {
      {"trained", true},
      {"stage", !real.empty() ? "pretrain (synthetic renders mixed with real frames, METHOD eq. 9)"
                              : "pretrain (synthetic renders of the head model)"},
      {"head_model", model.data().name},
      {"resolution", o.resolution},
      {"fit", FitJson(o.fit, fitted, !real.empty())},
      {"eval", EvalJson(eval, "held-out synthetic renders")}};
  nlohmann::json train_frames = nlohmann::json::array();  // per dataset
  for (const PreparedDataset& d : real) train_frames.push_back(d.train().size());
  if (!real.empty())
    summary["mix"] = {{"datasets", o.real_datasets}, {"train_frames", train_frames}, {"m", o.fit.mix.m},
                      {"n", o.fit.mix.n_end},        {"p_min", o.fit.mix.p_min},     {"p_max", o.fit.mix.p_max}};
  Finish(avatar, summary, Stack(rows), o.outputs);
  return summary;
}

namespace {

// The surface texture's settings (a subject's own, added to a general model).
void CopySurfaceTexture(const AvatarConfig& from, AvatarConfig* to) {
  to->surface_features = from.surface_features;
  to->surface_resolution = from.surface_resolution;
  to->surface_extent = from.surface_extent;
  to->surface_shell = from.surface_shell;
  to->surface_rigid = from.surface_rigid;
  to->surface_displacement = from.surface_displacement;
  to->surface_eye_symmetry = from.surface_eye_symmetry;
  to->surface_blend = from.surface_blend;
  to->surface_blend_components = from.surface_blend_components;
  to->surface_conditioned = from.surface_conditioned;
  to->surface_hidden = from.surface_hidden;
  to->surface_levels = from.surface_levels;
}

// The avatar with AvatarConfig::expression_low/high set to each coefficient's
// smallest and largest value over the dataset's training frames (resized to
// the avatar's count as the conditioning takes them); without a dataset, with
// no span.
Avatar WithExpressionSpan(const Avatar& avatar, const PreparedDataset* data) {
  AvatarConfig c = avatar.config();
  c.ClearExpressionSpan();
  if (data) {
    const float inf = std::numeric_limits<float>::infinity();
    Eigen::VectorXf low = Eigen::VectorXf::Constant(c.num_expression, inf), high = -low;
    for (int i : data->train()) {
      const Eigen::VectorXf e = Resized(data->params(i).expression, c.num_expression);
      low = low.cwiseMin(e);
      high = high.cwiseMax(e);
    }
    c.expression_low.assign(low.data(), low.data() + low.size());
    c.expression_high.assign(high.data(), high.data() + high.size());
  }
  return avatar.WithRuntimeSwitches(c);
}

// The avatar drawn with its coverage logit scaled by `scale` (AvatarConfig::matte_scale).
Avatar WithMatteScale(const Avatar& avatar, double scale) {
  AvatarConfig c = avatar.config();
  c.matte_scale = scale;
  return avatar.WithRuntimeSwitches(c);
}

// The avatar with the mean of the offsets its fit learnt (`fitted` has
// them) added to its conditioning bias (AvatarConfig::bias_geometry/appearance).
Avatar WithMeanOffset(const Avatar& avatar, const TrainResult& fitted) {
  AvatarConfig c = avatar.config();
  if (!c.has_conditioning_bias()) {
    c.bias_geometry.assign(c.conditioning_dim(), 0.f);
    c.bias_appearance.assign(c.appearance_dim(), 0.f);
  }
  for (size_t i = 0; i < c.bias_geometry.size(); ++i) c.bias_geometry[i] += fitted.mean_offset_geometry.at(i);
  for (size_t i = 0; i < c.bias_appearance.size(); ++i) c.bias_appearance[i] += fitted.mean_offset_appearance.at(i);
  return avatar.WithRuntimeSwitches(c);
}

}  // namespace

FitOptions SubjectFitDefaults() {
  FitOptions f;
  f.loss.regions.weight = 4;
  f.learning_rate = 4e-3;  // twice pretraining's; a fine-tune at this rate diverges without the warm-up
  f.warmup_steps = 200;
  // The default blendshapes (kSubjectSurfaceBlend) undecayed overfit a clip
  // whose frames vary along few directions; held back they gain on every clip
  // (bench/results/fidelity_ablation.md).
  f.blend_decay = 0.5;
  return f;
}

void SubjectOptions::Check() const {
  OptionsCheck c("SubjectOptions");
  c.That(general.empty() == from_scratch, "give a general model, or from_scratch (not both)");
  c.That(!dataset.empty(), "dataset is required");
  c.InRange("synthetic_start", synthetic_start, 0.0, 1.0).InRange("freeze_layers", freeze_layers, 0, 64);
  c.InRange("hair_margin", hair_margin, -1, 64);
  c.That(config.has_matte() || matte_scale == kSubjectMatteScale, "matte_scale needs a matte (not with matte none)");
  c.That(!expression_span_in_training || expression_span,
         "expression_span_in_training needs the span kept (not with --no-expression-span)");
  CheckRun(resolution, outputs, &c);
  c.ThrowIfErrors();
  fit.Check();
  // The texture's options and the matte's scale are the subject's own (added
  // to the general model): the same rules as a whole configuration's
  // (surface_conditioned needs a texture, the scale's range, ...), checked
  // before training rather than when the file is written after it.
  AvatarConfig own = AvatarConfig::Default(resolution);
  CopySurfaceTexture(config, &own);
  own.matte_scale = matte_scale;
  own.motion_blur = config.motion_blur;
  own.Check();
}

nlohmann::json RunSubject(SubjectOptions o) {
  o.Check();
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  const PreparedDataset data = PreparedDataset::Load(o.dataset, model, o.resolution, o.use_interpolated);
  if (data.test().empty()) spdlog::warn("{}: no test frames; figures are on training frames", o.dataset);
  SubjectParams subject = data.subject();
  std::string identity = "the dataset's (" + data.manifest().value("identity", std::string("?")) + ")";
  if (!o.identity_from.empty()) {
    subject.shape = ReadTrackingIdentity(o.identity_from, model).cast<float>();
    const bool avatar = fs::path(o.identity_from).extension() == ".hcavatar";
    identity = (avatar ? "the avatar " : "headcast-fit-mesh ") + o.identity_from;
  }
  subject.texture = Resized(subject.texture, model.num_texture());
  o.config.matte_rules = data.matte_rules();  // a bounded matte keeps to what its targets were cut by
  Avatar avatar = [&] {
    if (o.from_scratch) {
      o.config.output_size = o.resolution;
      if (o.hair_margin >= 0) o.config.hair_margin_px = o.hair_margin;
      return Avatar::CreateRandom(o.config, model, subject, o.fit.seed);
    }
    Avatar general = Avatar::Load(o.general, model);
    AvatarConfig c = general.config();
    c.output_size = o.resolution;
    TakeSampleSwitches(o.config, &c);  // the subject's choice, whatever the general model's
    if (o.hair_margin >= 0) c.hair_margin_px = o.hair_margin;
    if (o.config.has_surface()) {  // the subject's own texture, added to a general model without one
      CopySurfaceTexture(o.config, &c);
    }
    c.matte = o.config.matte;
    c.matte_rules = o.config.matte_rules;
    c.matte_core = o.config.matte_core;
    c.matte_scale = 1;        // training draws the outline as the networks learn it
    c.ClearExpressionSpan();  // another subject's, if the start is an avatar
    c.ClearConditioningBias();
    return general.WithRuntimeSwitches(c);
  }();
  if (o.expression_span_in_training) avatar = WithExpressionSpan(avatar, &data);
  if (const double explained = SetBlendDirections(avatar, data); explained > 0 && o.fit.distributed.rank == 0)
    spdlog::info(
        "the texture's blendshapes follow the training frames' first {} expression directions ({:.1f} % of "
        "their variance)",
        avatar.config().surface_blend_components, 100 * explained);
  avatar.mutable_subject() = subject;
  if (const std::optional<CameraContract> contract = data.camera_contract()) avatar.set_camera_contract(*contract);
  if (const std::optional<AnchorReference> anchor = data.anchor_reference())
    avatar.set_tracking_anchor(anchor->ToJson());
  avatar.set_tracking_fit(data.expression_fit().ToJson());
  // The subject's own renders, decaying to none (METHOD §6): beta and tau stay the subject's.
  SyntheticDataOptions synthetic_options;
  synthetic_options.image_size = o.resolution;
  synthetic_options.vary_identity = false;
  synthetic_options.neck_x_deg = synthetic_options.neck_y_deg = synthetic_options.neck_z_deg = 25;
  SyntheticData synthetic(model, synthetic_options, subject, o.fit.seed + 200);
  FitOptions fit = o.fit;
  fit.freeze_identity = true;
  fit.freeze_cnerf_layers = o.from_scratch ? 0 : o.freeze_layers;
  fit.mix = MixSchedule{0, std::max(1, fit.iterations), 0.0, o.synthetic_start};
  const TrainingData training{o.synthetic_start > 0 ? &synthetic : nullptr, {&data}};
  std::vector<int> eval_positions = data.test().empty() ? data.train() : data.test();
  std::vector<int> periodic = eval_positions;
  if (static_cast<int>(periodic.size()) > o.outputs.eval_frames) {
    // Spread over the split, for the curve; the final figure uses every frame.
    std::vector<int> spread;
    for (int k = 0; k < o.outputs.eval_frames; ++k)
      spread.push_back(periodic[static_cast<size_t>(k) * periodic.size() / o.outputs.eval_frames]);
    periodic = spread;
  }
  const TrainResult fitted = TrainWithReports(avatar, model, training, fit, o.outputs,
                                              [&](Avatar& a) { return EvaluateOnDataset(a, model, data, periodic); });
  if (fit.distributed.rank != 0) return {{"rank", fit.distributed.rank}, {"written_by", "rank 0"}};
  // Set after training by default: what the networks learnt is unchanged by it.
  if (o.expression_span && !o.expression_span_in_training) avatar = WithExpressionSpan(avatar, &data);
  if (o.mean_offset && !fitted.mean_offset_geometry.empty()) avatar = WithMeanOffset(avatar, fitted);
  if (avatar.config().has_matte()) avatar = WithMatteScale(avatar, o.matte_scale);
  const EvalResult eval = EvaluateOnDataset(avatar, model, data, eval_positions);
  std::vector<cv::Mat> rows;
  for (int k = 0; k < 4; ++k) {
    const int i = eval_positions[static_cast<size_t>(k) * eval_positions.size() / 4];
    const RealSample& s = data.At(i);
    cv::Mat row;
    cv::hconcat(MaskedTarget(s.image_bgr, s.mask), RenderAvatarBgr(avatar, model, subject, s.params), row);
    rows.push_back(row);
  }
  const nlohmann::json summary = {
      {"trained", true},
      {"stage", o.from_scratch ? "subject, from random networks" : "subject fine-tune of " + o.general},
      {"head_model", model.data().name},
      {"resolution", o.resolution},
      {"dataset", o.dataset},
      {"identity", identity},
      {"frozen", {{"beta_tau", true}, {"cnerf_layers", fit.freeze_cnerf_layers}}},
      {"synthetic_mix",
       {{"start", o.synthetic_start},
        {"end", 0},
        {"decay", "linear over the iterations"},
        {"face_regions", fit.loss.blind_synthetic_face ? "not learned from them" : "learned from them"}}},
      {"expression_span", !o.expression_span ? "none"
                          : o.expression_span_in_training
                              ? "the training frames', from the first step (the synthetic renders' held within it)"
                              : "the training frames' (the networks told no expression beyond it)"},
      {"train_frames", data.train().size() - data.interpolated()},
      {"interpolated_frames", data.interpolated()},
      {"matte_scale", avatar.config().has_matte() ? nlohmann::json(avatar.config().matte_scale) : nullptr},
      {"fit", FitJson(fit, fitted, true)},
      {"eval", EvalJson(eval, data.test().empty() ? "training frames (no test split)"
                                                  : "test split: the last frames, never trained on")}};
  Finish(avatar, summary, Stack(rows), o.outputs);
  return summary;
}

namespace {
// What eval.json says of the frames' skin colours (FrameParams::skin_colour).
std::string SkinColourUse(const PreparedDataset& data, const std::vector<int>& positions, bool matched) {
  int carried = 0;
  for (int i : positions) carried += data.At(i).params.skin_colour.has_value();
  if (carried == 0) return "the avatar's own colours (the dataset's frames carry no skin colour)";
  const std::string of = std::to_string(carried) + " of " + std::to_string(positions.size()) + " frames";
  return matched ? "matched to the frames' skin colours (" + of + " carry one)"
                 : "the avatar's own colours (--no-skin-colour; " + of + " carry one)";
}
}  // namespace

void EvalOptions::Check() const {
  OptionsCheck c("EvalOptions");
  c.That(!avatar.empty(), "avatar is required").That(!dataset.empty(), "dataset is required");
  c.That(!out_dir.empty(), "out_dir is required").NonNegative("max_frames", max_frames);
  c.InRange("orbit_frames", orbit_frames, 0, 10000).InRange("orbit_deg", orbit_deg, 0.0, 90.0);
  c.That(split == "test" || split == "train", "split must be test or train, not '" + split + "'");
  c.That(expression_span == "avatar" || expression_span == "none" || expression_span == "dataset",
         "expression_span must be avatar, none or dataset, not '" + expression_span + "'");
  c.That(motion_blur == -1 || (motion_blur >= 0 && motion_blur <= 2),
         "motion_blur must be -1 (the avatar's) or an exposure of 0 to 2 frame intervals");
  c.InRange("outline_bins", outline_bins, 0, kMaxOutlineBins).InRange("outline_every", outline_every, 1, 1000);
  c.That(outline_ramp == -1 || (outline_ramp >= 0 && outline_ramp <= 0.5),
         "outline_ramp must be -1 (the avatar's) or a share of the picture's height of 0 to 0.5");
  c.InRange("outline_centre_y", outline_centre_y, -0.2, 0.2);
  c.That(outline_matte_scale == 0 || (outline_matte_scale >= 0.05 && outline_matte_scale <= 4),
         "outline_matte_scale must be 0 (the avatar's) or a scale of 0.05 to 4");
  c.ThrowIfErrors();
  if (matte_scale != 0) {  // 0: the avatar's; any other, a scale an avatar may carry
    AvatarConfig scaled = AvatarConfig::Default();
    scaled.matte_scale = matte_scale;
    scaled.Check();
  }
}

nlohmann::json RunEval(const EvalOptions& o) {
  o.Check();
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  Avatar avatar = Avatar::Load(o.avatar, model);
  const PreparedDataset data =
      PreparedDataset::Load(o.dataset, model, avatar.config().output_size, /*interpolated=*/false);
  if (o.expression_span != "avatar")
    avatar = WithExpressionSpan(avatar, o.expression_span == "dataset" ? &data : nullptr);
  if (o.matte_scale > 0) {
    if (!avatar.config().has_matte()) throw std::invalid_argument(o.avatar + " has no matte to scale (matte_scale)");
    avatar = WithMatteScale(avatar, o.matte_scale);
  }
  if (o.motion_blur >= 0 || o.outline_ramp >= 0 || o.outline_matte_scale > 0 || o.outline_bins > 0) {
    AvatarConfig c = avatar.config();
    if (o.motion_blur >= 0) c.motion_blur = o.motion_blur;
    if (o.outline_ramp >= 0) c.outline_ramp = o.outline_ramp;
    if (o.outline_matte_scale > 0) c.outline_matte_scale = o.outline_matte_scale;
    if (o.outline_bins > 0) c.outline_centre_y = o.outline_centre_y;
    avatar = avatar.WithRuntimeSwitches(c);
  }
  std::optional<OutlineOptions> outline;
  if (o.outline_bins > 0) {
    outline.emplace();
    outline->bins = o.outline_bins;
    outline->centre_y_m = o.outline_centre_y;
  }
  const bool on_test = o.split == "test" && !data.test().empty();
  std::vector<int> positions = on_test ? data.test() : data.train();
  if (o.max_frames > 0 && static_cast<int>(positions.size()) > o.max_frames) {
    if (on_test) {
      positions.resize(o.max_frames);  // the first of the held-out frames, as always
    } else {
      std::vector<int> spread(o.max_frames);  // across the whole training span
      for (int k = 0; k < o.max_frames; ++k) spread[k] = positions[k * positions.size() / o.max_frames];
      positions = spread;
    }
  }
  fs::create_directories(o.out_dir);
  const fs::path dir = o.out_dir;
  const SubjectParams& subject = avatar.subject();
  // The head model as the tracker saw it, for the third panel.
  HeadRenderOptions render_options;
  std::copy(subject.light.begin(), subject.light.end(), render_options.light.begin());
  const cv::Mat albedo = AlbedoTexture(model, subject.texture.cast<double>());
  const HeadIdentity identity = model.MakeIdentity(subject.shape.cast<double>());
  auto posed_head = [&](const FrameParams& f) {
    HeadModelOutput posed;
    model.Forward(identity, Resized(f.expression, model.num_expression()).cast<double>(), f.HeadPose(), &posed);
    return posed;
  };
  auto head_model_view = [&](const FrameParams& f, const HeadModelOutput& posed) {
    return RenderHead(model, posed.vertices, f.CamFromHead(), subject.intrinsics, albedo, render_options).image_bgr;
  };
  const double fps = 30;
  int written = 0;
  if (o.write_frames) fs::create_directories(dir / "frames");
  std::ofstream csv(dir / "per_frame.csv");
  csv << "frame,psnr,ssim\n";
  std::unique_ptr<LandmarkAgreement> agreement;
  nlohmann::json fidelity = "not computed (--no-landmarks)";
  if (o.landmarks && fs::exists(o.landmark_predictor))
    agreement = std::make_unique<LandmarkAgreement>(o.landmark_predictor);
  else if (o.landmarks)
    fidelity = "not computed: no dlib shape predictor at " + o.landmark_predictor;
  {
    VideoWriter side((dir / "side_by_side.mp4").string(), fps);
    ProgressLine progress(0, static_cast<int>(positions.size()), 10, "frame");
    int done = 0;
    TemporalAgreement temporal;
    const EvalResult e = EvaluateOnDataset(
        avatar, model, data, positions,
        [&](int i, const cv::Mat& truth, const cv::Mat& rendered) {
          progress.Show(done++, "evaluating");
          const FrameParams& params = data.At(i).params;
          const HeadModelOutput posed = posed_head(params);
          cv::Mat row;
          cv::hconcat(std::vector<cv::Mat>{truth, rendered, head_model_view(params, posed)}, row);
          side.Write(row);
          if (agreement) {
            const Landmarks2d fitted = ProjectLandmarks(posed, params.CamFromHead(), subject.intrinsics);
            agreement->Add(truth, rendered, &fitted);
          }
          temporal.Add(data.At(i).frame, truth, rendered);
          if (o.write_frames) {
            char name[32];
            std::snprintf(name, sizeof(name), "_%05d.png", written++);
            WriteImage((dir / "frames" / ("truth" + std::string(name))).string(), truth);
            WriteImage((dir / "frames" / ("avatar" + std::string(name))).string(), rendered);
          }
        },
        o.skin_colour, outline ? &*outline : nullptr, o.outline_every);
    progress.Finish();
    for (int k = 0; k < e.count; ++k)
      csv << data.At(positions[k]).frame << "," << e.psnr[k] << "," << e.ssim[k] << "\n";
    nlohmann::json report = {
        {"avatar", o.avatar},
        {"dataset", o.dataset},
        {"resolution", avatar.config().output_size},
        {"eval", EvalJson(e, on_test ? "test split" : "training frames")},
        {"ground_truth", "frames with their background replaced by the renders' colour (head mask)"},
        {"skin_colour", SkinColourUse(data, positions, o.skin_colour)},
        {"expression_span", !avatar.config().has_expression_span() ? "none: the networks told each frame's expression"
                            : o.expression_span == "dataset"
                                ? "the dataset's training frames' (the networks told no expression beyond it)"
                                : "the avatar's (the networks told no expression beyond it)"},
        {"matte_scale", !avatar.config().has_matte()
                            ? nlohmann::json(nullptr)
                            : nlohmann::json{{"value", avatar.config().matte_scale},
                                             {"from", o.matte_scale > 0 ? "--matte-scale" : "the avatar"}}},
        {"motion_blur", nlohmann::json{{"exposure", avatar.config().motion_blur},
                                       {"from", o.motion_blur >= 0 ? "--motion-blur" : "the avatar"}}},
        {"outline", !outline
                        ? nlohmann::json("none: the frames carry no outline")
                        : nlohmann::json{{"bins", outline->bins},
                                         {"measured_every", o.outline_every},
                                         {"centre_y_m", outline->centre_y_m},
                                         {"ramp", avatar.config().outline_ramp},
                                         {"matte_scale", avatar.config().outline_matte_scale},
                                         {"how",
                                          "each frame carries the top of its mask's outline, as the sender "
                                          "measures it on its frame's mask; the avatar's outline is moved there"}}},
        {"lpips", "not computed (needs LPIPS weights, which cannot be downloaded here)"},
        {"expression_fidelity",
         agreement ? nlohmann::json{{"how",
                                     "dlib's 68 landmarks on the avatar's frames against the true frames', mean "
                                     "distance over the true eye distance per region; blink: correlation of the "
                                     "eye opening; gaze: the iris in its eye's frame (eye widths), correlation "
                                     "and mean distance; fit: each picture's points against the fitted head's "
                                     "landmarks projected (where the fit or the avatar lost an expression)"},
                                    {"result", agreement->Summary()}}
                   : fidelity},
        {"temporal", temporal.Summary()},
        {"videos", {"side_by_side.mp4: ground truth | avatar | head model"}}};
    // Novel views: the first evaluated frame, the head turned on its vertical axis.
    const FrameParams base = data.At(positions.front()).params;
    if (o.orbit_frames > 0) {
      VideoWriter orbit((dir / "orbit.mp4").string(), fps);
      const RigidTransform cam_from_head = base.CamFromHead();
      for (int k = 0; k < o.orbit_frames; ++k) {
        const double yaw = o.orbit_deg * M_PI / 180 * std::sin(2 * M_PI * k / o.orbit_frames);
        FrameParams f = base;
        f.SetCamFromHead({cam_from_head.rotation * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).matrix(),
                          cam_from_head.translation});
        orbit.Write(RenderAvatarBgr(avatar, model, subject, f));
      }
      report["videos"].push_back("orbit.mp4: novel views, yaw +-" + std::to_string(o.orbit_deg) + " degrees");
    }
    // Expression transfer: another recording's expressions and jaw on this avatar, its pose kept.
    if (!o.drive.empty()) {
      RecordingInfo info;
      const std::vector<FrameParams> drive = ReadRecording(o.drive, &info);
      if (info.head_model_fingerprint != model.fingerprint())
        throw std::runtime_error(o.drive + ": recorded for head model " + info.head_model_name + ", not " +
                                 model.data().name);
      VideoWriter transfer((dir / "transfer.mp4").string(), fps);
      for (const FrameParams& d : drive) {
        FrameParams f = base;
        f.expression = d.expression;
        f.jaw = d.jaw;
        cv::Mat row;
        cv::hconcat(head_model_view(f, posed_head(f)), RenderAvatarBgr(avatar, model, subject, f), row);
        transfer.Write(row);
      }
      report["videos"].push_back("transfer.mp4: " + o.drive + "'s expressions (head model | avatar)");
    }
    std::ofstream(dir / "eval.json") << report.dump(2) << "\n";
    return report;
  }
}

}  // namespace headcast
