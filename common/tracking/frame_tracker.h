// The one per-frame tracker: face tracker, then the head-model fit (the RGB
// landmark fit, or the RGB-D fit of METHOD §3 when the frame carries depth),
// warm-started from the previous frame. The live sender, the offline pass
// (headcast-track, and so the trainer's prep) and the benchmark all track
// through this class, so the parameters an avatar is trained on and driven by
// come from the same rule.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/avatar/matte.h"
#include "common/capture/frame_source.h"
#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/background_identity.h"
#include "common/tracking/expression_fit.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/photometric_anchor.h"
#include "common/tracking/rgbd_fitter.h"

namespace headcast {

struct FrameTrackerOptions {
  FaceTrackerOptions face;
  HeadFitterOptions fit;
  // RGB-D without a given identity: the identity is the per-component median
  // of this many first fitted frames' shapes, then frozen.
  int rgbd_identity_frames = 15;
  // Live: those fits run beside tracking (BackgroundIdentity) while every
  // frame is tracked at once with the identity known so far (neutral at
  // first), instead of each holding its frame for a free-shape fit.
  bool rgbd_identity_in_background = false;
  // Each fitted frame carries its skin colour (FrameParams::skin_colour,
  // measured where the fit puts the cheeks, nose and chin), which the
  // receiver matches its avatar's picture to.
  bool skin_colour = true;
  void Check() const;
};

struct TrackedFrame {
  FaceObservation face;
  bool fitted = false;
  bool with_depth = false;  // fitted (or tried) by the RGB-D fit
  // RGB-D identity calibration: this frame was fitted with a free shape. The
  // offline pass fits such frames again once the identity is frozen.
  bool identity_frame = false;
  bool identity_frozen_now = false;  // this frame completed the RGB-D identity
  // Background identity: fitted with the identity not yet made (neutral shape at first).
  bool provisional_identity = false;
  double landmarks_ms = 0;     // detection/tracking + landmarks
  double fit_ms = 0;           // head-model fit
  double depth_ms = 0;         // RGB-D: depth made on demand (stereo matching in the face's box)
  cv::Mat depth_m;             // RGB-D: the depth the fit read
  double rgbd_accuracy_m = 0;  // RGB-D: point-to-mesh RMS after the fit
  int contour_rejected = 0;    // RGB-D: contour landmarks taken for background
  int rigid_points = 0;        // rigid points followed by optical flow into this frame's fit
  // With an anchor (SetAnchor): the frame was fitted again with its
  // placement held to the references; how far the alignment moved the
  // points, and the time it all took (within fit_ms).
  bool anchored = false;
  double anchor_shift_px = 0;
  double anchor_ms = 0;
  Landmarks2d model_landmarks{};  // fitted: the fitted model's 68 landmarks in the frame (pixels)
  std::string problem;            // why not fitted, when a fit failed
};

// Rigid points seen in a reference frame (`reference`: head-frame points and
// their pixels there) found in `gray` by pyramidal Lucas-Kanade, starting at
// `predicted` (one per point); those whose flow back misses their start are dropped.
RigidObservations FollowRigidPoints(const RigidObservations& reference, const cv::Mat& reference_gray,
                                    const cv::Mat& gray, const std::vector<Eigen::Vector2d>& predicted);

class FrameTracker {
 public:
  FrameTracker(const HeadModel& model, const FrameTrackerOptions& options = {});
  ~FrameTracker();

  // The person's shape (beta). `frozen`: RGB-D frames do not calibrate it.
  void SetIdentity(const Eigen::VectorXd& shape, bool frozen = true);
  const Eigen::VectorXd& identity() const { return identity_; }
  bool identity_frozen() const { return identity_frozen_; }

  // Holds each colour frame's head placement to these references (an
  // avatar's, ReadAvatarAnchorReference) as the offline pass held the
  // avatar's training frames: the landmark fit, then the pose aligned to the
  // references' grey levels, then the frame fitted again with the aligned
  // points at the references' weight. A frame whose alignment fails or moves
  // the points too far keeps its landmark fit. The points follow the identity
  // (SetIdentity remakes them). Throws std::invalid_argument when the
  // references do not match the points their options make.
  void SetAnchor(const AnchorReference& reference);
  bool anchored() const { return anchor_ != nullptr; }

  // Tracks one frame; `depth_m` empty for colour-only frames, or
  // `depth_on_demand` asked for depth in the face's box once the landmarks
  // are found (stereo). On success *params holds the frame's expression, jaw
  // and cam_from_head (the caller stamps sequence, time and confidence). No
  // face or a failed fit marks the tracker cold: the next face starts from PnP
  // with a neutral expression.
  TrackedFrame Track(const cv::Mat& bgr, const cv::Mat& depth_m, double time_s, const PinholeCamera& camera,
                     FrameParams* params, const DepthOnDemand* depth_on_demand = nullptr);
  // Track's first half: the face and its landmarks on the frame.
  FaceObservation Observe(const cv::Mat& bgr, double time_s);
  // The same with the face already observed (Observe, or a recorded track
  // smoothed offline, SmoothTrackTwoSided): only the fit runs; landmarks_ms
  // stays 0.
  TrackedFrame TrackObserved(const cv::Mat& bgr, const cv::Mat& depth_m, const FaceObservation& face,
                             const PinholeCamera& camera, FrameParams* params,
                             const DepthOnDemand* depth_on_demand = nullptr);

  // RGB-D: fits `landmarks` and `depth_m` again with the frozen identity,
  // warm from `previous` when given (frames held during identity calibration).
  RgbdFitResult RefitRgbd(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera,
                          const RgbdFitResult* previous);

  // RGB-D: freezes the identity at the median of the shapes collected so far
  // (an input shorter than rgbd_identity_frames); false when there are none.
  bool FreezeRgbdIdentity();

  // Forgets the previous frame (cold start) and the face track.
  void Reset();

  const HeadFitter& fitter() const { return fitter_; }
  const HeadModel& model() const { return model_; }

 private:
  const HeadModel& model_;
  FrameTrackerOptions options_;
  FaceTracker faces_;
  HeadFitter fitter_;
  // Made at the first frame with depth: their bases are large (ICT-FaceKit:
  // ~100 MB each), and colour-only tracking never needs them.
  RgbdFitter& Rgbd(bool calibrating);
  std::unique_ptr<RgbdFitter> rgbd_calibrating_, rgbd_;
  std::unique_ptr<BackgroundIdentity> background_;  // live: until the identity is made
  Eigen::VectorXd identity_;
  bool identity_frozen_ = false;
  std::vector<Eigen::VectorXd> calibration_shapes_;
  RgbdFitResult last_rgbd_;
  FrameParams last_;
  // The photometric anchor (SetAnchor): the points made for the identity
  // with their references, and a fitter holding the pose to them.
  void MakeAnchor(const AnchorReference& reference);
  void AnchorFrame(const cv::Mat& bgr, const FaceObservation& face, const PinholeCamera& camera, TrackedFrame* r);
  std::unique_ptr<PhotometricAnchor> anchor_;
  std::unique_ptr<HeadFitter> anchor_fitter_;
  // Rigid points: the frame they were taken in and where they were seen there.
  cv::Mat reference_gray_;
  RigidObservations reference_;
};

// The person's shape for tracking: from an avatar (.hcavatar: the identity it
// was trained with, so the fit agrees with the avatar) or a PARAMS.json
// (headcast-fit-mesh). Throws naming the file when it is unreadable or made
// for another head model.
Eigen::VectorXd ReadTrackingIdentity(const std::string& path, const HeadModel& model);

// The camera contract an avatar file (.hcavatar) records, if any; nothing for
// other files. Throws naming the file when it is unreadable or the contract malformed.
std::optional<CameraContract> ReadAvatarCameraContract(const std::string& path);

// The rules an avatar file's (.hcavatar) training masks were cut by (its
// matte's), if it records them; nothing for other files. Throws naming the
// file when it is unreadable or the rules malformed.
std::optional<MatteRules> ReadAvatarMatteRules(const std::string& path);

// The photometric anchor's references an avatar file (.hcavatar) carries (its
// training frames were fitted to them), if any; nothing for other files.
// Throws naming the file when it is unreadable or the references malformed.
std::optional<AnchorReference> ReadAvatarAnchorReference(const std::string& path);

// How an avatar file's (.hcavatar) training frames were fitted, to fit live
// frames the same way: the settings it carries, or ExpressionFitSettings::Legacy()
// for a file from before they travelled; nothing for other files. Throws naming
// the file when it is unreadable or the settings malformed.
std::optional<ExpressionFitSettings> ReadAvatarExpressionFit(const std::string& path);

// Where the RGB-D fit reads depth around these landmarks: their span with a
// margin and the forehead above (more than the fit's own cloud box takes).
cv::Rect DepthBoxForFit(const Landmarks2d& landmarks, const cv::Size& image);

// An RGB-D fit as the frame parameters the sender streams.
void ApplyRgbdFit(const RgbdFitResult& fit, FrameParams* params);

}  // namespace headcast
