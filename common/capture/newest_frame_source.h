// The hand-off from a live source to a tracker that may be slower than it: a
// thread reads the source as fast as it delivers and keeps only the newest
// frame, so the tracker always works on the freshest picture. Without it a
// camera's driver queue (and a paced file) hands over frames that have aged
// while the tracker was busy, and the latency grows with every slow frame.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "common/capture/frame_source.h"

namespace headcast {

class NewestFrameSource : public FrameSource {
 public:
  explicit NewestFrameSource(std::unique_ptr<FrameSource> inner);
  ~NewestFrameSource() override;  // stops the reader (after at most the frame it is reading)
  // The newest frame not handed out yet, waiting for one if there is none;
  // a problem the reader met when no newer frame came after it; kEnd once the
  // source has ended and its last frame was handed out.
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override { return inner_->Describe(); }
  double fps() const override { return inner_->fps(); }
  bool has_depth() const override { return inner_->has_depth(); }
  uint64_t dropped() const;  // frames a newer one replaced before they were read

 private:
  void Run();
  std::unique_ptr<FrameSource> inner_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::optional<CapturedFrame> newest_;
  std::optional<std::string> problem_;
  bool ended_ = false, stop_ = false;
  uint64_t dropped_ = 0;
  std::thread reader_;
};

}  // namespace headcast
