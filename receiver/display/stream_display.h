// A display that streams raw frames to another program (the virtual camera,
// a pipe): the picture placed on a fixed canvas, converted, written. Frames
// keep flowing between sessions — the last frame held for a while, then a
// "waiting" card — because call programs drop a camera that goes quiet.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "common/core/timer.h"
#include "receiver/display/display.h"
#include "receiver/display/raw_frames.h"
#include "receiver/display/v4l2_output.h"

namespace headcast {

struct StreamDisplayOptions {
  cv::Size size{640, 480};
  RawPixelFormat format = RawPixelFormat::kYuyv;
  cv::Scalar background{0, 0, 0};
  double hold_s = 2;  // how long the last picture stays after frames stop, then the card
  std::string waiting_text = "headcast: waiting for a sender";
  void Check() const;
};

class StreamDisplay : public Display {
 public:
  StreamDisplay(std::unique_ptr<FrameSink> sink, StreamDisplayOptions options, std::string name);
  bool Show(const cv::Mat& image_bgr, const DisplayOverlay& overlay) override;
  bool Idle() override;
  std::string name() const override { return name_; }
  std::string Describe() const { return sink_->Describe(); }

 private:
  bool Send(const cv::Mat& canvas);
  std::unique_ptr<FrameSink> sink_;
  StreamDisplayOptions options_;
  std::string name_;
  std::string raw_;  // the last frame written, as bytes (repeated while idle)
  bool showing_card_ = false;
  Stopwatch since_picture_;  // since the last real picture
  bool had_picture_ = false;
};

}  // namespace headcast
