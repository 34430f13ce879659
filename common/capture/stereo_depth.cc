// Stereo depth with OpenCV.
#include "common/capture/stereo_depth.h"

#include <cmath>
#include <fstream>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/disparity_filter.hpp>
#include <sstream>
#include <stdexcept>

#include "common/core/options.h"

namespace headcast {

void StereoCalibration::Check() const {
  auto need = [](const cv::Mat& m, int rows, int cols, const char* name) {
    if (m.empty() || m.rows * m.cols != rows * cols)
      throw std::invalid_argument(std::string("stereo calibration: ") + name + " must have " +
                                  std::to_string(rows * cols) + " values");
    if (!cv::checkRange(m)) throw std::invalid_argument(std::string("stereo calibration: ") + name + " is not finite");
  };
  if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("stereo calibration: image size missing");
  need(K1, 3, 3, "K1");
  need(K2, 3, 3, "K2");
  need(R, 3, 3, "R");
  need(T, 3, 1, "T");
  if (D1.total() > 14 || D2.total() > 14) throw std::invalid_argument("stereo calibration: too many distortion terms");
  if (cv::norm(T) <= 0 || cv::norm(T) > 2) throw std::invalid_argument("stereo calibration: |T| must be 0..2 m");
}

namespace {

StereoCalibration ReadZedConf(const std::string& path, const std::string& resolution) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::map<std::string, std::map<std::string, double>> ini;
  std::string section, line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#' || line[0] == ';') continue;
    if (line[0] == '[') {
      section = line.substr(1, line.find(']') - 1);
      continue;
    }
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    try {
      ini[section][line.substr(0, eq)] = std::stod(line.substr(eq + 1));
    } catch (const std::exception&) {
      throw std::runtime_error(path + ": [" + section + "] " + line.substr(0, eq) + " is not a number");
    }
  }
  static const std::map<std::string, cv::Size> sizes = {
      {"2K", {2208, 1242}}, {"FHD", {1920, 1080}}, {"HD", {1280, 720}}, {"VGA", {672, 376}}};
  if (!sizes.count(resolution)) throw std::runtime_error("stereo resolution must be 2K, FHD, HD or VGA");
  auto get = [&](const std::string& s, const std::string& k) {
    auto it = ini.find(s);
    if (it == ini.end() || !it->second.count(k)) throw std::runtime_error(path + ": no " + k + " in [" + s + "]");
    return it->second.at(k);
  };
  StereoCalibration c;
  c.size = sizes.at(resolution);
  auto camera = [&](const std::string& s, cv::Mat* K, cv::Mat* D) {
    *K = (cv::Mat_<double>(3, 3) << get(s, "fx"), 0, get(s, "cx"), 0, get(s, "fy"), get(s, "cy"), 0, 0, 1);
    *D = (cv::Mat_<double>(1, 5) << get(s, "k1"), get(s, "k2"), get(s, "p1"), get(s, "p2"), get(s, "k3"));
  };
  camera("LEFT_CAM_" + resolution, &c.K1, &c.D1);
  camera("RIGHT_CAM_" + resolution, &c.K2, &c.D2);
  const cv::Mat rvec = (cv::Mat_<double>(3, 1) << get("STEREO", "RX_" + resolution), get("STEREO", "CV_" + resolution),
                        get("STEREO", "RZ_" + resolution));
  cv::Rodrigues(rvec, c.R);
  // The right camera sits Baseline mm along +x of the left one: X_right = R X_left + T with T = -(B, TY, TZ).
  c.T = (cv::Mat_<double>(3, 1) << -get("STEREO", "Baseline"), -get("STEREO", "TY"), -get("STEREO", "TZ")) / 1000.0;
  return c;
}

}  // namespace

StereoCalibration ReadStereoCalibration(const std::string& path, const std::string& resolution) {
  StereoCalibration c;
  if (path.size() > 5 && path.substr(path.size() - 5) == ".conf") {
    c = ReadZedConf(path, resolution);
  } else {
    cv::FileStorage fs;
    try {
      fs.open(path, cv::FileStorage::READ);
    } catch (const cv::Exception& e) {
      throw std::runtime_error(path + ": not an OpenCV YAML/XML file (" + e.err + ")");
    }
    if (!fs.isOpened()) throw std::runtime_error(path + ": cannot open the stereo calibration");
    int w = 0, h = 0;
    fs["image_width"] >> w;
    fs["image_height"] >> h;
    c.size = cv::Size(w, h);
    fs["K1"] >> c.K1;
    fs["D1"] >> c.D1;
    fs["K2"] >> c.K2;
    fs["D2"] >> c.D2;
    fs["R"] >> c.R;
    fs["T"] >> c.T;
  }
  for (cv::Mat* m : {&c.K1, &c.D1, &c.K2, &c.D2, &c.R, &c.T})
    if (!m->empty()) m->convertTo(*m, CV_64F);
  if (!c.T.empty()) c.T = c.T.reshape(1, 3);
  try {
    c.Check();
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  return c;
}

void StereoMatchOptions::Check() const {
  OptionsCheck c("StereoMatchOptions");
  c.InRange("max_disparity", max_disparity, 16, 1024).InRange("block_size", block_size, 1, 31);
  c.InRange("min_disparity", min_disparity, 0, max_disparity - 1);
  c.That(block_size % 2 == 1, "block_size must be odd");
  c.Positive("wls_lambda", wls_lambda).Positive("wls_sigma_color", wls_sigma_color);
  c.ThrowIfErrors();
}

cv::Mat ComputeDisparity(const cv::Mat& left, const cv::Mat& right, const StereoMatchOptions& o) {
  o.Check();
  if (left.empty() || left.size() != right.size() || left.type() != right.type())
    throw std::invalid_argument("ComputeDisparity: the images must be non-empty and of one size and type");
  const int num = (o.max_disparity - o.min_disparity + 15) / 16 * 16;
  const int channels = left.channels();
  auto sgbm = cv::StereoSGBM::create(o.min_disparity, num, o.block_size, 8 * channels * o.block_size * o.block_size,
                                     32 * channels * o.block_size * o.block_size, 1, 63, 10, 100, 2,
                                     cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat raw, out;
  sgbm->compute(left, right, raw);  // CV_16S, 1/16 pixel
  if (o.wls_filter) {
    auto wls = cv::ximgproc::createDisparityWLSFilter(sgbm);
    auto right_matcher = cv::ximgproc::createRightMatcher(sgbm);
    cv::Mat raw_right, filtered;
    right_matcher->compute(right, left, raw_right);
    wls->setLambda(o.wls_lambda);
    wls->setSigmaColor(o.wls_sigma_color);
    wls->filter(raw, left, filtered, raw_right);
    raw = filtered;
  }
  raw.convertTo(out, CV_32F, 1.0 / 16);
  // SGBM marks unknown as min_disparity - 1.
  out.setTo(0, (out < static_cast<float>(o.min_disparity)) | (out <= 0));
  return out;
}

StereoDepth::StereoDepth(const StereoCalibration& calibration, double scale, bool wls_filter, double min_depth_m)
    : calib_(calibration), scale_(scale) {
  calib_.Check();
  if (!(scale > 0 && scale <= 1)) throw std::invalid_argument("stereo depth scale must be in (0, 1]");
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(calib_.K1, calib_.D1, calib_.K2, calib_.D2, calib_.size, calib_.R, calib_.T, R1, R2, P1, P2, Q,
                    cv::CALIB_ZERO_DISPARITY, 0);
  cv::initUndistortRectifyMap(calib_.K1, calib_.D1, R1, P1, calib_.size, CV_32FC1, map1x_, map1y_);
  cv::initUndistortRectifyMap(calib_.K2, calib_.D2, R2, P2, calib_.size, CV_32FC1, map2x_, map2y_);
  camera_.fx = P1.at<double>(0, 0);
  camera_.fy = P1.at<double>(1, 1);
  camera_.cx = P1.at<double>(0, 2);
  camera_.cy = P1.at<double>(1, 2);
  camera_.width = calib_.size.width;
  camera_.height = calib_.size.height;
  baseline_ = std::abs(P2.at<double>(0, 3) / P2.at<double>(0, 0));
  match_.wls_filter = wls_filter;
  // Enough disparity range for anything nearer than min_depth_m.
  match_.max_disparity =
      std::clamp(static_cast<int>(std::ceil(camera_.fx * baseline_ / min_depth_m * scale_)), 16, 512);
}

void StereoDepth::Compute(const cv::Mat& left, const cv::Mat& right, cv::Mat* left_rectified, cv::Mat* depth_m) const {
  if (left.size() != calib_.size || right.size() != calib_.size)
    throw std::invalid_argument("stereo: images are " + std::to_string(left.cols) + "x" + std::to_string(left.rows) +
                                ", the calibration is for " + std::to_string(calib_.size.width) + "x" +
                                std::to_string(calib_.size.height));
  *left_rectified = RectifyLeft(left);
  *depth_m = ComputeIn(*left_rectified, right, cv::Rect(cv::Point(0, 0), calib_.size));
}

cv::Mat StereoDepth::RectifyLeft(const cv::Mat& left) const {
  if (left.size() != calib_.size)
    throw std::invalid_argument("stereo: the left image is not of the calibration's size");
  cv::Mat out;
  cv::remap(left, out, map1x_, map1y_, cv::INTER_LINEAR);
  return out;
}

cv::Mat StereoDepth::ComputeIn(const cv::Mat& left_rectified, const cv::Mat& right, const cv::Rect& box_asked,
                               double near_m, double far_m) const {
  if (left_rectified.size() != calib_.size || right.size() != calib_.size)
    throw std::invalid_argument("stereo: images are not of the calibration's size");
  cv::Mat depth = cv::Mat::zeros(calib_.size, CV_32F);
  const cv::Rect box = box_asked & cv::Rect(cv::Point(0, 0), calib_.size);
  if (box.width < 8 || box.height < 8) return depth;
  StereoMatchOptions match = match_;
  const double fb_scaled = camera_.fx * baseline_ * scale_;  // disparity at the matching scale times depth
  if (near_m > 0 && far_m > near_m) {
    match.max_disparity = std::clamp(static_cast<int>(std::ceil(fb_scaled / near_m)), 16, match_.max_disparity);
    match.min_disparity = std::clamp(static_cast<int>(std::floor(fb_scaled / far_m)), 0, match.max_disparity - 16);
  }
  // A left pixel x matches right pixels x - d, d < the disparity range: the
  // strip reaches that far left of the box (both images, so columns agree).
  const int reach = static_cast<int>(std::ceil(match.max_disparity / scale_)) + 1;
  const int x0 = std::max(0, box.x - reach);
  const cv::Rect strip(x0, box.y, box.x + box.width - x0, box.height);
  cv::Mat right_rectified;
  cv::remap(right, right_rectified, map2x_(strip), map2y_(strip), cv::INTER_LINEAR);
  cv::Mat l = left_rectified(strip), r = right_rectified;
  if (scale_ < 1) {
    cv::resize(l, l, cv::Size(), scale_, scale_, cv::INTER_AREA);
    cv::resize(r, r, cv::Size(), scale_, scale_, cv::INTER_AREA);
  }
  if (l.cols < 16 || l.rows < 8) return depth;
  cv::Mat disparity = ComputeDisparity(l, r, match);
  if (scale_ < 1) {
    cv::resize(disparity, disparity, strip.size(), 0, 0, cv::INTER_NEAREST);
    disparity /= scale_;
  }
  const float fb = static_cast<float>(camera_.fx * baseline_);
  for (int y = 0; y < box.height; ++y) {
    const float* d = disparity.ptr<float>(y) + (box.x - x0);
    float* z = depth.ptr<float>(box.y + y) + box.x;
    for (int x = 0; x < box.width; ++x) z[x] = d[x] > 0 ? fb / d[x] : 0.f;
  }
  return depth;
}

namespace {

// One frame's stereo pair, matched where the tracker asks.
class StereoFrameDepth final : public DepthOnDemand {
 public:
  StereoFrameDepth(std::shared_ptr<const StereoDepth> depth, cv::Mat left_rectified, cv::Mat right)
      : depth_(std::move(depth)), left_(std::move(left_rectified)), right_(std::move(right)) {}
  cv::Mat DepthIn(const cv::Rect& box, double near_m, double far_m) const override {
    return depth_->ComputeIn(left_, right_, box, near_m, far_m);
  }

 private:
  std::shared_ptr<const StereoDepth> depth_;
  cv::Mat left_, right_;
};

}  // namespace

StereoDepthSource::StereoDepthSource(std::unique_ptr<FrameSource> side_by_side, const StereoCalibration& calibration,
                                     const SourceOptions& options)
    : inner_(std::move(side_by_side)),
      depth_(std::make_shared<const StereoDepth>(calibration, options.depth_scale, options.wls_filter)),
      eye_(calibration.size) {}

ReadStatus StereoDepthSource::Read(CapturedFrame* frame, std::string* problem) {
  CapturedFrame both;
  const ReadStatus s = inner_->Read(&both, problem);
  if (s != ReadStatus::kFrame) return s;
  if (both.bgr.cols != 2 * eye_.width || both.bgr.rows != eye_.height) {
    if (problem)
      *problem = "stereo: a side-by-side frame must be " + std::to_string(2 * eye_.width) + "x" +
                 std::to_string(eye_.height) + " for this calibration, got " + std::to_string(both.bgr.cols) + "x" +
                 std::to_string(both.bgr.rows);
    return ReadStatus::kSkipped;
  }
  const cv::Mat left = both.bgr(cv::Rect(0, 0, eye_.width, eye_.height));
  const cv::Mat right = both.bgr(cv::Rect(eye_.width, 0, eye_.width, eye_.height));
  frame->bgr = depth_->RectifyLeft(left);
  frame->depth_m.release();
  // The right half is copied: an inner source may fill its buffer again on the next read.
  frame->depth_on_demand = std::make_shared<StereoFrameDepth>(depth_, frame->bgr, right.clone());
  frame->capture_time_s = both.capture_time_s;
  frame->index = both.index;
  frame->camera = depth_->camera();
  return ReadStatus::kFrame;
}

}  // namespace headcast
