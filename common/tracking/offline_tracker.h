// The offline tracking pass (headcast-track, the trainer's prep): every frame
// of a recorded input (or a camera) through the one FrameTracker, with the
// subject's constants found on the way — identity (calibrated over key
// frames, frozen from the first RGB-D frames, or given), camera intrinsics,
// texture and light — head masks, an overlay video and a report.
#pragma once

#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/capture/frame_source.h"
#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/frame_tracker.h"
#include "common/tracking/head_mask.h"
#include "common/tracking/outline_hold.h"
#include "common/tracking/photometric_anchor.h"

namespace headcast {

struct OfflineTrackOptions {
  std::string input;  // what OpenFrameSource opens: a video, image or RGB-D folder, zed:SOURCE, /dev/videoN
  SourceOptions source;
  int max_frames = 0;                       // stop after this many readable frames (0: all)
  double fov_deg = 40;                      // vertical field of view when nothing better is known, degrees
  std::optional<PinholeCamera> intrinsics;  // given intrinsics (else calibration, the source's, or fov_deg)
  // RGB, recorded input: identity (shape) and focal length calibrated over key
  // frames spread over the head's yaw in a first pass (METHOD §2).
  bool calibrate = false;
  // Recorded input: the landmarks and irises of the whole input found first,
  // then smoothed forwards and backwards (SmoothTrackTwoSided, with the face
  // tracker's filter settings) and fitted: no lag, which a live camera's
  // forward-only filter has. For training data: the crops are not lagged.
  bool two_sided_filter = false;
  int calibration_frames = 15;  // key frames at most (calibrate); RGB-D: frames whose median shape is the identity
  Eigen::VectorXd identity;     // a given shape (empty: calibrated, RGB-D, or neutral)
  std::string identity_source;  // where `identity` came from, for the report
  bool fit_appearance = true;   // texture and SH light by the masked photometric fit
  bool masks = false;           // a head mask for every fitted frame, handed to the observer
  HeadMaskOptions mask;
  FrameTrackerOptions tracker;
  std::string overlay;  // MP4 of the frames with detected and fitted landmarks (empty: none)
  // Recorded RGB input: once every frame is fitted, the head's placement is
  // held to its appearance over the clip and each frame fitted again
  // (photometric_anchor.h). Masks and the overlay are the first fits'.
  PhotometricAnchorOptions anchor;
  // With the anchor and masks: the head's pitch also held to the top of the
  // hair's outline in those refits (outline_hold.h).
  OutlineHoldOptions outline;
  // Another way: each frame held to these references (an avatar's) as it is
  // fitted, in the one pass, as the live sender does (FrameTracker::SetAnchor).
  // Needs the identity they were made for.
  std::optional<AnchorReference> anchor_reference;
  void Check() const;
};

// Whether OpenFrameSource reads `input` from a live camera (/dev/videoN, or
// zed:/dev/videoN): it cannot be read twice.
bool IsLiveCameraSource(const std::string& input);

// How the landmarks are taken over time, by name (--landmark-filter of prep and
// headcast-track): "causal" (the live filter), "off" (as found) or "two-sided"
// (two_sided_filter). Throws std::invalid_argument for another name.
inline const std::vector<std::string> kLandmarkFilterModes = {"causal", "off", "two-sided"};
void SetLandmarkFilter(const std::string& mode, OfflineTrackOptions* options);

// One readable frame, as the pass sees it. Frame numbers count readable frames
// from 0 (a corrupt image is skipped and not counted). `mask` is set for
// fitted frames when OfflineTrackOptions::masks.
struct OfflineFrame {
  int index = 0;
  const cv::Mat* bgr = nullptr;
  bool fitted = false;
  cv::Mat mask;
};
using OfflineFrameObserver = std::function<void(const OfflineFrame&)>;

struct OfflineTrack {
  std::vector<FrameParams> frames;  // the fitted frames; sequence = frame number
  SubjectParams subject;            // shape, texture, light and the full frame's intrinsics
  double fps = 30;
  int frames_read = 0;
  nlohmann::json report;  // counts, landmark error, jitter, timing, calibration, appearance
  // The anchor on: the reference grey levels its last round aligned the
  // frames to (what a live tracker holds the head to, FrameTracker::SetAnchor).
  std::optional<AnchorReference> anchor_reference;
};

using FrameSourceFactory = std::function<std::unique_ptr<FrameSource>()>;

// Tracks every frame of options.input. Throws with a clear message when the
// input cannot be opened, has no readable frame, or calibration fails.
OfflineTrack TrackVideo(const HeadModel& model, const OfflineTrackOptions& options,
                        const OfflineFrameObserver& observer = {});

// The same pass over frames from `open` (called once, or twice with
// calibrate); options.input only names the input in messages and the report.
OfflineTrack TrackFrames(const HeadModel& model, const OfflineTrackOptions& options, const FrameSourceFactory& open,
                         const OfflineFrameObserver& observer = {});

}  // namespace headcast
