// A square cut from a frame and its camera: the dataset's crops and a live
// frame cut the same way (the sender measuring what the training masks showed).
#pragma once

#include <opencv2/core.hpp>

#include "common/core/camera.h"

namespace headcast {

// The crop box's intrinsics: `camera` (full frame) cut to the square at
// (x0, y0) with edge `side` pixels, resized to `resolution`.
PinholeCamera CropIntrinsics(const PinholeCamera& camera, double x0, double y0, double side, int resolution);
// The square crop of `image` at (x0, y0, side) source pixels, resized to
// resolution²; outside the frame is black. Pixel centres as in CropIntrinsics.
cv::Mat CropSquare(const cv::Mat& image, double x0, double y0, double side, int resolution, int interpolation);

}  // namespace headcast
