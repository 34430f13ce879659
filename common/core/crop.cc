#include "common/core/crop.h"

#include <opencv2/imgproc.hpp>

namespace headcast {

PinholeCamera CropIntrinsics(const PinholeCamera& camera, double x0, double y0, double side, int resolution) {
  const double s = resolution / side;
  PinholeCamera k = camera;
  k.width = k.height = resolution;
  k.fx = camera.fx * s;
  k.fy = camera.fy * s;
  // Pixel centres: a source pixel u maps to (u + 0.5 - x0) * s - 0.5.
  k.cx = (camera.cx + 0.5 - x0) * s - 0.5;
  k.cy = (camera.cy + 0.5 - y0) * s - 0.5;
  return k;
}

cv::Mat CropSquare(const cv::Mat& image, double x0, double y0, double side, int resolution, int interpolation) {
  const double s = resolution / side;
  cv::Matx23d affine(s, 0, -x0 * s, 0, s, -y0 * s);
  // Map pixel centres (see CropIntrinsics).
  affine(0, 2) += 0.5 * s - 0.5;
  affine(1, 2) += 0.5 * s - 0.5;
  cv::Mat out;
  cv::warpAffine(image, out, affine, cv::Size(resolution, resolution), interpolation, cv::BORDER_CONSTANT,
                 cv::Scalar::all(0));
  return out;
}

}  // namespace headcast
