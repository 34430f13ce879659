// The render loop.
#include "receiver/render_loop.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <stdexcept>
#include <thread>

#include "common/core/options.h"

namespace headcast {

SequenceSource::SequenceSource(std::vector<FrameParams> frames, bool paced)
    : frames_(std::move(frames)), paced_(paced) {
  // Paced replay waits for each capture time: one that is not a time, or
  // that lies ages after the first, would stall the loop for good.
  for (size_t i = 0; i < frames_.size(); ++i) {
    const double t = frames_[i].capture_time_s;
    if (!std::isfinite(t) || (paced_ && std::abs(t - frames_.front().capture_time_s) > kMaxReplaySpanS))
      throw std::invalid_argument("frame " + std::to_string(i) + ": capture time " + std::to_string(t) +
                                  " cannot be paced (not finite, or more than " +
                                  std::to_string(static_cast<long>(kMaxReplaySpanS)) + " s from the first frame)");
  }
}

std::optional<FrameParams> SequenceSource::Next(double now_s, bool* finished) {
  *finished = next_ >= frames_.size();
  if (*finished) return std::nullopt;
  if (!paced_) {
    *finished = next_ + 1 >= frames_.size();
    return frames_[next_++];
  }
  // Newest frame whose capture time (relative to the first) has come; older ones are dropped.
  const double t0 = frames_.front().capture_time_s;
  std::optional<FrameParams> newest;
  while (next_ < frames_.size() && frames_[next_].capture_time_s - t0 <= now_s) newest = frames_[next_++];
  *finished = next_ >= frames_.size() && !newest;
  return newest;
}

SessionFrameSource::SessionFrameSource(const ReceiverSessions& sessions, ShowPolicy policy,
                                       const std::atomic<bool>* stop)
    : sessions_(sessions), policy_(std::move(policy)), stop_(stop) {}

std::optional<FrameParams> SessionFrameSource::Next(double, bool* finished) {
  *finished = stop_ && *stop_;
  // The receiver's clock, not the loop's: the jitter buffers run on it.
  const double now = sessions_.Now();
  for (const SessionView& s : DisplayOrder(sessions_.Sessions(), policy_)) {
    if (auto p = s.buffer->Sample(now)) {
      std::lock_guard<std::mutex> lock(mutex_);
      shown_ = s;
      return p;
    }
  }
  return std::nullopt;
}

SessionView SessionFrameSource::shown() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return shown_;
}

void RenderLoopOptions::Check() const {
  OptionsCheck c("RenderLoopOptions");
  c.InRange("target_fps", target_fps, 0.1, 1000).NonNegative("max_seconds", max_seconds);
  c.ThrowIfErrors();
}

RenderLoopStats RunRenderLoop(AvatarBackend& avatar, FrameParamsSource& source, Display& display,
                              const RenderLoopOptions& options, const std::function<void(DisplayOverlay*)>& overlay) {
  return RunRenderLoop([&]() -> AvatarBackend& { return avatar; }, source, display, options, overlay);
}

RenderLoopStats RunRenderLoop(const AvatarPicker& pick, FrameParamsSource& source, Display& display,
                              const RenderLoopOptions& options, const std::function<void(DisplayOverlay*)>& overlay) {
  options.Check();
  using Clock = std::chrono::steady_clock;
  RenderLoopStats stats;
  const auto start = Clock::now();
  const double period = 1.0 / options.target_fps;
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  cv::Mat image;
  long tick = 0;
  Stopwatch fps_window;
  int fps_frames = 0;
  double shown_fps = 0;
  for (;;) {
    const double now = elapsed();
    if (options.max_seconds > 0 && now >= options.max_seconds) break;
    if (options.on_tick) options.on_tick();
    bool finished = false;
    const std::optional<FrameParams> params = source.Next(now, &finished);
    if (params) {
      Stopwatch frame_watch;
      AvatarTimings t;
      std::string why;
      if (pick().Render(*params, &image, &t, &why)) {
        Stopwatch show_watch;
        DisplayOverlay o;
        if (fps_window.ElapsedSeconds() >= 0.5) {
          shown_fps = fps_frames / fps_window.ElapsedSeconds();
          fps_window.Restart();
          fps_frames = 0;
        }
        o.fps = shown_fps;
        if (overlay) overlay(&o);
        const bool keep_going = display.Show(image, o);
        ++stats.rendered;
        ++fps_frames;
        stats.render_ms.Add(t.total_ms);
        stats.head_model_ms.Add(t.head_model_ms);
        stats.sample_ms.Add(t.sample_ms);
        stats.surface_ms.Add(t.surface_ms);
        stats.texture_ms.Add(t.texture_ms);
        stats.mlp_ms.Add(t.mlp_ms);
        stats.composite_ms.Add(t.composite_ms);
        stats.upsample_ms.Add(t.upsample_ms);
        stats.show_ms.Add(show_watch.ElapsedMs());
        stats.frame_ms.Add(frame_watch.ElapsedMs());
        const double glass_ms = 1e3 * (SteadyNowSeconds() - params->capture_time_s);
        if (std::abs(glass_ms) < 60e3) stats.glass_to_glass_ms.Add(glass_ms);
        if (options.on_shown) options.on_shown(*params, glass_ms, t.total_ms);
        if (!keep_going) break;
      } else {
        ++stats.refused;
        spdlog::warn("frame {} refused: {}", params->sequence, why);
      }
    } else if (!finished) {
      ++stats.idle_ticks;
      if (!display.Idle()) break;  // the output is gone (a closed pipe)
    }
    if (finished) break;
    if (!options.paced) continue;
    // Next tick on the fixed grid; ticks that already passed are skipped, not caught up.
    const double after = elapsed();
    const long next_tick = static_cast<long>(std::floor(after / period)) + 1;
    if (next_tick > tick + 1) stats.missed_ticks += static_cast<int>(next_tick - tick - 1);
    tick = next_tick;
    std::this_thread::sleep_for(std::chrono::duration<double>(tick * period - elapsed()));
  }
  stats.seconds = elapsed();
  return stats;
}

}  // namespace headcast
