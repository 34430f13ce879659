// FaceTracker: dlib's HOG face detector on a downscaled frame, then the face
// box followed from the previous landmarks (the detector runs only on loss or
// periodically), dlib's 68-point shape predictor, and One-Euro filtering of the
// landmarks. Per-frame outcomes are statuses, never exceptions.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "common/tracking/head_fitter.h"
#include "common/tracking/iris_locator.h"
#include "common/tracking/landmark_repair.h"

namespace headcast {

struct FaceTrackerOptions {
  std::string predictor_path = "/usr/share/dlib/shape_predictor_68_face_landmarks.dat";
  int detect_width = 320;      // the detector sees the frame scaled to this width (at most 2x up), pixels
  int redetect_interval = 30;  // while tracking the detector runs every this many frames (1: every frame)
  // While tracking, the box handed to the shape predictor is drawn around the
  // previous landmarks with the margins the detector's own box had at the last
  // detection. The predictor was trained on detector boxes: a box of another
  // convention makes it see a bigger (or smaller) face each frame, and the
  // landmarks drift until the next detection. Off: fixed margins (comparisons).
  bool box_from_detection = true;
  double min_face_px = 40;  // smaller faces are ignored, pixels (full frame)
  // The shape predictor runs on this many views of the face and each landmark
  // is the median of its views: the box as found, the frame mirrored (each
  // point taken back to its own side), then the box 6 % smaller and larger,
  // mirrored and not (kMaxPredictorViews in all). The predictor's cascade
  // starts from its mean shape placed in the box, and its errors differ from
  // view to view; 1: the box as found only.
  int predictor_views = 1;
  // Which points take the views' median, the others the box's own: "all";
  // "no-eyes" (the eyes' from the box); "outline" (only the jaw line and the
  // nose, the points that hold the pose and cut the masks). The median pulls a
  // wide stare, shut lids or a frown toward the predictor's mean shape.
  std::string predictor_views_points = "all";
  bool TakesTheViewsMedian(int landmark) const;
  // While tracking, landmarks whose width changes by more than this factor
  // since the previous frame, or whose centre moves by more than this share
  // of the face's width in a frame, mean the box slipped off the face: the
  // detector runs again in that frame.
  double max_tracked_scale_change = 1.25;
  double max_tracked_shift = 0.35;
  // A slower creep (the landmarks shrinking onto the lower face a few percent
  // a frame) shows against the last detection: width or height changed by
  // more than this factor since then makes the detector check the face.
  double max_scale_change_since_detection = 1.1;
  double filter_min_cutoff = 1.5;  // One-Euro: Hz at rest (lower: steadier)
  double filter_beta = 0.05;       // One-Euro: speed coefficient (higher: less lag when moving)
  // false: landmarks and irises as found, unfiltered (an offline pass that
  // smooths the whole track afterwards, SmoothTrackTwoSided).
  bool filter = true;
  bool locate_irises = true;  // the irises in the eyes the landmarks give (gaze), filtered like them
  IrisLocatorOptions iris;
  LandmarkRepairOptions repair;  // predictor jumps caught by flow from the previous frame
  void Check() const;
};

constexpr int kMaxPredictorViews = 6;
inline const std::vector<std::string> kPredictorViewsPoints = {"all", "no-eyes", "outline"};

// The landmark that point l of dlib's 68 becomes in the mirrored image (the
// left eye's outer corner the right eye's, the jaw read the other way round).
int MirroredLandmark(int l);

enum class FaceStatus { kDetected, kTracked, kNoFace };
const char* FaceStatusName(FaceStatus s);

struct FaceObservation {
  FaceStatus status = FaceStatus::kNoFace;
  Landmarks2d landmarks{};  // filtered, pixels
  Landmarks2d raw{};        // as the predictor gave them
  EyeIrises irises;         // filtered; not found when closed, or not looked for
  cv::Rect box;
  int faces_detected = 0;  // faces the detector saw (when it ran)
  bool recovered = false;  // tracking slipped in this frame and the detector found the face again
  // A bit (1 << LandmarkRegion) per region whose predicted points disagreed
  // with the flow from the previous frame, and per region whose points were
  // then carried by it (`raw` holds the carried ones; LandmarkRepairOptions::repair).
  unsigned disputed = 0, repaired = 0;
};

class FaceTracker {
 public:
  // Throws std::runtime_error naming the file if the shape predictor cannot be read.
  explicit FaceTracker(const FaceTrackerOptions& options = {});
  ~FaceTracker();
  FaceObservation Track(const cv::Mat& image_bgr, double time_s);
  void Reset();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// One-Euro filter (Casiez et al. 2012) for one value.
class OneEuroFilter {
 public:
  OneEuroFilter(double min_cutoff, double beta, double derivative_cutoff = 1.0)
      : min_cutoff_(min_cutoff), beta_(beta), d_cutoff_(derivative_cutoff) {}
  double Filter(double value, double time_s);
  void Reset() { initialised_ = false; }

 private:
  double min_cutoff_, beta_, d_cutoff_;
  bool initialised_ = false;
  double x_ = 0, dx_ = 0, t_ = 0;
};

// A recorded face track smoothed without lag: each landmark and iris
// coordinate through the One-Euro filter forwards and backwards in time, the
// two averaged (their lags cancel). A live tracker can only filter forwards,
// which draws a moving face where it was a frame or two before. Reads `raw`
// and the irises as found; writes `landmarks` and the irises' centres. A
// frame without a face (or an iris not found) ends a run: runs are smoothed
// apart. `times_s` has one entry per observation, increasing.
void SmoothTrackTwoSided(std::vector<FaceObservation>* track, const std::vector<double>& times_s, double min_cutoff,
                         double beta);

}  // namespace headcast
