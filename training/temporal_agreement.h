// How an avatar's pictures change from frame to frame against how the true
// frames change: what a viewer sees as shaking or flicker, which the
// per-frame figures (PSNR, SSIM) do not see. A steady error (a face drawn a
// little off in every frame) cancels in the frame-to-frame change; an error
// that comes and goes with each frame (a head that jitters around the true
// one, lids that flicker) does not.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

namespace headcast {

class TemporalAgreement {
 public:
  // One frame of a sequence: its number in the video, the true picture and
  // the avatar's (same size, 8-bit BGR). Consecutive calls whose frame
  // numbers follow each other (n, n + 1) make a pair; a gap, a size change or
  // a first frame only starts a new run.
  void Add(int frame_number, const cv::Mat& truth_bgr, const cv::Mat& avatar_bgr);
  int pairs() const { return pairs_; }
  // Over the pairs' pixels (RGB in 0..1): the PSNR of the avatar's change
  // against the truth's, 10 log10(1 / mean((A_t - A_t-1) - (T_t - T_t-1))^2),
  // dB; and the ratio of their rms changes (above 1: the avatar moves more
  // than the person). Null figures without a pair.
  nlohmann::json Summary() const;

 private:
  int last_frame_ = 0;
  cv::Mat last_truth_, last_avatar_;  // CV_32FC3, 0..1
  int pairs_ = 0;
  double values_ = 0;  // pixels x channels summed over the pairs
  double error_sq_ = 0, truth_sq_ = 0, avatar_sq_ = 0;
};

}  // namespace headcast
