// The subcommands of headcast-train as library entry points: each takes a
// checked options struct, does the whole job (progress, logs, plots,
// checkpoints, reports) and returns its report.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "common/avatar/avatar_config.h"
#include "common/tracking/face_tracker.h"
#include "training/avatar_fit.h"

namespace headcast {

// Logs, plots and periodic evaluation shared by pretrain and subject.
struct RunOutputs {
  std::string out;       // the .hcavatar to write
  std::string log_csv;   // loss per step (step,loss,mse,synthetic)
  std::string eval_csv;  // test PSNR/SSIM every eval_every steps (step,psnr,ssim)
  std::string plot_dir;  // losses.png and psnr.png here
  std::string preview;   // ground truth | avatar for 4 held-out samples (PNG)
  std::string report;    // the report JSON
  int eval_every = 0;    // 0: only at the end
  int eval_frames = 20;  // held-out samples per evaluation
};

// General model (METHOD §5): synthetic renders of the head model made on the
// fly, optionally mixed with the real training frames of a prepared dataset by
// the p(n) schedule.
struct PretrainOptions {
  std::string head_model = "builtin";
  int resolution = 128;
  std::string init;     // continue from this .hcavatar
  AvatarConfig config;  // architecture (output_size is set from resolution)
  SyntheticDataOptions synthetic;
  // Prepared datasets whose training frames are mixed in (optional): other
  // people's real faces (lids, irises, teeth) for the networks a fine-tune starts from.
  std::vector<std::string> real_datasets;
  FitOptions fit;
  RunOutputs outputs;
  void Check() const;
};
nlohmann::json RunPretrain(PretrainOptions options);

// A fine-tune's optimiser and loss defaults where they differ from pretraining's:
// the MSE weighted up around the eyes, brows and mouth, a higher rate reached
// through a warm-up (bench/DEFAULTS.md).
FitOptions SubjectFitDefaults();

// Per-subject avatar (METHOD §6): from a general model, beta and tau frozen,
// every CNeRF layer fine-tuned unless freeze_layers says otherwise (the
// thesis froze four), synthetic mixing decaying linearly to 0,
// z-augmentation; trained on the dataset's training split, evaluated on its test split.
struct SubjectOptions {
  std::string head_model = "builtin";
  std::string general;        // the general model .hcavatar; empty only with from_scratch
  bool from_scratch = false;  // random networks instead (the comparison of the thesis's claim)
  std::string dataset;        // from `prep`
  int resolution = 256;
  std::string identity_from;      // beta of an avatar or a headcast-fit-mesh PARAMS.json instead of the dataset's
  double synthetic_start = 0.25;  // probability of a synthetic sample at step 0, falling to 0
  bool use_interpolated = true;   // train on the dataset's interpolated frames too, if it has them
  int freeze_layers = 0;          // CNeRF layers kept from the general model (METHOD §6: 4)
  // The trained avatar tells its networks expressions within its training
  // frames' span only (AvatarConfig::expression_low/high); false: none.
  bool expression_span = true;
  // The span set before training instead of after it: the synthetic renders'
  // expressions beyond it are then told as the receiver will tell them (held
  // within it) while their mesh takes them as they are (the real frames lie
  // within it). Off: training unchanged by the span.
  bool expression_span_in_training = false;
  // The mean of the per-frame offsets the fine-tune learnt kept as the
  // avatar's conditioning bias (AvatarConfig::bias_geometry/appearance).
  bool mean_offset = false;
  // Feature-map pixels beyond the head's silhouette that still get CNeRF rays
  // (AvatarConfig::hair_margin_px): which rays are cast, not the networks'
  // size, so a fine-tune may choose it. -1: the start's.
  int hair_margin = -1;
  // The coverage logit's scale the avatar is drawn with (AvatarConfig::
  // matte_scale), written into the file after training; training draws at 1.
  double matte_scale = kSubjectMatteScale;
  AvatarConfig config;  // architecture when from_scratch
  FitOptions fit = SubjectFitDefaults();
  RunOutputs outputs;
  void Check() const;
};
nlohmann::json RunSubject(SubjectOptions options);

// Figures and videos of an avatar on a dataset's test split.
struct EvalOptions {
  std::string head_model = "builtin";
  std::string avatar;
  std::string dataset;
  std::string out_dir;
  int max_frames = 0;  // 0: the whole split
  // "test" (the held-out frames) or "train" (the real training frames, spread
  // evenly when max_frames is smaller): the two side by side tell
  // underfitting (both low) from overfitting (train high, test low).
  std::string split = "test";
  std::string drive;          // a recording whose expressions drive the expression-transfer video
  int orbit_frames = 60;      // novel-view orbit video (0: none)
  double orbit_deg = 30;      // yaw swing of the orbit
  bool write_frames = false;  // also OUT/frames/truth_NNNNN.png and avatar_NNNNN.png (codec comparisons)
  // The frames' skin colours, when the dataset has them, matched as the
  // receiver matches them; false: the avatar's own colours.
  bool skin_colour = true;
  // The expressions the networks are told: "avatar" within the span the
  // avatar carries (if any), "none" as the frames say, "dataset" within the
  // span of the dataset's training frames (what a fine-tune on it records;
  // for avatars made before spans were kept).
  std::string expression_span = "avatar";
  // The coverage logit's scale (AvatarConfig::matte_scale) instead of the
  // avatar's; 0: the avatar's.
  double matte_scale = 0;
  // The exposure of the motion blur (AvatarConfig::motion_blur) instead of
  // the avatar's; -1: the avatar's.
  double motion_blur = -1;
  // Each frame carries the top of its mask's outline in this many arcs, as a
  // sender with --outline measures it on its frame's mask cut the same way
  // (FrameParams::outline, LiveTrackerOptions::outline); 0: none (the avatar
  // alone, as the default sender's frames).
  int outline_bins = 0;
  // The outline measured on every Nth held-out frame only, the others
  // carrying the last measurement (a sender measuring at a lower rate).
  int outline_every = 1;
  // How the avatar moves its outline there (AvatarConfig::outline_ramp)
  // instead of the avatar's; -1: the avatar's.
  double outline_ramp = -1;
  // The coverage logit's scale on those frames (AvatarConfig::outline_matte_scale)
  // instead of the avatar's; 0: the avatar's.
  double outline_matte_scale = 0;
  // The head point the outline is measured about (AvatarConfig::outline_centre_y), metres.
  double outline_centre_y = AvatarConfig{}.outline_centre_y;
  // Expression fidelity: dlib's landmarks on the avatar's frames against the
  // true frames' (LandmarkAgreement); skipped, and said so, without the predictor file.
  bool landmarks = true;
  std::string landmark_predictor = FaceTrackerOptions{}.predictor_path;
  void Check() const;
};
// Writes OUT/eval.json, per_frame.csv, side_by_side.mp4 (ground truth | avatar |
// head model), orbit.mp4 and, with `drive`, transfer.mp4.
nlohmann::json RunEval(const EvalOptions& options);

}  // namespace headcast
