#include "training/temporal_agreement.h"

#include <cmath>
#include <stdexcept>

namespace headcast {

void TemporalAgreement::Add(int frame_number, const cv::Mat& truth_bgr, const cv::Mat& avatar_bgr) {
  if (truth_bgr.type() != CV_8UC3 || avatar_bgr.type() != CV_8UC3 || truth_bgr.size() != avatar_bgr.size())
    throw std::invalid_argument("TemporalAgreement: wants two 8-bit BGR pictures of one size");
  cv::Mat truth, avatar;
  truth_bgr.convertTo(truth, CV_32FC3, 1.0 / 255);
  avatar_bgr.convertTo(avatar, CV_32FC3, 1.0 / 255);
  if (!last_truth_.empty() && frame_number == last_frame_ + 1 && truth.size() == last_truth_.size()) {
    const cv::Mat dt = truth - last_truth_, da = avatar - last_avatar_;
    const cv::Mat de = da - dt;
    error_sq_ += de.dot(de);
    truth_sq_ += dt.dot(dt);
    avatar_sq_ += da.dot(da);
    values_ += static_cast<double>(truth.total()) * truth.channels();
    ++pairs_;
  }
  last_frame_ = frame_number;
  last_truth_ = truth;
  last_avatar_ = avatar;
}

nlohmann::json TemporalAgreement::Summary() const {
  nlohmann::json j = {{"pairs", pairs_},
                      {"how",
                       "consecutive frames: PSNR of the avatar's frame-to-frame change against the truth's (dB), and "
                       "the ratio of their rms changes (above 1: the avatar moves more than the person)"},
                      {"change_psnr_db", nullptr},
                      {"motion_ratio", nullptr}};
  if (pairs_ == 0) return j;
  j["change_psnr_db"] = 10 * std::log10(1.0 / std::max(error_sq_ / values_, 1e-12));
  if (truth_sq_ > 0) j["motion_ratio"] = std::sqrt(avatar_sq_ / truth_sq_);
  return j;
}

}  // namespace headcast
