// Flow-based frame interpolation.
#include "training/interpolation.h"

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace headcast {

FlowPair DenseFlow(const cv::Mat& a_bgr, const cv::Mat& b_bgr) {
  cv::Mat a, b;
  cv::cvtColor(a_bgr, a, cv::COLOR_BGR2GRAY);
  cv::cvtColor(b_bgr, b, cv::COLOR_BGR2GRAY);
  FlowPair f;
  // Pyramid 0.5 x 4 levels, window 15: faces move a few pixels per frame at these sizes.
  cv::calcOpticalFlowFarneback(a, b, f.forward, 0.5, 4, 15, 3, 5, 1.2, 0);
  cv::calcOpticalFlowFarneback(b, a, f.backward, 0.5, 4, 15, 3, 5, 1.2, 0);
  return f;
}

namespace {

// `image` sampled at x + scale * flow(x).
cv::Mat Warp(const cv::Mat& image, const cv::Mat& flow, double scale) {
  cv::Mat map(flow.size(), CV_32FC2);
  for (int y = 0; y < flow.rows; ++y)
    for (int x = 0; x < flow.cols; ++x) {
      const cv::Vec2f d = flow.at<cv::Vec2f>(y, x);
      map.at<cv::Vec2f>(y, x) = cv::Vec2f(static_cast<float>(x + scale * d[0]), static_cast<float>(y + scale * d[1]));
    }
  cv::Mat out;
  cv::remap(image, out, map, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

}  // namespace

cv::Mat InterpolateImage(const cv::Mat& a, const cv::Mat& b, const FlowPair& flow, double t) {
  CV_Assert(a.size() == b.size() && a.type() == b.type() && flow.forward.size() == a.size());
  // A pixel x at time t came from about x - t * forward in a, and is about x - (1 - t) * backward in b.
  const cv::Mat from_a = Warp(a, flow.forward, -t);
  const cv::Mat from_b = Warp(b, flow.backward, -(1 - t));
  cv::Mat out;
  cv::addWeighted(from_a, 1 - t, from_b, t, 0, out);
  return out;
}

}  // namespace headcast
