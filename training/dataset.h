// Prepared datasets (`headcast-train prep`): one person's video turned into
// what the trainer reads — square head crops at one or more resolutions with
// their head masks, the per-frame parameters fitted by the sender's own
// tracker, the subject's constants (beta, tau, lambda, the crop's intrinsics)
// and an INSTA-style split (train on the leading frames, test on the last N).
//
// On disk (DIR):
//   dataset.json        format, version, head model, source, crop box, split, subject, per-resolution intrinsics
//   params.hcrec        the tracker's recording (full-frame camera)
//   track_report.json   the tracker's report (written last: a finished pass); preview.mp4 its overlay
//   full_frames/, full_masks/   the fitted frames and their head masks, full size (lossless PNG)
//   R/images/NNNNN.png  crops at R x R (R in 128, 256, 512), NNNNN the source frame number
//   R/masks/NNNNN.png   the head masks, same crops
//   params_interp.hcrec, R/interp/{images,masks}/NNNNN.png   frames synthesised between
//                       consecutive training frames (prep --interpolate K), training only
#pragma once

#include <array>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/avatar/matte.h"
#include "common/capture/frame_source.h"
#include "common/core/crop.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/tracking/expression_fit.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/head_mask.h"
#include "common/tracking/photometric_anchor.h"

namespace headcast {

constexpr int kDatasetFormatVersion = 1;
constexpr int kMaxSteadyMasks = 8;  // PrepOptions::steady_masks

struct PrepOptions {
  std::string input;  // anything the offline tracker reads: video, image or RGB-D folder, zed:SOURCE
  std::string head_model = "builtin";
  std::string out_dir;
  std::vector<int> resolutions = {128, 256};
  int test_frames = 150;      // the last N fitted frames are the test split
  double test_share = 0;      // > 0: at most this share of the fitted frames (short videos); 0: no cap
  int max_frames = 0;         // 0: all
  bool calibrate = true;      // identity calibration over key frames (shape, focal)
  std::string identity_from;  // or: beta from an avatar (.hcavatar) or headcast-fit-mesh's PARAMS.json
  std::string intrinsics;     // fx,fy,cx,cy when known (else calibration / field of view)
  double shape_prior = HeadFitterOptions{}.shape_prior;  // calibration: weight of the shape's squared coefficients
  // calibration: weight of the key frames' mean expression (HeadFitterOptions::calibration_mean_expression)
  double calibration_mean_expression = HeadFitterOptions{}.calibration_mean_expression;
  double rigid_flow_weight = HeadFitterOptions{}.rigid_flow_weight;  // HeadFitterOptions::rigid_flow_weight
  // How the expression is fitted (prior, range weight, eyeLook prior); recorded
  // in dataset.json for the avatar to carry to the sender.
  ExpressionFitSettings expression_fit;
  double crop_scale = 2.2;  // crop edge over the landmarks' extent (room for hair, ears, neck)
  // The training mask is the tracker's head mask (GrabCut) within the fitted
  // head model's silhouette dilated by this fraction of the crop edge: pixels
  // the avatar cannot reach (background caught by GrabCut) are not targets.
  double mask_margin = 0.08;
  // Below the eye line the silhouette grows by this much less: there the head
  // ends at the cheeks and ears, and GrabCut's extra pieces are background
  // (a picture frame behind the ear on talking_d9, in most frames but not all).
  // Long hair that falls beside the face needs it raised to mask_margin.
  double side_margin = 0.02;
  // Keep what GrabCut finds below the jaw line (the neck). Off by default: it
  // finds the neck in some frames only, which no avatar can learn.
  bool keep_neck = false;
  // GrabCut segments the head region at about this many pixels across
  // (HeadMaskOptions::working_size); the live default is coarser than a 256²
  // crop of a 512-pixel video, and the mask's outline is then drawn on that
  // coarser grid.
  int mask_working_size = HeadMaskOptions{}.working_size;
  // GrabCut's masks steadied over this many frames either side before the
  // rules cut them (SteadyMask); 0: each frame's own.
  int steady_masks = 0;
  // The fitted skull above the brows is head in every mask (FillSkull).
  bool fill_skull = true;
  MatteRules matte_rules() const { return {mask_margin, side_margin, keep_neck, fill_skull}; }
  bool gaze = true;             // locate the irises and fit the eye joints (off: the eyes look ahead, as before)
  bool landmark_repair = true;  // carry disputed brow and mouth landmarks by flow (LandmarkRepairOptions::repair)
  int predictor_views = FaceTrackerOptions{}.predictor_views;  // the shape predictor's views of each face, median
  std::string predictor_views_points = FaceTrackerOptions{}.predictor_views_points;  // which take the views' median
  // The landmarks over time. "off": as the shape predictor found them;
  // "causal": the live tracker's One-Euro filter, which steadies a live
  // picture but draws a moving face (lips, lids) where it was a frame or two
  // before, while the crops are not lagged, so the avatar learns the lag as
  // blur; "two-sided": that filter forwards and backwards (no lag, but it
  // still smooths fast blinks and lips). Off by measurement (DEFAULTS.md).
  std::string landmark_filter = "off";
  double landmark_filter_hz = FaceTrackerOptions{}.filter_min_cutoff;  // causal, two-sided: cutoff at rest
  double landmark_filter_beta = FaceTrackerOptions{}.filter_beta;      // causal, two-sided: speed coefficient
  // The head's placement smoothed over time after every frame is fitted
  // (SmoothHeadPlacement), sigma in frames; 0: as fitted.
  double pose_smoothing = 0;
  // The head's placement held to its appearance over the clip, then every
  // frame fitted again (OfflineTrackOptions::anchor; recorded input, not a
  // live camera); weight 0: off. On by measurement (DEFAULTS.md).
  double photometric_anchor = 0.5;
  // With the anchor: the head's pitch also held to the top of the hair's
  // outline in its refits (OfflineTrackOptions::outline), each held column's
  // weight against a landmark; 0: off.
  double outline_hold = 0;
  // Short videos: K frames synthesised between each pair of consecutive
  // training frames (optical flow; parameters interpolated). Never in the test split.
  int interpolate = 0;
  // Reuse a finished tracking pass in out_dir (its report is written last, so
  // its presence means the recording is complete); crops are always redone.
  bool resume = false;
  SourceOptions source;  // how the input is read (stereo calibration, depth input, ...)
  void Check() const;
};

// Runs the tracker, crops, writes DIR; returns the dataset's report (also in dataset.json).
// Throws with a clear message: no face anywhere, too few fitted frames for the split, unreadable input.
nlohmann::json PrepareDataset(const PrepOptions& options);

// One real training or test frame at one resolution.
struct RealSample {
  int frame = 0;      // source frame number
  cv::Mat image_bgr;  // R x R, CV_8UC3
  cv::Mat mask;       // R x R, CV_8U, 255 on the head
  FrameParams params;
};

class PreparedDataset {
 public:
  // Refuses, naming the file: a missing or foreign folder, another format
  // version, a dataset made for another head model, a missing resolution.
  // `interpolated`: also train on the synthesised in-between frames, if prepared.
  static PreparedDataset Load(const std::string& dir, const HeadModel& model, int resolution, bool interpolated = true);

  int resolution() const { return resolution_; }
  int size() const { return static_cast<int>(frames_.size()); }
  // Positions in [0, size): the real training frames, then any interpolated ones.
  const std::vector<int>& train() const { return train_; }
  int interpolated() const { return size() - first_interpolated_; }
  const std::vector<int>& test() const { return test_; }
  // The subject's constants with the intrinsics of the R x R crops.
  const SubjectParams& subject() const { return subject_; }
  const nlohmann::json& manifest() const { return manifest_; }
  // The full frames' camera and the crop (datasets prepared before the
  // source size was recorded have none).
  std::optional<CameraContract> camera_contract() const;
  // The photometric anchor's references its frames were fitted to (none when
  // prepared without the anchor, or before they were recorded).
  std::optional<AnchorReference> anchor_reference() const;
  // How its frames' expressions were fitted (datasets from before it was
  // recorded: ExpressionFitSettings::Legacy() with the eyeLook prior they
  // recorded). Throws naming the file when the entry is malformed.
  ExpressionFitSettings expression_fit() const;
  // The rules its masks were cut with (datasets from before they were
  // recorded: the defaults, which they were made with unless prepped otherwise).
  MatteRules matte_rules() const;
  const std::string& dir() const { return dir_; }
  // Reads (and caches) the crop and mask of position i.
  const RealSample& At(int i) const;
  // The fitted parameters of position i, without reading its pictures.
  const FrameParams& params(int i) const;

 private:
  std::string dir_;
  int resolution_ = 0;
  nlohmann::json manifest_;
  SubjectParams subject_;
  std::vector<FrameParams> frames_;
  std::vector<int> train_, test_;
  int first_interpolated_ = 0;
  mutable std::map<int, RealSample> cache_;
};

}  // namespace headcast
