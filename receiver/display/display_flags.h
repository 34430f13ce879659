// The display flags headcast-receiver and headcast-avatar render share, and
// the DisplayOptions they make.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "receiver/display/display.h"
#include "receiver/display/raw_frames.h"

namespace headcast {

struct DisplayFlags {
  std::string display = "window", video, output_size = "640x480", background = "black", output_format = "auto";
};

inline void AddDisplayFlags(CLI::App& app, DisplayFlags& f) {
  app.add_option("--display", f.display,
                 "window, offscreen, video, none, pipe (raw frames on stdout) or v4l2:/dev/videoN (a virtual camera)")
      ->capture_default_str();
  app.add_option("--video", f.video, "also write what is shown to this MP4");
  app.add_option("--output-size", f.output_size, "frame size of the virtual camera or pipe, WIDTHxHEIGHT")
      ->capture_default_str();
  app.add_option("--background", f.background,
                 "around the avatar in the camera or pipe frame: black, white, gray, green or blue (chroma keys), "
                 "#RRGGBB")
      ->capture_default_str();
  app.add_option("--output-format", f.output_format,
                 "pixel format of the camera (auto, yuyv, i420) or the pipe (auto = bgr24, yuyv, i420)")
      ->capture_default_str();
}

// Throws std::invalid_argument naming the flag that is wrong.
inline DisplayOptions MakeDisplayOptions(const DisplayFlags& f, double fps, const std::string& title) {
  DisplayOptions o;
  o.kind = ParseDisplayKind(f.display, &o.device);
  if (o.kind == DisplayKind::kVideo && f.video.empty())
    throw std::invalid_argument("--display video needs --video OUT.mp4");
  o.video_path = f.video;
  o.video_fps = fps;
  o.title = title;
  const cv::Size size = ParseOutputSize(f.output_size);
  o.output_width = size.width;
  o.output_height = size.height;
  o.background = ParseBackground(f.background);
  if (f.output_format != "auto") (void)ParseRawPixelFormat(f.output_format);  // a typo fails here, not later
  o.output_format = f.output_format;
  return o;
}

}  // namespace headcast
