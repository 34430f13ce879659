// Display: where the receiver's frames go — a real GLFW window, an offscreen
// OSMesa GL context (machines without a display), an MP4 file, PNG screenshots.
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
  virtual std::string name() const = 0;
};

enum class DisplayKind {
  kWindow,     // GLFW window with an OpenGL texture
  kOffscreen,  // OSMesa: the same GL drawing into memory
  kVideo,      // MP4 file only
  kNone,       // nothing (benchmarks)
};

struct DisplayOptions {
  DisplayKind kind = DisplayKind::kWindow;
  std::string title = "headcast";
  int width = 0, height = 0;  // window/offscreen size; 0: the first frame's size
  bool draw_overlay = true;
  std::string video_path;  // also record what is shown here (any kind), "" = no
  double video_fps = 30;
  std::string screenshot_dir = ".";  // where the window's 's' key writes PNGs
  void Check() const;
};

// Throws std::runtime_error with a clear reason when the kind cannot work here
// (no X display for a window, no OSMesa library, unwritable video path).
std::unique_ptr<Display> MakeDisplay(const DisplayOptions& options);

// "window", "offscreen", "video", "none" -> kind; throws for anything else.
DisplayKind ParseDisplayKind(const std::string& name);

}  // namespace headcast
