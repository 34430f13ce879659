// Landmark failures caught between frames: each region's points (brows,
// eyes, mouth) are carried from the previous frame by optical flow; where the
// shape predictor's points disagree with them far more than its jitter while
// the flow is sure of itself, the region is disputed: the predictor jumped (a
// wide "O" mouth it puts far above the lips, brows it moves onto an eyelid
// crease) — or it came back from such a jump. Disputed regions are counted,
// and the carried points stand in for the predictor's (`repair`): right when
// the previous frame was, wrong when it was the jump. On talking_d10 that
// mends more frames than it spoils (bench/results/fidelity_ablation.md).
#pragma once

#include <array>
#include <opencv2/core.hpp>

#include "common/tracking/head_fitter.h"

namespace headcast {

enum class LandmarkRegion { kRightBrow, kLeftBrow, kRightEye, kLeftEye, kMouth };
constexpr int kNumRepairRegions = 5;
const char* LandmarkRegionName(LandmarkRegion region);  // "right_brow", ..., "mouth"

struct LandmarkRepairOptions {
  bool enabled = true;  // look for disputed regions at all
  bool repair = true;   // use the carried points in a disputed region
  // A region's mean disagreement between the predictor and the flow, as a
  // share of the outer-eye-corner distance, beyond which the predictor failed.
  double max_disagreement = 0.08;
  double max_flow_error_px = 1.0;  // a point's forward-backward flow error, pixels, within which the flow is sure
  double min_sure_share = 0.7;     // the share of a region's points that must be sure for a repair
  // Repairs in a row a region may have before the predictor is trusted again:
  // flow drifts.
  int max_frames = 15;
  // The eyes too. Off by default: lids close in two or three frames, faster
  // than the flow follows them, and a repair would hold a blinking eye open.
  bool eyes = false;
  void Check() const;
};

class LandmarkRepair {
 public:
  explicit LandmarkRepair(const LandmarkRepairOptions& options = {});
  // A bit (1 << region) per region.
  struct Regions {
    unsigned disputed = 0, repaired = 0;
  };
  // Checks `landmarks` (this frame's, from the predictor; replaced in the
  // repaired regions) against `previous` (last frame's, as used) carried by
  // flow from `previous_gray` to `gray` (same size, 8-bit).
  Regions Check(const cv::Mat& previous_gray, const Landmarks2d& previous, const cv::Mat& gray, Landmarks2d* landmarks);
  void Reset() { runs_.fill(0); }  // a new face: no run of repairs goes on

 private:
  LandmarkRepairOptions options_;
  std::array<int, kNumRepairRegions> runs_{};
};

}  // namespace headcast
