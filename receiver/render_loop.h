// The receiver's render loop: takes the newest parameters, renders at the target
// rate, skips ticks rather than lag behind, shows frames and keeps statistics.
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <optional>
#include <vector>

#include "common/avatar/avatar_backend.h"
#include "common/core/timer.h"
#include "receiver/display/display.h"
#include "receiver/receiver_sessions.h"

namespace headcast {

// Where parameters come from (a session, a recording, a synthetic sequence).
class FrameParamsSource {
 public:
  virtual ~FrameParamsSource() = default;
  // The newest parameters available `now_s` seconds after the loop started, or
  // nothing new. Sets *finished once no more will ever come.
  virtual std::optional<FrameParams> Next(double now_s, bool* finished) = 0;
};

// Replays frames by their capture timestamps (paced) or one per call (unpaced,
// for offline export where every frame must be rendered). Throws
// std::invalid_argument for capture times that cannot be paced.
constexpr double kMaxReplaySpanS = 7 * 24 * 3600.0;
class SequenceSource : public FrameParamsSource {
 public:
  SequenceSource(std::vector<FrameParams> frames, bool paced);
  std::optional<FrameParams> Next(double now_s, bool* finished) override;

 private:
  std::vector<FrameParams> frames_;
  bool paced_;
  size_t next_ = 0;
};

// A receiver's live sessions: the first session in the ShowPolicy's order
// whose jitter buffer has something to show. Remembers which session that
// was, so the frame is drawn with the avatar that session asked for.
class SessionFrameSource : public FrameParamsSource {
 public:
  // `stop` (optional): once set, the source says it is finished.
  SessionFrameSource(const ReceiverSessions& sessions, ShowPolicy policy, const std::atomic<bool>* stop = nullptr);
  std::optional<FrameParams> Next(double now_s, bool* finished) override;
  SessionView shown() const;  // the session of the last frame given (empty before the first)

 private:
  const ReceiverSessions& sessions_;
  ShowPolicy policy_;
  const std::atomic<bool>* stop_;
  mutable std::mutex mutex_;
  SessionView shown_;
};

struct RenderLoopOptions {
  double target_fps = 30;  // ticks per second when paced
  bool paced = true;       // false: render as fast as the source gives frames
  double max_seconds = 0;  // stop after this long (0: when the source finishes)
  // Called after each frame is shown: its parameters, glass-to-glass ms, render ms.
  std::function<void(const FrameParams&, double, double)> on_shown;
  // Called at every tick, frames or not (a service watchdog's sign of life).
  std::function<void()> on_tick;
  void Check() const;
};

struct RenderLoopStats {
  int rendered = 0;      // frames rendered and shown
  int missed_ticks = 0;  // ticks skipped because rendering ran late
  int idle_ticks = 0;    // ticks with no new parameters
  int refused = 0;       // parameter sets the renderer refused (NaN, out of range)
  double seconds = 0;    // wall time of the loop
  // A receiver runs for days: each keeps a bounded random subset of its samples.
  static constexpr size_t kKept = 100000;
  SampleStats frame_ms{kKept};  // render + show per frame
  SampleStats render_ms{kKept}, head_model_ms{kKept}, sample_ms{kKept}, surface_ms{kKept}, texture_ms{kKept},
      mlp_ms{kKept}, composite_ms{kKept}, upsample_ms{kKept}, show_ms{kKept};
  // Glass to glass: shown minus the capture time of what is shown (the jitter
  // buffer interpolates capture times too). Same-host clocks only: values
  // beyond a minute (other hosts' clocks) are left out.
  SampleStats glass_to_glass_ms{kKept};
  double fps() const { return seconds > 0 ? rendered / seconds : 0; }
};

// Runs until the source finishes, the display asks to quit, or max_seconds.
// `overlay` (optional) supplies extra overlay figures (latency, kbit/s).
RenderLoopStats RunRenderLoop(AvatarBackend& avatar, FrameParamsSource& source, Display& display,
                              const RenderLoopOptions& options,
                              const std::function<void(DisplayOverlay*)>& overlay = nullptr);
// The same with the avatar chosen per frame, after the source gave its
// parameters (a receiver with several avatars renders the one the shown
// session drives).
using AvatarPicker = std::function<AvatarBackend&()>;
RenderLoopStats RunRenderLoop(const AvatarPicker& avatar, FrameParamsSource& source, Display& display,
                              const RenderLoopOptions& options,
                              const std::function<void(DisplayOverlay*)>& overlay = nullptr);

}  // namespace headcast
