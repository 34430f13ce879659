// The iris in the eye region the 68 landmarks give: the eye is resampled
// upright at a fixed size, and the iris centre is the point the image
// gradients inside the lids converge on (dark-to-bright edges point away from
// it), weighted toward dark pixels. Closed eyes give no iris.
#pragma once

#include <Eigen/Core>
#include <array>
#include <opencv2/core.hpp>

#include "common/tracking/head_fitter.h"

namespace headcast {

struct IrisLocatorOptions {
  // The eye, corner to corner, is resampled to this many pixels: the search
  // costs the same for every face size, and small faces are enlarged.
  int eye_width_px = 40;
  // Eye opening (mean lid distance over corner distance) below which the eye
  // counts as closed and no iris is reported.
  double min_opening = 0.14;
  // Gradients weaker than this fraction of the strongest in the eye are noise.
  double gradient_threshold = 0.2;
  // The iris radius over the corner distance (~6 mm of ~30 mm): only edges
  // about this far from a candidate centre vote for it, not the far lid line.
  double iris_radius = 0.2;
  void Check() const;
};

struct IrisObservation {
  bool found = false;
  Eigen::Vector2d center = Eigen::Vector2d::Zero();  // image pixels
  double opening = 0;                                // lid distance over corner distance (landmarks)
};

// The subject's own left eye is landmarks 42..47, the right 36..41.
struct EyeIrises {
  IrisObservation left, right;
};

// `gray` is CV_8U. Never throws for any landmarks (off-image or degenerate eyes are not found).
IrisObservation LocateIris(const cv::Mat& gray, const std::array<Eigen::Vector2d, 6>& eye,
                           const IrisLocatorOptions& options = {});
EyeIrises LocateIrises(const cv::Mat& gray, const Landmarks2d& landmarks, const IrisLocatorOptions& options = {});

// The iris in the eye's own frame: origin at the corners' midpoint, x along
// the corners (from landmark 36 to 39, or 42 to 45), both in units of the
// corner distance. What compares gaze between two pictures of one face.
Eigen::Vector2d IrisInEyeFrame(const Eigen::Vector2d& iris, const std::array<Eigen::Vector2d, 6>& eye);

// Landmarks first..first+5 (36 or 42).
std::array<Eigen::Vector2d, 6> EyeLandmarks(const Landmarks2d& landmarks, int first);

}  // namespace headcast
