// Where the sender's frames come from: a FrameSource yields colour frames
// (and, for RGB-D sources, metric depth aligned to them) with capture
// timestamps. Sources: V4L2 webcams, video files and image folders, ZED2-style
// side-by-side stereo (depth by StereoSGBM), and TUM-style RGB-D folders.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "common/core/camera.h"

namespace headcast {

// Depth a source makes only where it is asked for (side-by-side stereo:
// matching the whole frame costs more than tracking it).
class DepthOnDemand {
 public:
  virtual ~DepthOnDemand() = default;
  // CV_32F metres aligned to the frame's bgr, the frame's size; 0 where
  // unknown and outside `box` (clipped to the frame). With near_m < far_m
  // only depths in that range are looked for (stereo: fewer disparities).
  virtual cv::Mat DepthIn(const cv::Rect& box, double near_m = 0, double far_m = 0) const = 0;
};

struct CapturedFrame {
  cv::Mat bgr;      // 8-bit BGR
  cv::Mat depth_m;  // CV_32F metres aligned to bgr, 0 where unknown; empty without depth
  // Or depth made on demand (stereo), computed where the tracker needs it.
  std::shared_ptr<const DepthOnDemand> depth_on_demand;
  bool has_depth() const { return !depth_m.empty() || depth_on_demand != nullptr; }
  // Steady-clock seconds at capture for live and real-time sources; media time
  // (index / fps) for files read as fast as possible.
  double capture_time_s = 0;
  uint64_t index = 0;
  std::optional<PinholeCamera> camera;  // calibrated intrinsics of bgr, when the source knows them
};

enum class ReadStatus {
  kFrame,    // *frame is filled
  kSkipped,  // this frame was unreadable (corrupt file, bad depth); the next may be fine
  kEnd,      // no more frames
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Never throws for a bad frame: returns kSkipped and says why in *problem.
  virtual ReadStatus Read(CapturedFrame* frame, std::string* problem) = 0;
  virtual std::string Describe() const = 0;
  virtual double fps() const = 0;
  virtual bool has_depth() const { return false; }
  // Recorded sources: frames in one pass, when known (for progress); 0 otherwise.
  virtual int64_t frame_count() const { return 0; }
};

struct SourceOptions {
  bool realtime = false;                 // recorded sources: pace to their frame rate (stamps from the steady clock)
  bool loop = false;                     // recorded sources: start again at the end
  double fps = 30;                       // image folders: their rate; cameras: the rate asked for
  int width = 640, height = 480;         // cameras: the size asked for (per eye for stereo)
  std::string pixel_format = "auto";     // cameras: auto, yuyv or mjpeg
  std::string stereo_calibration;        // "zed:" sources: OpenCV YAML or a ZED factory .conf
  std::string stereo_resolution = "HD";  // which section of a ZED .conf: 2K, FHD, HD, VGA
  double depth_scale = 0.5;              // stereo: disparity computed at this fraction of the size (speed)
  // stereo: edge-aware WLS filtering of the disparity. Denser but less exact,
  // so off by default (bench/DEFAULTS.md).
  bool wls_filter = false;
  std::string depth_input;              // RGB-D: an association file (TUM style) for the colour/depth pairs
  double depth_units_per_metre = 1000;  // RGB-D: 16-bit depth PNG units (1000 = millimetres; TUM uses 5000)
  void Check() const;
};

// Opens a source from a spec:
//   /dev/videoN or v4l2:/dev/videoN   a V4L2 camera
//   zed:SPEC                          side-by-side stereo from SPEC (camera, video or folder); needs
//                                     stereo_calibration; frames carry depth
//   FOLDER                            images (sorted by name); an RGB-D folder when depth_input is set
//                                     or the folder holds associations.txt
//   FILE                              a video
// Throws std::runtime_error with a clear message when the source cannot be opened.
std::unique_ptr<FrameSource> OpenFrameSource(const std::string& spec, const SourceOptions& options);

}  // namespace headcast
