// Per-pixel loss weights that favour the parts of a face a viewer reads an
// expression from: the eyes with their brows, and the mouth. They are small
// (a few per cent of a head's pixels) and a plain MSE spends an avatar's
// capacity mostly on cheeks, hair and outline.
#pragma once

#include <opencv2/core.hpp>

#include "common/headmodel/head_model.h"

namespace headcast {

struct FaceRegionOptions {
  double weight = 0;  // added to 1 inside a region (0: every pixel weighs 1)
  // Each region's convex hull grown by this fraction of the eye distance, so
  // lids, lashes and lip corners that the 68 points only bound are in.
  double margin = 0.15;
  void Check() const;
};

// CV_32F map of `size`: 1 + weight inside the regions (each eye with its brow,
// the mouth) of the frame's 68 landmarks, 1 elsewhere. Landmarks that are not
// finite, or whose eyes coincide, give all ones.
cv::Mat FaceRegionWeights(const Landmarks2d& landmarks, cv::Size size, const FaceRegionOptions& options);

// CV_8U map of `size`: 255 inside the same regions (options.margin; the
// weight does not matter), 0 elsewhere; all 0 for unusable landmarks.
cv::Mat FaceRegionMask(const Landmarks2d& landmarks, cv::Size size, const FaceRegionOptions& options);

}  // namespace headcast
