// Per-session jitter buffer: frames are played out a fixed delay after they
// were captured (mapped to the receiver's clock), reordered, late ones dropped,
// missing ones interpolated (slerp for rotations) and resampled to the display rate.
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

#include "common/headmodel/params.h"

namespace headcast {

struct JitterBufferOptions {
  double target_delay_s = 0.1;  // playout delay added to the best-case network delay, seconds
  double max_hold_s = 0.5;      // keep showing the newest frame this long when nothing newer comes
  size_t capacity = 512;        // frames kept at most
  void Check() const;
};

struct JitterBufferStats {
  uint64_t received = 0;   // accepted frames
  uint64_t late = 0;       // arrived after their playout time had passed
  uint64_t duplicate = 0;  // same sequence number again
  uint64_t lost = 0;       // sequence numbers skipped by the time playout passed them
};

class JitterBuffer {
 public:
  explicit JitterBuffer(const JitterBufferOptions& options = {});
  // `arrival_s` on the receiver's clock; the frame's capture time is on the
  // sender's. Thread-safe.
  void Push(const FrameParams& frame, double arrival_s);
  // Parameters to show at receiver time `now_s`, interpolated between the two
  // frames around the playout time; nullopt before the first frame or after a
  // silence longer than max_hold_s. Thread-safe.
  std::optional<FrameParams> Sample(double now_s);
  // Receiver time at which a frame captured at `capture_s` is played out.
  double PlayoutTime(double capture_s) const;
  JitterBufferStats stats() const;

 private:
  JitterBufferOptions options_;
  mutable std::mutex mutex_;
  std::deque<FrameParams> frames_;  // ascending capture time
  double offset_ = 0;               // min(arrival - capture): network floor + clock difference
  bool have_offset_ = false;
  double played_capture_s_ = -1e300;  // newest capture time already played out
  uint64_t played_sequence_ = 0;
  bool played_any_ = false;
  JitterBufferStats stats_;
};

}  // namespace headcast
