// Display factory, overlay, and the video/none displays.
#include "receiver/display/display.h"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "common/core/image_io.h"
#include "common/core/options.h"
#include "receiver/display/glfw_display.h"
#include "receiver/display/osmesa_display.h"
#include "receiver/display/stream_display.h"

namespace headcast {

void DrawOverlay(const DisplayOverlay& o, cv::Mat* image) {
  std::string text;
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.1f fps", o.fps);
  text += buf;
  if (o.latency_ms >= 0) {
    std::snprintf(buf, sizeof(buf), "  %.0f ms", o.latency_ms);
    text += buf;
  }
  if (o.kbps >= 0) {
    std::snprintf(buf, sizeof(buf), "  %.1f kbit/s", o.kbps);
    text += buf;
  }
  if (!o.note.empty()) text += "  " + o.note;
  const double scale = std::max(0.35, image->cols / 640.0);
  const int base = static_cast<int>(18 * scale);
  cv::putText(*image, text, {6, base}, cv::FONT_HERSHEY_SIMPLEX, 0.5 * scale, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(*image, text, {6, base}, cv::FONT_HERSHEY_SIMPLEX, 0.5 * scale, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
}

void DisplayOptions::Check() const {
  OptionsCheck c("DisplayOptions");
  c.NonNegative("width", width).NonNegative("height", height).Positive("video_fps", video_fps);
  c.That(kind != DisplayKind::kVideo || !video_path.empty(), "the video display needs video_path");
  c.That(kind != DisplayKind::kV4l2 || !device.empty(), "the v4l2 display needs a device (v4l2:/dev/videoN)");
  c.InRange("output_width", output_width, 16, 7680).InRange("output_height", output_height, 16, 4320);
  c.ThrowIfErrors();
}

DisplayKind ParseDisplayKind(const std::string& name, std::string* device) {
  if (name == "window") return DisplayKind::kWindow;
  if (name == "offscreen") return DisplayKind::kOffscreen;
  if (name == "video") return DisplayKind::kVideo;
  if (name == "none") return DisplayKind::kNone;
  if (name == "pipe") return DisplayKind::kPipe;
  if (name.rfind("v4l2:", 0) == 0 && name.size() > 5) {
    if (device) *device = name.substr(5);
    return DisplayKind::kV4l2;
  }
  throw std::invalid_argument("unknown display '" + name +
                              "' (window, offscreen, video, none, pipe, v4l2:/dev/videoN)");
}

namespace {

class NoDisplay : public Display {
 public:
  bool Show(const cv::Mat&, const DisplayOverlay&) override { return true; }
  std::string name() const override { return "none"; }
};

// Draws the overlay, records the result if asked, then hands it to the inner display.
class FramedDisplay : public Display {
 public:
  FramedDisplay(std::unique_ptr<Display> inner, const DisplayOptions& o) : inner_(std::move(inner)), options_(o) {
    if (!o.video_path.empty()) video_ = std::make_unique<VideoWriter>(o.video_path, o.video_fps);
  }
  bool Show(const cv::Mat& image, const DisplayOverlay& overlay) override {
    const cv::Mat* shown = &image;
    if (options_.draw_overlay) {
      image.copyTo(framed_);
      DrawOverlay(overlay, &framed_);
      shown = &framed_;
    }
    if (video_) video_->Write(*shown);
    // A camera or pipe carries the clean picture: it is someone's face in a call.
    return inner_->Show(streams_ ? image : *shown, overlay);
  }
  bool Idle() override { return inner_->Idle(); }
  std::string name() const override { return inner_->name() + (video_ ? "+video" : ""); }

 private:
  std::unique_ptr<Display> inner_;
  DisplayOptions options_;
  bool streams_ = options_.kind == DisplayKind::kV4l2 || options_.kind == DisplayKind::kPipe;
  std::unique_ptr<VideoWriter> video_;
  cv::Mat framed_;
};

}  // namespace

std::unique_ptr<Display> MakeDisplay(const DisplayOptions& options) {
  options.Check();
  std::unique_ptr<Display> inner;
  switch (options.kind) {
    case DisplayKind::kWindow:
      inner = std::make_unique<GlfwDisplay>(options.title, options.screenshot_dir, options.width, options.height);
      break;
    case DisplayKind::kOffscreen:
      inner = std::make_unique<OsMesaDisplay>(options.width, options.height);
      break;
    case DisplayKind::kVideo:
    case DisplayKind::kNone:
      inner = std::make_unique<NoDisplay>();
      break;
    case DisplayKind::kV4l2: {
      V4l2OutputRequest request;
      request.size = {options.output_width, options.output_height};
      request.pixel_format = options.output_format;
      request.fps = options.video_fps;
      auto device = OpenV4l2OutputDevice(options.device);
      const V4l2OutputFormat format = NegotiateV4l2Output(*device, request);
      StreamDisplayOptions s;
      s.size = format.size;
      s.format = format.format;
      s.background = options.background;
      auto sink = std::make_unique<V4l2Sink>(std::move(device), format);
      spdlog::info("virtual camera: {}", sink->Describe());
      inner = std::make_unique<StreamDisplay>(std::move(sink), s, "v4l2");
      break;
    }
    case DisplayKind::kPipe: {
      StreamDisplayOptions s;
      s.size = {options.output_width, options.output_height};
      s.format = ParseRawPixelFormat(options.output_format == "auto" ? "bgr24" : options.output_format);
      s.background = options.background;
      spdlog::info("raw frames on standard output: {} {}x{} at {} fps", FfmpegPixelFormatName(s.format), s.size.width,
                   s.size.height, options.video_fps);
      inner = std::make_unique<StreamDisplay>(std::make_unique<PipeSink>(1), s, "pipe");
      break;
    }
  }
  return std::make_unique<FramedDisplay>(std::move(inner), options);
}

}  // namespace headcast
