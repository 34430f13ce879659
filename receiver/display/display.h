// Display: where the receiver's frames go — a real GLFW window, an offscreen
// OSMesa GL context (machines without a display), an MP4 file, PNG screenshots,
// a virtual camera (V4L2 output) or raw frames on standard output.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

namespace headcast {

// Figures drawn over the picture.
struct DisplayOverlay {
  double fps = 0;          // frames rendered per second
  double latency_ms = -1;  // glass-to-glass latency, ms (< 0: unknown, not drawn)
  double kbps = -1;        // uplink kbit/s (< 0: unknown, not drawn)
  std::string note;        // anything else, e.g. the session name
};

// Draws the overlay text into the top-left corner of `image_bgr`.
void DrawOverlay(const DisplayOverlay& overlay, cv::Mat* image_bgr);

class Display {
 public:
  virtual ~Display() = default;
  // Shows one frame (CV_8UC3 BGR). Returns false once the user asked to quit.
  virtual bool Show(const cv::Mat& image_bgr, const DisplayOverlay& overlay) = 0;
  // Called at ticks with nothing new to show. Outputs that must not go quiet
  // (a virtual camera) write a frame; returns false once the output is gone.
  virtual bool Idle() { return true; }
  virtual std::string name() const = 0;
};

enum class DisplayKind {
  kWindow,     // GLFW window with an OpenGL texture
  kOffscreen,  // OSMesa: the same GL drawing into memory
  kVideo,      // MP4 file only
  kNone,       // nothing (benchmarks)
  kV4l2,       // a V4L2 output device: a virtual camera for call programs
  kPipe,       // raw frames on standard output, for ffmpeg and the like
};

struct DisplayOptions {
  DisplayKind kind = DisplayKind::kWindow;
  std::string title = "headcast";
  int width = 0, height = 0;  // window/offscreen size; 0: the first frame's size
  bool draw_overlay = true;
  std::string video_path;  // also record what is shown here (any kind), "" = no
  double video_fps = 30;
  std::string screenshot_dir = ".";  // where the window's 's' key writes PNGs
  // The virtual camera and the pipe: a fixed frame size, the picture placed on
  // a background with its aspect kept, a pixel format (v4l2: auto, yuyv,
  // i420; pipe: bgr24, yuyv, i420), and no overlay in the picture itself.
  std::string device;  // kV4l2: /dev/videoN
  int output_width = 640, output_height = 480;
  cv::Scalar background{0, 0, 0};
  std::string output_format = "auto";  // auto: yuyv for v4l2, bgr24 for the pipe
  void Check() const;
};

// Throws std::runtime_error with a clear reason when the kind cannot work here
// (no X display for a window, no OSMesa library, unwritable video path).
std::unique_ptr<Display> MakeDisplay(const DisplayOptions& options);

// "window", "offscreen", "video", "none", "pipe" or "v4l2:/dev/videoN" ->
// kind (and device); throws std::invalid_argument for anything else.
DisplayKind ParseDisplayKind(const std::string& name, std::string* device = nullptr);

}  // namespace headcast
