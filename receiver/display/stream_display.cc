// Streaming displays.
#include "receiver/display/stream_display.h"

#include "common/core/options.h"

namespace headcast {

void StreamDisplayOptions::Check() const {
  OptionsCheck c("StreamDisplayOptions");
  c.InRange("size.width", size.width, 16, 7680).InRange("size.height", size.height, 16, 4320);
  c.That(format == RawPixelFormat::kBgr24 || (size.width % 2 == 0 && size.height % 2 == 0),
         "YUV frames need an even width and height");
  c.InRange("hold_s", hold_s, 0, 3600);
  c.ThrowIfErrors();
}

StreamDisplay::StreamDisplay(std::unique_ptr<FrameSink> sink, StreamDisplayOptions options, std::string name)
    : sink_(std::move(sink)), options_((options.Check(), std::move(options))), name_(std::move(name)) {}

bool StreamDisplay::Send(const cv::Mat& canvas) {
  ToRawFrame(canvas, options_.format, &raw_);
  return sink_->Write(raw_);
}

bool StreamDisplay::Show(const cv::Mat& image, const DisplayOverlay&) {
  had_picture_ = true;
  showing_card_ = false;
  since_picture_.Restart();
  return Send(PlaceOnCanvas(image, options_.size, options_.background));
}

bool StreamDisplay::Idle() {
  if (!had_picture_ || since_picture_.ElapsedSeconds() > options_.hold_s) {
    if (!showing_card_) {
      ToRawFrame(WaitingCard(options_.size, options_.background, options_.waiting_text), options_.format, &raw_);
      showing_card_ = true;
    }
  }
  return sink_->Write(raw_);
}

}  // namespace headcast
