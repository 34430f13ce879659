// ZED2-style RGB-D from side-by-side stereo: the camera is a UVC device whose
// frames hold the left and right images side by side. They are split,
// rectified with a calibration, matched with StereoSGBM (optionally WLS
// filtered) and turned into metric depth aligned to the rectified left image.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "common/capture/frame_source.h"

namespace headcast {

// Left/right intrinsics and distortion plus the pose of the right camera in
// the left one's frame (X_right = R X_left + T, metres), for one eye's image size.
struct StereoCalibration {
  cv::Size size;
  cv::Mat K1, D1, K2, D2, R, T;
  void Check() const;  // throws naming the bad or missing field
};

// Reads OpenCV YAML/XML (keys image_width, image_height, K1, D1, K2, D2, R, T;
// T in metres) or a ZED factory calibration file (SN<serial>.conf, as
// downloaded from calib.stereolabs.com: sections [LEFT_CAM_<res>],
// [RIGHT_CAM_<res>] with fx fy cx cy k1 k2 p1 p2 k3, and [STEREO] with
// Baseline (mm), TY, TZ (mm), RX_<res>, CV_<res>, RZ_<res> (radians)).
// `resolution` picks the section of a .conf: 2K, FHD, HD or VGA.
StereoCalibration ReadStereoCalibration(const std::string& path, const std::string& resolution = "HD");

struct StereoMatchOptions {
  int min_disparity = 0;
  int max_disparity = 128;  // pixels at the matching resolution; the range rounded up to a multiple of 16
  int block_size = 5;
  bool wls_filter = true;
  double wls_lambda = 8000, wls_sigma_color = 1.5;
  void Check() const;
};

// Disparity of a rectified pair, CV_32F pixels, 0 where unknown.
cv::Mat ComputeDisparity(const cv::Mat& left, const cv::Mat& right, const StereoMatchOptions& options);

class StereoDepth {
 public:
  // `scale`: disparity is computed at this fraction of the size (speed).
  StereoDepth(const StereoCalibration& calibration, double scale, bool wls_filter, double min_depth_m = 0.25);
  // Splits nothing: takes the left and right images (calibration size).
  void Compute(const cv::Mat& left, const cv::Mat& right, cv::Mat* left_rectified, cv::Mat* depth_m) const;
  // The rectified left image alone.
  cv::Mat RectifyLeft(const cv::Mat& left) const;
  // Depth inside `box` of the rectified left image (the rest 0): only the
  // rows of the box, and the columns a match for it can come from, are
  // rectified (right) and matched. `right` is the raw right image. With
  // near_m < far_m only disparities of that depth range are searched.
  cv::Mat ComputeIn(const cv::Mat& left_rectified, const cv::Mat& right, const cv::Rect& box, double near_m = 0,
                    double far_m = 0) const;
  const PinholeCamera& camera() const { return camera_; }  // of the rectified left image
  double baseline_m() const { return baseline_; }

 private:
  StereoCalibration calib_;
  double scale_;
  StereoMatchOptions match_;
  cv::Mat map1x_, map1y_, map2x_, map2y_;
  PinholeCamera camera_;
  double baseline_ = 0;
};

// Side-by-side frames from another source (camera, video, folder) turned into
// the rectified left image, with depth on demand (CapturedFrame::depth_on_demand).
class StereoDepthSource final : public FrameSource {
 public:
  StereoDepthSource(std::unique_ptr<FrameSource> side_by_side, const StereoCalibration& calibration,
                    const SourceOptions& options);
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override { return "stereo depth from " + inner_->Describe(); }
  double fps() const override { return inner_->fps(); }
  bool has_depth() const override { return true; }

 private:
  std::unique_ptr<FrameSource> inner_;
  std::shared_ptr<const StereoDepth> depth_;  // shared with the frames' depth on demand
  cv::Size eye_;
};

}  // namespace headcast
