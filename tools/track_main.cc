// headcast-track: the offline tracking pass (TrackVideo) on a video, image or
// RGB-D folder, side-by-side stereo or a camera — writing the parameter
// recording, head masks, an overlay video and a JSON report.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "common/capture/capture_flags.h"
#include "common/core/cli_flags.h"
#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/offline_tracker.h"
#include "proto/recording.h"

namespace {

using namespace headcast;

struct TrackFlags {
  OfflineTrackOptions track;
  std::string head_model = "builtin", out, report, masks_dir, log_level, identity_from, intrinsics;
  std::string camera_size = "640x480";
  bool avatar_anchor = false;
  std::vector<CLI::Option*> expression_fit_flags;  // given: they win over an avatar's ExpressionFitSettings
};

void AddFlags(CLI::App& app, TrackFlags& f) {
  OfflineTrackOptions& t = f.track;
  app.add_option("--input", t.input,
                 "video file, image folder, RGB-D folder (with associations.txt), /dev/videoN (V4L2 camera), or "
                 "zed:SOURCE (side-by-side stereo from a camera, video or folder)")
      ->required();
  app.add_option("--head-model", f.head_model, "builtin or a model .npz")->capture_default_str();
  app.add_option("--out", f.out, "parameter recording to write (.hcrec)")->required();
  AddJsonFlag(app, &f.report, "the tracking report", {"--report"});
  app.add_option("--overlay", t.overlay, "MP4 with the detected and fitted landmarks over the frames");
  AddMaxFramesFlag(app, &t.max_frames, "stop after this many frames");
  app.add_option("--fov", t.fov_deg, "vertical field of view of the camera, degrees (when nothing better is known)")
      ->capture_default_str();
  app.add_option("--predictor", t.tracker.face.predictor_path, "dlib 68-point shape predictor (.dat)")
      ->capture_default_str();
  app.add_flag("!--no-gaze", t.tracker.face.locate_irises, "do not locate the irises: the eyes look straight ahead");
  app.add_flag("!--no-landmark-repair", t.tracker.face.repair.repair,
               "keep the shape predictor's brows and mouth where they jump against the flow from the previous "
               "frame (no repair)");
  SourceOptions& s = t.source;
  AddDepthFlags(app, s);
  AddPacingFlag(app, &s.realtime, {"--realtime"});
  app.add_option("--intrinsics", f.intrinsics,
                 "camera intrinsics fx,fy,cx,cy in pixels (else calibration, the stereo calibration, or --fov)");
  app.add_option("--calibration-frames", t.calibration_frames,
                 "RGB-D: frames whose fitted shapes give the identity (median); with --calibrate: key frames at most")
      ->capture_default_str();
  app.add_option("--masks", f.masks_dir, "also write a head mask (face, hair, neck) per fitted frame here, NNNNN.png");
  app.add_option("--mask-hair-height", t.mask.hair_height,
                 "head masks: hair may reach this far above the brows, in face heights")
      ->capture_default_str();
  app.add_option("--mask-head-width", t.mask.head_width, "head masks: the head's width, in jaw widths")
      ->capture_default_str();
  app.add_option("--mask-min-face-height", t.mask.min_face_height,
                 "head masks: a face's height is at least this many jaw widths (a pitched head looks short)")
      ->capture_default_str();
  app.add_option("--mask-background-ring", t.mask.background_ring,
                 "head masks: probable (not certain) background this far beyond the head's region, in face heights")
      ->capture_default_str();
  app.add_option("--mask-working-size", t.mask.working_size,
                 "head masks: GrabCut segments the head region at about this many pixels across")
      ->capture_default_str();
  app.add_flag("!--no-appearance", t.fit_appearance, "skip the texture/light fit (stored in the recording's header)");
  app.add_flag("--calibrate", t.calibrate,
               "RGB, recorded input: calibrate identity (shape) and focal length over key frames spread over the "
               "head's yaw in a first pass, then track with them (METHOD §2)");
  app.add_option("--shape-prior", t.tracker.fit.shape_prior,
                 "with --calibrate: weight of the shape's squared coefficients against squared landmark pixels")
      ->capture_default_str();
  app.add_option("--contour-weight", t.tracker.fit.contour_weight,
                 "weight of the jaw contour's landmarks (0..16) against the inner ones")
      ->capture_default_str();
  app.add_option("--rigid-flow-weight", t.tracker.fit.rigid_flow_weight,
                 "weight of each rigid head point (forehead, hairline) followed by optical flow from the previous "
                 "frame, against a landmark (0: off)")
      ->capture_default_str();
  app.add_option("--photometric-anchor", t.anchor.weight,
                 "recorded input: once every frame is fitted, the head's placement is held to the grey levels of "
                 "its rigid part (forehead, temples, crown) over the clip and every frame fitted again; each "
                 "anchored point's weight against a landmark (0: off)")
      ->capture_default_str();
  app.add_option("--predictor-views", t.tracker.face.predictor_views,
                 "the shape predictor runs on this many views of each face (the box, its mirror, the box smaller "
                 "and larger), each landmark their median")
      ->check(CLI::Range(1, kMaxPredictorViews))
      ->capture_default_str();
  app.add_option("--predictor-views-points", t.tracker.face.predictor_views_points,
                 "with several predictor views, which points take their median (the others the box's): all, no-eyes, "
                 "outline (jaw line and nose)")
      ->check(CLI::IsMember(kPredictorViewsPoints))
      ->capture_default_str();
  app.add_option_function<std::string>(
         "--landmark-filter", [&t](const std::string& mode) { SetLandmarkFilter(mode, &t); },
         "the landmarks over time: causal (filtered forwards, as live; the default), off (as found) or two-sided "
         "(recorded input: filtered forwards and backwards, no lag)")
      ->check(CLI::IsMember(kLandmarkFilterModes));
  app.add_option("--landmark-filter-hz", t.tracker.face.filter_min_cutoff,
                 "the landmarks' One-Euro filter at rest, Hz (higher: less lag, more jitter)")
      ->capture_default_str();
  app.add_option("--landmark-filter-beta", t.tracker.face.filter_beta,
                 "the One-Euro filter's cutoff rise per pixel a second of landmark speed")
      ->capture_default_str();
  f.expression_fit_flags.push_back(
      app.add_option("--expression-prior", t.tracker.fit.expression_prior,
                     "weight of the expression's squared coefficients against squared landmark pixels (default: "
                     "with --identity-from AVATAR, as its training frames were fitted)")
          ->capture_default_str());
  f.expression_fit_flags.push_back(
      app.add_option("--expression-range-weight", t.tracker.fit.expression_range_weight,
                     "weight of each expression coefficient's squared distance outside the model's range (ICT: 0..1), "
                     "against squared landmark pixels")
          ->capture_default_str());
  f.expression_fit_flags.push_back(
      app.add_option("--eye-look-prior", t.tracker.fit.eye_look_prior,
                     "extra weight of the eyeLook coefficients (lid motion with gaze) against squared landmark pixels: "
                     "lids close with the blink shapes")
          ->capture_default_str());
  f.expression_fit_flags.push_back(
      app.add_option(
             "--eye-look-prior-shapes", t.tracker.fit.eye_look_prior_shapes,
             "which eyeLook shapes the prior weighs: all, or vertical (Up, Down: sideways looks keep their lids)")
          ->check(CLI::IsMember(kEyeLookPriorShapes))
          ->capture_default_str());
  f.expression_fit_flags.push_back(
      app.add_option("--lid-gaze-weight", t.tracker.fit.lid_gaze_weight,
                     "weight of each vertical eyeLook coefficient against the lids the eye's fitted pitch implies, "
                     "against squared landmark pixels (0: off): other lid motion is a blink or a wide eye")
          ->capture_default_str());
  app.add_option("--calibration-mean-expression", t.tracker.fit.calibration_mean_expression,
                 "with --calibrate: weight of the key frames' mean expression (per frame, against squared landmark "
                 "pixels): what every key frame shows goes into the shape")
      ->capture_default_str();
  AddCameraFlags(app, s, f.camera_size);
  app.add_option("--identity-from", f.identity_from,
                 "take the identity (shape) from an avatar (.hcavatar) or a headcast-fit-mesh PARAMS.json");
  app.add_flag("--avatar-anchor", f.avatar_anchor,
               "with --identity-from an avatar: hold each frame's placement to the photometric anchor its file "
               "carries as the frame is fitted, as the live sender does");
  app.add_option("--log", f.log_level, "log level");
}

int Run(TrackFlags& f) {
  InitLogging(f.log_level);
  OfflineTrackOptions& t = f.track;
  ParseSize(f.camera_size, "--camera-size", &t.source.width, &t.source.height);
  if (!f.intrinsics.empty()) t.intrinsics = ParseIntrinsics(f.intrinsics, "--intrinsics");
  const HeadModel model = LoadHeadModelSpec(f.head_model);
  if (!f.identity_from.empty()) {
    t.identity = ReadTrackingIdentity(f.identity_from, model);
    t.identity_source = f.identity_from;
    // As the sender fits for this avatar, unless the command line says otherwise.
    const bool given = std::any_of(f.expression_fit_flags.begin(), f.expression_fit_flags.end(),
                                   [](const CLI::Option* o) { return o->count() > 0; });
    if (const std::optional<ExpressionFitSettings> fit = ReadAvatarExpressionFit(f.identity_from); fit && !given)
      fit->ApplyTo(&t.tracker.fit);
  }
  if (f.avatar_anchor) {
    if (f.identity_from.empty()) throw std::invalid_argument("--avatar-anchor needs --identity-from AVATAR");
    t.anchor_reference = ReadAvatarAnchorReference(f.identity_from);
    if (!t.anchor_reference)
      throw std::invalid_argument(f.identity_from + ": carries no photometric anchor (prepared without one?)");
  }
  t.masks = !f.masks_dir.empty();
  if (t.masks) std::filesystem::create_directories(f.masks_dir);
  const OfflineTrack track = TrackVideo(model, t, [&](const OfflineFrame& frame) {
    if (!frame.mask.empty()) WriteImage(f.masks_dir + "/" + FrameFileName(frame.index), frame.mask);
  });
  WriteRecording(f.out, MakeRecordingInfo(model, track.fps, track.subject, "headcast-track " + t.input), track.frames);
  std::cout << track.report.dump(2) << "\n";
  if (!f.report.empty()) std::ofstream(f.report) << track.report.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"headcast-track: track a face in a video and fit the head model to every frame"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  TrackFlags flags;
  AddFlags(app, flags);
  return headcast::RunProgram(app, argc, argv, [&] { return Run(flags); });
}
