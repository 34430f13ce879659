// Jitter buffer.
#include "receiver/jitter_buffer.h"

#include <Eigen/Geometry>
#include <algorithm>

#include "common/core/options.h"

namespace headcast {

void JitterBufferOptions::Check() const {
  OptionsCheck c("JitterBufferOptions");
  c.InRange("target_delay_s", target_delay_s, 0, 10).InRange("max_hold_s", max_hold_s, 0, 60);
  c.That(capacity >= 2, "capacity must be >= 2");
  c.ThrowIfErrors();
}

namespace {
Eigen::Vector3f Slerp(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double t) {
  auto quat = [](const Eigen::Vector3f& w) {
    const double angle = w.norm();
    return angle < 1e-12 ? Eigen::Quaterniond::Identity()
                         : Eigen::Quaterniond(Eigen::AngleAxisd(angle, w.cast<double>() / angle));
  };
  const Eigen::AngleAxisd r(quat(a).slerp(t, quat(b)));
  return (r.angle() * r.axis()).cast<float>();
}
}  // namespace

FrameParams InterpolateParams(const FrameParams& a, const FrameParams& b, double t) {
  FrameParams out = t < 0.5 ? a : b;
  if (a.expression.size() == b.expression.size())
    out.expression = ((1 - t) * a.expression.cast<double>() + t * b.expression.cast<double>()).cast<float>();
  out.jaw = Slerp(a.jaw, b.jaw, t);
  out.neck = Slerp(a.neck, b.neck, t);
  out.left_eye = Slerp(a.left_eye, b.left_eye, t);
  out.right_eye = Slerp(a.right_eye, b.right_eye, t);
  out.cam_rotation = Slerp(a.cam_rotation, b.cam_rotation, t);
  out.cam_translation =
      ((1 - t) * a.cam_translation.cast<double>() + t * b.cam_translation.cast<double>()).cast<float>();
  out.capture_time_s = (1 - t) * a.capture_time_s + t * b.capture_time_s;
  out.confidence = static_cast<float>((1 - t) * a.confidence + t * b.confidence);
  return out;
}

JitterBuffer::JitterBuffer(const JitterBufferOptions& options) : options_(options) { options.Check(); }

double JitterBuffer::PlayoutTime(double capture_s) const { return capture_s + offset_ + options_.target_delay_s; }

void JitterBuffer::Push(const FrameParams& f, double arrival_s) {
  std::lock_guard<std::mutex> lock(mutex_);
  const double offset = arrival_s - f.capture_time_s;
  if (!have_offset_ || offset < offset_) offset_ = offset;  // the fastest frame sets the floor
  have_offset_ = true;
  if (played_any_ && f.capture_time_s <= played_capture_s_) {
    ++stats_.late;
    return;
  }
  auto it = std::lower_bound(frames_.begin(), frames_.end(), f.capture_time_s,
                             [](const FrameParams& a, double t) { return a.capture_time_s < t; });
  if (it != frames_.end() && it->sequence == f.sequence) {
    ++stats_.duplicate;
    return;
  }
  frames_.insert(it, f);
  ++stats_.received;
  while (frames_.size() > options_.capacity) frames_.pop_front();
}

std::optional<FrameParams> JitterBuffer::Sample(double now_s) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (frames_.empty() || !have_offset_) return std::nullopt;
  const double t = now_s - offset_ - options_.target_delay_s;   // capture time to show now
  if (t < frames_.front().capture_time_s) return std::nullopt;  // not due yet
  // Playout passes frames in order; sequence numbers it passes without having
  // seen them are lost.
  auto pass = [&](const FrameParams& f) {
    if (played_any_ && f.sequence > played_sequence_ + 1) stats_.lost += f.sequence - played_sequence_ - 1;
    if (!played_any_ || f.sequence > played_sequence_) played_sequence_ = f.sequence;
    played_any_ = true;
    played_capture_s_ = std::max(played_capture_s_, f.capture_time_s);
  };
  // Drop frames wholly in the past, keeping the one just before t for interpolation.
  while (frames_.size() >= 2 && frames_[1].capture_time_s <= t) {
    pass(frames_.front());
    frames_.pop_front();
  }
  const FrameParams& a = frames_.front();
  pass(a);
  if (frames_.size() == 1) {
    if (t - a.capture_time_s > options_.max_hold_s) return std::nullopt;  // the sender went quiet
    return a;                                                             // hold the newest rather than extrapolate
  }
  const FrameParams& b = frames_[1];
  const double span = b.capture_time_s - a.capture_time_s;
  return InterpolateParams(a, b, span > 0 ? std::clamp((t - a.capture_time_s) / span, 0.0, 1.0) : 0.0);
}

JitterBufferStats JitterBuffer::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace headcast
