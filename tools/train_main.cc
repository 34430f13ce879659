// headcast-train: builds avatars.
//   prep      video -> head crops, masks, per-frame parameters (the sender's tracker), split
//   pretrain  the general model on synthetic renders (optionally mixed with real frames)
//   subject   a person's avatar, fine-tuned from the general model
//   eval      PSNR/SSIM on the test split, side-by-side, orbit and transfer videos
//   plot      CSV logs of several runs in one picture
//   create    all of it in one command: video, image folder or camera -> avatar
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "common/capture/capture_flags.h"
#include "common/core/camera.h"
#include "common/core/cli_flags.h"
#include "common/core/local_ranks.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"
#include "common/tracking/offline_tracker.h"
#include "receiver/display/display.h"
#include "training/create.h"
#include "training/run_report.h"
#include "training/runs.h"
#include "training/session_compare.h"

namespace {

using namespace headcast;

// Flags every training subcommand has: optimiser, loss, checkpoints, outputs.
void AddTrainingFlags(CLI::App* app, FitOptions* fit, RunOutputs* out, int* processes) {
  app->add_option("--iterations", fit->iterations, "optimiser steps")->capture_default_str();
  app->add_option("--batch", fit->batch, "samples per step")->capture_default_str();
  app->add_option("--lr", fit->learning_rate, "Adam learning rate at the first step")->capture_default_str();
  app->add_option("--final-lr", fit->final_lr_fraction,
                  "learning rate at the last step as a fraction of --lr (exponential fall; 1 = constant)")
      ->capture_default_str();
  app->add_option("--warmup", fit->warmup_steps,
                  "the rate rises linearly to --lr over this many first steps (0: from the first step)")
      ->capture_default_str();
  app->add_option("--weight-average", fit->weight_average,
                  "keep and save a moving average of the weights with this decay per step (0 = off; "
                  "pretrain's default 0, subject's 1 - 8/iterations, at most 0.999)");
  app->add_option("--seed", fit->seed, "random seed");
  app->add_option("--vgg", fit->loss.vgg_path,
                  "VGG16 TorchScript file for the perceptual term (else 1 - SSIM stands in for it)");
  app->add_option("--perceptual-weight", fit->loss.perceptual_weight, "weight of the VGG16 term")
      ->capture_default_str();
  app->add_option("--ssim-weight", fit->loss.ssim_weight, "weight of 1 - SSIM (without --vgg)")->capture_default_str();
  app->add_option(
         "--region-weight", fit->loss.regions.weight,
         "the MSE weighs 1 + this around the fitted eyes with their brows and the mouth (0: every pixel alike)")
      ->capture_default_str();
  app->add_option("--expression-noise", fit->expression_noise,
                  "standard deviation of noise added to real frames' expression coefficients as the networks see "
                  "them (not the mesh; 0: off)")
      ->capture_default_str();
  app->add_option("--anchor-weight", fit->anchor_weight,
                  "pull of the networks' weights toward those training started from (the general model), per "
                  "step x learning rate (0: off)")
      ->capture_default_str();
  app->add_option("--offset-weight", fit->loss.offset_weight, "weight of the per-frame offsets' squared norm")
      ->capture_default_str();
  app->add_flag("!--no-offsets", fit->learn_offsets, "no learnable per-frame offsets on real frames");
  app->add_flag("--identity-offsets", fit->identity_offsets,
                "per-frame offsets on beta as the networks are told it, in a fine-tune too (the mesh keeps the "
                "subject's)");
  app->add_option("--offset-lr", fit->offset_lr_scale, "the per-frame offsets' learning rate as a multiple of --lr")
      ->capture_default_str();
  app->add_option("--offset-segment", fit->offset_segment,
                  "consecutive training frames sharing one offset (and one shift), for a slow drift of the picture "
                  "against the fit (1: one per frame)")
      ->capture_default_str();
  app->add_option("--exposure-rate", fit->exposure_rate,
                  "with --motion-blur: the rate at which the camera's exposure is learnt from the value given "
                  "(frame intervals a step; 0: kept)")
      ->capture_default_str();
  app->add_option("--frame-shift-rate", fit->frame_shift_rate,
                  "each real training frame's picture moved by a learnt shift of its own before the loss, at this "
                  "rate in pixels a step (0: off; the receiver draws with none)")
      ->capture_default_str();
  app->add_option("--frame-shift-weight", fit->loss.frame_shift_weight,
                  "weight of a frame shift's squared length (pixels)")
      ->capture_default_str();
  app->add_option("--rare-expressions", fit->rare_expressions.strength,
                  "real frames drawn by how rare their expression is, weight (isolation / median)^S (0: uniformly)")
      ->capture_default_str();
  app->add_option("--z-augmentation", fit->z_augmentation, "probability of the distance augmentation on real frames")
      ->capture_default_str();
  app->add_option("--roll-augmentation", fit->roll_augmentation,
                  "probability of turning a real frame's camera about its optical axis")
      ->capture_default_str();
  app->add_option("--roll-max-degrees", fit->roll_max_degrees, "largest turn of the roll augmentation")
      ->capture_default_str();
  app->add_option("--checkpoint-dir", fit->checkpoint_dir,
                  "checkpoint here (atomically) every --checkpoint-every steps");
  app->add_option("--checkpoint-every", fit->checkpoint_every, "steps between checkpoints")->capture_default_str();
  app->add_flag("--resume", fit->resume, "continue from the latest checkpoint in --checkpoint-dir, if any");
  app->add_option("--processes", *processes,
                  "data parallel on this machine: start this many processes of one thread each (2 on 2 cores "
                  "trains ~2x faster than 1)")
      ->check(CLI::Range(1, 64))
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->capture_default_str();
  app->add_option("--threads", fit->threads, "libtorch threads of this process (0: libtorch's choice)")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->capture_default_str();
  app->add_option("--rank", fit->distributed.rank, "data parallel: this process's rank (0 writes the outputs)");
  app->add_option("--world-size", fit->distributed.world_size, "data parallel: processes in all")
      ->capture_default_str();
  app->add_option("--master-addr", fit->distributed.master_addr, "data parallel: rank 0's address")
      ->capture_default_str();
  app->add_option("--master-port", fit->distributed.master_port, "data parallel: rank 0's TCP store port")
      ->capture_default_str();
  app->add_option("--out", out->out, "output .hcavatar")->required();
  app->add_option("--log-csv", out->log_csv, "loss per step (CSV)");
  app->add_option("--eval-csv", out->eval_csv, "held-out PSNR/SSIM every --eval-every steps (CSV)");
  app->add_option("--eval-every", out->eval_every, "steps between held-out evaluations (0: at the end only)");
  app->add_option("--eval", out->eval_frames, "held-out samples per evaluation")->capture_default_str();
  app->add_option("--plots", out->plot_dir, "write losses.png (and psnr.png) here");
  app->add_option("--preview", out->preview, "ground truth | avatar for 4 held-out samples (PNG)");
  AddJsonFlag(*app, &out->report, "the training report", {"--report"});
}

// The network's size, for a new avatar (a fine-tune keeps its general model's).
// Checked with the rest of the configuration (AvatarConfig::Check). Returns
// the options, so that a fine-tune can refuse them.
std::vector<CLI::Option*> AddArchitectureFlags(CLI::App* app, AvatarConfig* config, const std::string& when) {
  return {
      app->add_option("--expressions", config->num_expression,
                      when + "at most this many expression components condition the avatar (fewer if the model has "
                             "fewer)")
          ->capture_default_str(),
      app->add_option("--mlp-width", config->mlp_width, when + "CNeRF hidden width")->capture_default_str(),
      app->add_option("--mlp-layers", config->mlp_layers, when + "CNeRF layers before the density head")
          ->capture_default_str(),
      app->add_option_function<std::vector<int>>(
             "--renderer-channels",
             [config](const std::vector<int>& ch) {
               config->renderer_channels = ch;
               if (!ch.empty()) config->feature_channels = ch[0];  // the feature map enters the renderer
             },
             when +
                 "2D renderer: feature channels, then the channels out of each x2 level (4 values, e.g. 48,24,12,8: a "
                 "feature map of output/8; 3 values, e.g. 48,24,8: two levels and a feature map of output/4)")
          ->delimiter(','),
      app->add_option("--samples-per-ray", config->samples_per_ray, when + "CNeRF samples per ray")
          ->capture_default_str(),
  };
}

// The surface texture (METHOD's baseline has none): for a new avatar, or
// added to a general model without one in a fine-tune.
// A MotionConditioning option: full, no_expression or neck.
void AddMotionConditioning(CLI::App* app, const std::string& name, MotionConditioning* mode, const std::string& help) {
  app->add_option_function<std::string>(
         name, [mode](const std::string& value) { *mode = ParseMotionConditioning(value); }, help)
      ->default_str(MotionConditioningName(*mode))
      ->check(CLI::IsMember({"full", "no_expression", "neck"}));
}

void AddSurfaceFlags(CLI::App* app, AvatarConfig* config, FitOptions* fit) {
  app->add_option("--surface-features", config->surface_features,
                  "channels of the learned texture on the head model's surface (0: none, the thesis's avatar)")
      ->capture_default_str();
  app->add_option("--surface-resolution", config->surface_resolution, "texels along each of its three planes")
      ->capture_default_str();
  app->add_option("--surface-extent", config->surface_extent, "metres from the model's origin to a plane's edge")
      ->capture_default_str();
  app->add_option("--surface-shell", config->surface_shell,
                  "metres: the texture also covers the pixels just beyond the mesh, looked up on the mesh inflated "
                  "by this much (hair, the outline; 0: the mesh only)")
      ->capture_default_str();
  app->add_flag("--surface-rigid,!--no-surface-rigid", config->surface_rigid,
                "a second texture looked up at the posed surface point in the head frame, beside the canonical one "
                "(what moves with the head but not with the skin under it: glasses, hair over the face)");
  app->add_flag("--surface-displacement,!--no-surface-displacement", config->surface_displacement,
                "the surface branch told, per pixel, how far the expression moved the skin there (the posed surface "
                "point less the canonical one), beside the texture");
  app->add_flag("--surface-eye-symmetry,!--no-surface-eye-symmetry", config->surface_eye_symmetry,
                "the texture looked up on the eyeballs by the angle from their pole alone, so that the sclera seen "
                "beside the iris is drawn above and below it too");
  app->add_option("--surface-blend", config->surface_blend,
                  "texels along an edge of the texture's expression blendshapes: planes per expression coefficient, "
                  "weighted by the frame's (detail at its place on the face that grows with the expression; 0: none)")
      ->capture_default_str();
  app->add_flag("--surface-conditioned,!--no-surface-conditioned", config->surface_conditioned,
                "the texture's branch is scaled and shifted per frame by the pose and expression (detail that comes "
                "and goes with the expression: wrinkles, creases)");
  app->add_option("--surface-hidden", config->surface_hidden,
                  "hidden channels of the texture's per-pixel branch (0: twice --surface-features)")
      ->capture_default_str();
  app->add_option("--surface-levels", config->surface_levels,
                  "the renderer's x2 levels the texture joins, counted from the last (1: the last only; 2: averaged "
                  "into the level before too, where a 3x3 layer sees it)")
      ->capture_default_str();
  app->add_option("--surface-lr", fit->surface_lr_scale, "the texture's learning rate as a multiple of --lr")
      ->capture_default_str();
  app->add_option("--surface-blend-components", config->surface_blend_components,
                  "with --surface-blend: one set of planes per principal direction of the training frames' "
                  "expressions, the first N (0: one per coefficient)")
      ->capture_default_str();
  app->add_option("--surface-blend-lr", fit->blend_lr_scale,
                  "the texture's expression blendshapes' learning rate as a multiple of --lr")
      ->capture_default_str();
  app->add_option("--surface-blend-decay", fit->blend_decay,
                  "decoupled weight decay of the texture's expression blendshapes (each step shrinks them by their "
                  "rate times this; 0: off)")
      ->capture_default_str();
  app->add_flag("--canonical-samples,!--no-canonical-samples", config->canonical_samples,
                "move CNeRF samples into the neutral head through the posed triangle under their ray "
                "(the mesh carries the motion; off: rigid head frame, the thesis's avatar)");
  app->add_flag("--rigid-margin,!--no-rigid-margin", config->rigid_margin,
                "with canonical samples: the rays beside the silhouette (the hair beyond the head) stay rigid with "
                "the skull instead of following the nearest triangle, which a raised brow or a moved jaw stretches");
  app->add_flag("--covered-apart,!--no-covered-apart", config->covered_apart,
                "with canonical samples: the parts the neutral head covers (the mouth's inside, the eyeballs under "
                "the lids) looked up at a place of their own, not just behind the lips and lids");
  AddMotionConditioning(app, "--motion-conditioning", &config->motion_conditioning,
                        "what of each frame's motion the networks are told: full (neck, jaw, eyes, expression; the "
                        "thesis's avatar), no_expression (the expression coefficients left out) or neck (the neck's "
                        "rotation only); the posed mesh carries all of it in every mode");
  AddMotionConditioning(app, "--hair-conditioning", &config->hair_conditioning,
                        "what the CNeRF samples of the hair (over skin no expression moves, and beside it) are told "
                        "of each frame's motion: full (as every sample), no_expression or neck; told less, the hair "
                        "follows the skull");
  app->add_flag("--view-rotation,!--no-view-rotation", config->view_rotation,
                "tell the networks the head's rotation as the camera sees it (in the neck's place): how it is "
                "turned to the camera and the light");
  app->add_option("--motion-blur", config->motion_blur,
                  "the camera's exposure in frame intervals: each real frame is drawn smeared along the head's "
                  "image motion since the frame before over that much of it, in training and in a call (0: sharp)")
      ->capture_default_str();
  app->add_option("--hair-reach", config->hair_reach,
                  "metres per unit of an expression coefficient below which a face counts as the hair's "
                  "(--hair-conditioning)")
      ->capture_default_str();
}

// The outline: coverage predicted beside the RGB, bounded or not by the dataset's mask rules.
void AddMatteFlags(CLI::App* app, AvatarConfig* config, FitOptions* fit) {
  app->add_option_function<std::string>(
         "--matte", [config](const std::string& name) { config->matte = ParseMatteMode(name); },
         "the outline: none (RGB only, the thesis's avatar), learned (coverage predicted at full resolution, "
         "composited over the background) or bounded (learned, kept inside the region the dataset's masks may "
         "cover: below the jaw line and beside the face nothing)")
      ->check(CLI::IsMember({"none", "learned", "bounded"}))
      ->default_str(MatteModeName(config->matte));
  app->add_option("--matte-core", config->matte_core,
                  "with a bounded matte: the model's silhouette eroded by this fraction of the image edge is always "
                  "covered (0: off)")
      ->capture_default_str();
  app->add_option("--matte-weight", fit->loss.matte_weight,
                  "with a matte: weight of the coverage's cross-entropy against the masks")
      ->capture_default_str();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"headcast-train: build avatars"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  app.require_subcommand(1);
  std::string log_level;
  app.add_option("--log", log_level, "log level");

  auto* prep = app.add_subcommand("prep", "video or image folder -> a prepared dataset (crops, masks, parameters)");
  PrepOptions p;
  prep->add_option("--input", p.input, "video file, image or RGB-D folder, or zed:SOURCE (as headcast-track)")
      ->required();
  prep->add_option("--head-model", p.head_model, "builtin or a model .npz")->capture_default_str();
  prep->add_option("--out", p.out_dir, "dataset folder to write")->required();
  prep->add_option("--resolutions", p.resolutions, "crop sizes (128, 256, 512)")->delimiter(',')->capture_default_str();
  prep->add_option("--test-frames", p.test_frames, "the last N fitted frames are the test split")
      ->capture_default_str();
  AddMaxFramesFlag(*prep, &p.max_frames, "use only the first N frames");
  prep->add_flag("!--no-calibrate", p.calibrate, "no identity calibration (shape stays neutral)");
  prep->add_option("--shape-prior", p.shape_prior,
                   "identity calibration: weight of the shape's squared coefficients against squared landmark pixels")
      ->capture_default_str();
  prep->add_option("--rigid-flow-weight", p.rigid_flow_weight,
                   "tracking: weight of each rigid head point (forehead, hairline) followed by optical flow, against a "
                   "landmark (0: off)")
      ->capture_default_str();
  prep->add_option("--expression-prior", p.expression_fit.expression_prior,
                   "tracking: weight of the expression's squared coefficients against squared landmark pixels (the "
                   "avatar carries it to the sender, which fits with it)")
      ->capture_default_str();
  prep->add_option("--expression-range-weight", p.expression_fit.expression_range_weight,
                   "tracking: weight of each expression coefficient's squared distance outside the model's range "
                   "(ICT: 0..1), against squared landmark pixels")
      ->capture_default_str();
  prep->add_option("--eye-look-prior", p.expression_fit.eye_look_prior,
                   "tracking: extra weight of the eyeLook coefficients (lid motion with gaze) against squared landmark "
                   "pixels: lids close with the blink shapes")
      ->capture_default_str();
  prep->add_option("--eye-look-prior-shapes", p.expression_fit.eye_look_prior_shapes,
                   "tracking: which eyeLook shapes the prior weighs: all, or vertical (Up, Down: sideways looks keep "
                   "their lids)")
      ->check(CLI::IsMember(kEyeLookPriorShapes))
      ->capture_default_str();
  prep->add_option("--lid-gaze-weight", p.expression_fit.lid_gaze_weight,
                   "tracking: weight of each vertical eyeLook coefficient against the lids the eye's fitted pitch "
                   "implies, against squared landmark pixels (0: off): other lid motion is a blink or a wide eye")
      ->capture_default_str();
  prep->add_option("--calibration-mean-expression", p.calibration_mean_expression,
                   "identity calibration: weight of the key frames' mean expression (per frame, against squared "
                   "landmark pixels): what every key frame shows goes into the shape")
      ->capture_default_str();
  prep->add_option("--identity-from", p.identity_from,
                   "shape from an avatar (.hcavatar) or headcast-fit-mesh's PARAMS.json (implies --no-calibrate)");
  prep->add_option("--intrinsics", p.intrinsics, "camera fx,fy,cx,cy in pixels, when known");
  prep->add_option("--crop-scale", p.crop_scale, "crop edge over the landmarks' extent")->capture_default_str();
  prep->add_option("--mask-margin", p.mask_margin,
                   "training masks: the model's silhouette grown by this fraction of the crop")
      ->capture_default_str();
  prep->add_option("--side-margin", p.side_margin,
                   "below the eye line the silhouette grows only this much (raise it for long hair)")
      ->capture_default_str();
  prep->add_option("--mask-working-size", p.mask_working_size,
                   "training masks: GrabCut segments the head region at about this many pixels across")
      ->capture_default_str();
  prep->add_option("--steady-masks", p.steady_masks,
                   "training masks: GrabCut's masks of this many frames either side moved with the head and "
                   "averaged (0: each frame's own)")
      ->capture_default_str();
  prep->add_flag("--keep-neck", p.keep_neck, "training masks keep the neck (where GrabCut finds it)");
  prep->add_flag("!--no-skull-fill", p.fill_skull,
                 "training masks: leave the fitted skull above the brows to GrabCut (which may take dark hair before "
                 "a dark wall for the wall, and the avatar is then drawn bald)");
  prep->add_flag("!--no-gaze", p.gaze, "do not locate the irises: the eyes look straight ahead");
  prep->add_flag("!--no-landmark-repair", p.landmark_repair,
                 "keep the shape predictor's brows and mouth where they jump against the flow from the previous "
                 "frame (no repair; drive the avatar the same way)");
  prep->add_option("--predictor-views", p.predictor_views,
                   "tracking: the shape predictor runs on this many views of each face (the box, its mirror, "
                   "the box smaller and larger), each landmark their median")
      ->check(CLI::Range(1, kMaxPredictorViews))
      ->capture_default_str();
  prep->add_option("--predictor-views-points", p.predictor_views_points,
                   "tracking: with several predictor views, which points take their median (the others the box's): "
                   "all, no-eyes, outline (jaw line and nose)")
      ->check(CLI::IsMember(kPredictorViewsPoints))
      ->capture_default_str();
  prep->add_option("--pose-smoothing", p.pose_smoothing,
                   "tracking: the head's placement smoothed over time after every frame is fitted, sigma in frames "
                   "(0: as fitted)")
      ->capture_default_str();
  prep->add_option("--photometric-anchor", p.photometric_anchor,
                   "tracking: once every frame is fitted, the head's placement is held to the grey levels of its "
                   "rigid part (forehead, temples, crown) over the clip and every frame fitted again; each anchored "
                   "point's weight against a landmark (0: off)")
      ->capture_default_str();
  prep->add_option("--outline-hold", p.outline_hold,
                   "tracking, with the photometric anchor: the head's pitch also held to the top of the hair's "
                   "outline in the head mask (the hair's thickness over the skull kept at its median over the clip); "
                   "each held column's weight against a landmark (0: off)")
      ->capture_default_str();
  prep->add_option("--landmark-filter", p.landmark_filter,
                   "tracking: the landmarks over time: off (as found), causal (the live tracker's filter, which "
                   "lags a moving face) or two-sided (filtered forwards and backwards: no lag)")
      ->check(CLI::IsMember(kLandmarkFilterModes))
      ->capture_default_str();
  prep->add_option("--landmark-filter-hz", p.landmark_filter_hz,
                   "tracking: the landmarks' One-Euro filter at rest, Hz (higher: less lag, more jitter)")
      ->capture_default_str();
  prep->add_option("--landmark-filter-beta", p.landmark_filter_beta,
                   "tracking: the One-Euro filter's cutoff rise per pixel a second of landmark speed")
      ->capture_default_str();
  prep->add_option("--interpolate", p.interpolate,
                   "short videos: frames synthesised between consecutive training frames")
      ->capture_default_str();
  prep->add_flag("--resume", p.resume, "reuse a finished tracking pass in --out (after an interrupted prep)");
  AddDepthFlags(*prep, p.source);

  int processes = 1;
  auto* pretrain = app.add_subcommand("pretrain", "train the general model on synthetic head-model renders");
  PretrainOptions g;
  double neck_deg = 20;
  pretrain->add_option("--head-model", g.head_model, "builtin or a model .npz")->capture_default_str();
  pretrain->add_option("--resolution", g.resolution, "output size")->check(CLI::IsMember({128, 256, 512}));
  pretrain->add_option("--neck-deg", neck_deg, "neck rotations drawn in +-DEG (METHOD uses up to 80)")
      ->capture_default_str();
  std::vector<CLI::Option*> pretrain_network = AddArchitectureFlags(pretrain, &g.config, "without --init: ");
  pretrain_network.push_back(
      pretrain
          ->add_option(
              "--hair-margin", g.config.hair_margin_px,
              "without --init: feature-map pixels beyond the head's silhouette that still get CNeRF rays (hair)")
          ->capture_default_str());
  AddSurfaceFlags(pretrain, &g.config, &g.fit);
  AddMatteFlags(pretrain, &g.config, &g.fit);
  pretrain->add_option("--init", g.init, "continue from this .hcavatar");
  pretrain->add_option("--real", g.real_datasets,
                       "a prepared dataset whose training frames are mixed in (repeat for several people)");
  pretrain->add_option("--mix-m", g.fit.mix.m, "METHOD eq. 9: synthetic only up to step M")->capture_default_str();
  pretrain->add_option("--mix-n", g.fit.mix.n_end, "METHOD eq. 9: p reaches p_min at step N")->capture_default_str();
  pretrain->add_option("--p-min", g.fit.mix.p_min, "METHOD eq. 9")->capture_default_str();
  pretrain->add_option("--p-max", g.fit.mix.p_max, "METHOD eq. 9")->capture_default_str();
  AddTrainingFlags(pretrain, &g.fit, &g.outputs, &processes);

  auto* subject = app.add_subcommand("subject", "fine-tune a person's avatar from the general model");
  SubjectOptions s;
  s.fit.iterations = 1000;
  // --surface-features 0 --matte none: the thesis's avatar.
  ApplySubjectDefaults(&s.config);
  subject->add_option("--head-model", s.head_model, "builtin or a model .npz")->capture_default_str();
  subject->add_option("--general", s.general, "the general model (.hcavatar)");
  subject->add_flag("--from-scratch", s.from_scratch, "random networks instead of a general model (comparisons)");
  subject->add_option("--data", s.dataset, "dataset folder from prep")->required();
  subject->add_option("--resolution", s.resolution, "output size (crops of this size must be prepared)")
      ->check(CLI::IsMember({128, 256, 512}))
      ->capture_default_str();
  const std::vector<CLI::Option*> subject_network = AddArchitectureFlags(subject, &s.config, "with --from-scratch: ");
  subject
      ->add_option("--hair-margin", s.hair_margin,
                   "feature-map pixels beyond the head's silhouette that still get CNeRF rays (the hair; -1: the "
                   "general model's, or 2 from scratch)")
      ->capture_default_str();
  AddSurfaceFlags(subject, &s.config, &s.fit);
  AddMatteFlags(subject, &s.config, &s.fit);
  subject->add_option(
      "--identity-from", s.identity_from,
      "the shape (beta) of an avatar (.hcavatar) or a headcast-fit-mesh PARAMS.json, not the dataset's");
  subject
      ->add_option("--synthetic-start", s.synthetic_start, "probability of a synthetic sample at step 0 (falls to 0)")
      ->capture_default_str();
  subject->add_flag("--blind-synthetic-face", s.fit.loss.blind_synthetic_face,
                    "synthetic renders teach no eyes, brows or mouth (their target there is the avatar's own output: "
                    "the painted mesh has no real lids, irises or teeth)");
  subject->add_flag("!--no-interpolated", s.use_interpolated, "leave out the dataset's interpolated frames");
  subject->add_option("--freeze-layers", s.freeze_layers, "CNeRF layers kept from the general model")
      ->capture_default_str();
  subject->add_flag("!--no-expression-span", s.expression_span,
                    "tell the networks the frames' expressions as they are, not held within the training frames' span "
                    "(the mesh takes them as they are either way)");
  subject->add_flag("--expression-span-in-training", s.expression_span_in_training,
                    "hold the synthetic renders' expressions within the span in training too, as the receiver will");
  subject
      ->add_flag("--mean-offset,!--no-mean-offset", s.mean_offset,
                 "keep the mean of the per-frame offsets learnt on the training frames as the avatar's "
                 "conditioning bias (added to every frame's codes)")
      ->capture_default_str();
  subject
      ->add_option("--matte-scale", s.matte_scale,
                   "the matte's coverage logit is multiplied by this where the avatar is drawn, written into the "
                   "file after training (below 1: a softer outline; training draws at 1)")
      ->capture_default_str();
  AddTrainingFlags(subject, &s.fit, &s.outputs, &processes);

  auto* eval = app.add_subcommand("eval", "evaluate an avatar on a dataset's test split; videos");
  EvalOptions e;
  eval->add_option("--head-model", e.head_model, "builtin or a model .npz")->capture_default_str();
  eval->add_option("--avatar", e.avatar, ".hcavatar")->required();
  eval->add_option("--data", e.dataset, "dataset folder from prep")->required();
  eval->add_option("--out", e.out_dir, "folder for eval.json, per_frame.csv and the videos")->required();
  AddMaxFramesFlag(*eval, &e.max_frames, "evaluate at most N frames");
  eval->add_option("--split", e.split, "test (held-out frames) or train (real training frames)")
      ->check(CLI::IsMember({"test", "train"}))
      ->capture_default_str();
  eval->add_option("--drive", e.drive, "a recording (.hcrec) whose expressions drive transfer.mp4");
  eval->add_flag("--write-frames", e.write_frames,
                 "also write the ground-truth and avatar frames (PNG) under OUT/frames");
  eval->add_option("--orbit-frames", e.orbit_frames, "frames of the novel-view orbit (0: none)")->capture_default_str();
  eval->add_flag("!--no-skin-colour", e.skin_colour,
                 "draw the avatar in its own colours, not matched to the frames' skin colours (when the dataset has "
                 "them)");
  eval->add_flag("!--no-landmarks", e.landmarks,
                 "skip the expression-fidelity figures (dlib landmarks on avatar and true frames)");
  eval->add_option("--predictor", e.landmark_predictor, "dlib's 68-point shape predictor")->capture_default_str();
  eval->add_option("--expression-span", e.expression_span,
                   "the expressions the networks are told: within the span the avatar carries (avatar), as the "
                   "frames say (none), or within the dataset's training frames' span (dataset: avatars made "
                   "before spans were kept)")
      ->check(CLI::IsMember({"avatar", "none", "dataset"}))
      ->capture_default_str();
  eval->add_option("--matte-scale", e.matte_scale,
                   "draw with the matte's coverage logit multiplied by this instead of the avatar's scale (0: the "
                   "avatar's)")
      ->capture_default_str();
  eval->add_option("--motion-blur", e.motion_blur,
                   "draw with this exposure (frame intervals) for the motion blur instead of the avatar's (-1: the "
                   "avatar's; 0: sharp)")
      ->capture_default_str();
  eval->add_option("--outline-bins", e.outline_bins,
                   "each frame carries the top of its mask's outline in this many arcs, as the sender measures it "
                   "on its frame (12: the sender's, by default with an avatar that records its camera; 0: none, the "
                   "avatar alone, as a sender with --no-outline or on a narrow link)")
      ->capture_default_str();
  eval->add_option("--outline-every", e.outline_every,
                   "with --outline-bins: the outline measured on every Nth frame only, the others carrying the last "
                   "measurement (a sender measuring at a lower rate)")
      ->capture_default_str();
  eval->add_option("--outline-ramp", e.outline_ramp,
                   "the avatar's outline is moved to the frame's from this far inside it (share of the picture's "
                   "height) instead of the avatar's setting (-1: the avatar's; 0: not moved)")
      ->capture_default_str();
  eval->add_option("--outline-matte-scale", e.outline_matte_scale,
                   "on frames whose outline is moved there, draw with the matte's coverage logit multiplied by this "
                   "instead of the avatar's outline scale (0: the avatar's)")
      ->capture_default_str();
  eval->add_option("--outline-centre-y", e.outline_centre_y,
                   "the head point the outline's rays start from, (0, Y, 0) in the head frame, metres")
      ->capture_default_str();

  auto* compare = app.add_subcommand(
      "compare",
      "a session against its input: the receiver's recording rendered beside the frames it was tracked from");
  CompareOptions m;
  compare->add_option("--head-model", m.head_model, "builtin or a model .npz")->capture_default_str();
  compare->add_option("--avatar", m.avatar, ".hcavatar (the receiver's)")->required();
  compare->add_option("--recording", m.recording, "the receiver's --record (.hcrec)")->required();
  compare->add_option("--truth", m.truth, "the input the sender tracked: a video or image folder")->required();
  compare->add_option("--frame-map", m.frame_map,
                      "the sender's --frames-csv (without it, sequence k is input frame k)");
  compare->add_option("--out", m.out_dir, "folder for compare.json, per_frame.csv, side_by_side.mp4")->required();
  compare->add_option("--caption", m.caption, "a line of text under the panels");

  auto* plot = app.add_subcommand("plot", "line plot of CSV columns (logs of several runs in one picture)");
  std::vector<std::string> series;
  std::string plot_out, title = "", x_label = "step", y_label = "";
  bool log_y = false;
  plot->add_option("--series", series, "CSV:COLUMN:LABEL, repeatable")->required();
  plot->add_option("--out", plot_out, "PNG to write")->required();
  plot->add_option("--title", title, "title");
  plot->add_option("--x-label", x_label, "x axis")->capture_default_str();
  plot->add_option("--y-label", y_label, "y axis");
  plot->add_flag("--log-y", log_y, "logarithmic y axis");

  auto* create = app.add_subcommand(
      "create", "one command to your avatar: a video, image folder or camera -> tracking, dataset, fine-tune, eval");
  CreateOptions c;
  std::string preview = std::getenv("DISPLAY") != nullptr ? "window" : "none";
  create->add_option("--input", c.input, "a video file, an image folder, or a camera (/dev/videoN: recorded first)")
      ->required();
  create->add_option("--out", c.out, "the avatar to write (.hcavatar)")->required();
  create->add_option("--work", c.work_dir, "the stages' outputs (default: OUT's name + .create beside it)");
  create->add_option("--head-model", c.head_model,
                     "builtin or a model .npz (default: the shipped ICT-FaceKit, models/ict_facekit.npz)");
  create->add_option("--general", c.general,
                     "the general model to fine-tune (default: the shipped one for the head model)");
  create->add_option("--iterations", c.iterations, "fine-tune steps")->capture_default_str();
  create->add_option("--resolution", c.resolution, "the avatar's output size")
      ->check(CLI::IsMember({128, 256, 512}))
      ->capture_default_str();
  create->add_option("--max-frames", c.max_frames, "use at most this many frames (0: all)")->capture_default_str();
  create
      ->add_option("--test-frames", c.test_frames,
                   "the last N fitted frames are held out for the figures (at most a sixth of them)")
      ->capture_default_str();
  create->add_option("--intrinsics", c.intrinsics, "camera fx,fy,cx,cy in pixels, when known");
  create->add_option("--identity-from", c.identity_from,
                     "your shape when known: an avatar (.hcavatar) or headcast-fit-mesh's PARAMS.json of a head scan "
                     "(instead of calibrating it from the video)");
  create->add_option("--shape-prior", c.shape_prior,
                     "identity calibration: weight of the shape's squared coefficients against squared landmark "
                     "pixels (default: the tracker's)");
  create->add_flag("--resume", c.resume, "continue an interrupted create in --work");
  create->add_option("--stop-after", c.stop_after, "end after this stage (record, prep, fine-tune); --resume goes on")
      ->check(CLI::IsMember({"record", "prep", "fine-tune"}));
  create->add_option("--record", c.record_s,
                     "seconds to record first (cameras: 60 unless given; a video given this plays as a camera)");
  create->add_flag("--accept-recording", c.accept_recording, "train even when the recording's quality check fails");
  create->add_option("--preview", preview, "while recording, show the camera with its prompts: window or none")
      ->check(CLI::IsMember({"window", "none"}))
      ->capture_default_str();
  create->add_flag("!--no-landmarks", c.landmarks, "skip eval's dlib landmark figures");
  create->add_option("--processes", c.processes, "fine-tune ranks (2 on two cores)")
      ->check(CLI::Range(1, 64))
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->capture_default_str();
  create->add_option("--threads", c.threads, "libtorch threads of this process (0: libtorch's choice)")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  create->add_option("--rank", c.distributed.rank, "(set by --processes for its copies)")->group("");
  create->add_option("--world-size", c.distributed.world_size, "")->group("");
  create->add_option("--master-addr", c.distributed.master_addr, "")->group("");
  create->add_option("--master-port", c.distributed.master_port, "")->group("");
  std::string camera_size = "640x480";
  AddCameraFlags(*create, c.source, camera_size);

  EndWithParentRank();
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    nlohmann::json report;
    if (prep->parsed()) {
      if (!p.identity_from.empty()) p.calibrate = false;
      report = PrepareDataset(p);
      report.erase("frame_numbers");
    } else if (pretrain->parsed() || subject->parsed()) {
      FitOptions& fit = pretrain->parsed() ? g.fit : s.fit;
      if (subject->parsed() && subject->get_option("--weight-average")->count() == 0)
        fit.weight_average = SubjectWeightAverage(fit.iterations);
      // The default conditioning and blendshapes belong to the default texture:
      // without a texture (the thesis's avatar) there is nothing to condition
      // or to add to, unless asked.
      if (subject->parsed() && !s.config.has_surface()) {
        if (subject->get_option("--surface-conditioned")->count() == 0) s.config.surface_conditioned = false;
        if (subject->get_option("--surface-blend")->count() == 0) s.config.surface_blend = 0;
      }
      // Likewise the covered parts apart belong to the canonical samples, and
      // would move the points a surface displacement is measured from.
      if (subject->parsed() && (!s.config.canonical_samples || s.config.surface_displacement) &&
          subject->get_option("--covered-apart")->count() == 0)
        s.config.covered_apart = false;
      // A fine-tune takes its general model's network: a size given with it
      // would be dropped without a word.
      if (subject->parsed() && !s.from_scratch)
        for (const CLI::Option* option : subject_network)
          if (option->count() > 0)
            throw std::invalid_argument(option->get_name() +
                                        " sizes a new network: a fine-tune keeps its general model's (" + s.general +
                                        "); give it to pretrain, or with --from-scratch");
      if (pretrain->parsed() && !g.init.empty())
        for (const CLI::Option* option : pretrain_network)
          if (option->count() > 0)
            throw std::invalid_argument(option->get_name() + " sizes a new network: --init continues " + g.init + "'s");
      std::unique_ptr<LocalRanks> ranks;
      if (processes > 1) {
        if (fit.distributed.world_size > 1)
          throw std::invalid_argument("--processes starts its own ranks; it does not go with --world-size");
        if (fit.threads == 0) fit.threads = 1;
        ranks = std::make_unique<LocalRanks>(processes, std::vector<std::string>(argv + 1, argv + argc));
        fit.distributed.world_size = processes;
        fit.distributed.master_addr = "127.0.0.1";
        fit.distributed.master_port = ranks->port();
      }
      g.synthetic.neck_x_deg = g.synthetic.neck_y_deg = g.synthetic.neck_z_deg = neck_deg;
      report = pretrain->parsed() ? RunPretrain(g) : RunSubject(s);
      if (ranks) ranks->Wait();
    } else if (eval->parsed()) {
      report = RunEval(e);
    } else if (create->parsed()) {
      ParseSize(camera_size, "--camera-size", &c.source.width, &c.source.height);
      std::unique_ptr<LocalRanks> ranks;
      std::unique_ptr<Display> display;
      CreateHooks hooks;
      hooks.start_ranks = [&](FitOptions* fit) -> std::function<void()> {
        if (fit->threads == 0) fit->threads = 1;
        ranks = std::make_unique<LocalRanks>(c.processes, std::vector<std::string>(argv + 1, argv + argc));
        fit->distributed.world_size = c.processes;
        fit->distributed.master_addr = "127.0.0.1";
        fit->distributed.master_port = ranks->port();
        return [&] { ranks->Wait(); };
      };
      if (preview == "window")
        hooks.show = [&](const cv::Mat& frame) {
          if (!display) {
            DisplayOptions d;
            d.title = "headcast: recording for your avatar";
            d.draw_overlay = false;
            display = MakeDisplay(d);
          }
          return display->Show(frame, {});
        };
      report = RunCreate(c, hooks);
      if (c.distributed.rank > 0) return 0;
      std::cerr << CreateSummaryText(report);
    } else if (compare->parsed()) {
      report = RunCompare(m);
    } else if (plot->parsed()) {
      std::vector<PlotSeries> lines;
      for (const std::string& spec : series) {
        const size_t a = spec.find(':'), b = spec.find(':', a == std::string::npos ? a : a + 1);
        if (a == std::string::npos || b == std::string::npos)
          throw std::invalid_argument("--series wants CSV:COLUMN:LABEL, got " + spec);
        PlotSeries line = ReadCsvColumns(spec.substr(0, a), {spec.substr(a + 1, b - a - 1)}).front();
        line.name = spec.substr(b + 1);
        lines.push_back(line);
      }
      WritePlot(plot_out, title, x_label, y_label, lines, log_y);
      report = {{"wrote", plot_out}};
    }
    std::cout << report.dump(2) << "\n";
  } catch (const std::exception& ex) {
    spdlog::error("{}", headcast::InFlagNames(app, ex.what()));
    return 1;
  }
  return 0;
}
