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
