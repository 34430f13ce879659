// The capture flags of every program that opens a source (headcast-track,
// headcast-sender, headcast-train prep): one spelling and one meaning each.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "common/capture/frame_source.h"

namespace headcast {

// Depth: RGB-D folders and side-by-side stereo (zed:SOURCE).
inline void AddDepthFlags(CLI::App& app, SourceOptions& s) {
  app.add_option("--depth-input", s.depth_input,
                 "RGB-D: association file (TUM style: t colour.png t depth.png) of 16-bit depth PNGs");
  app.add_option("--depth-units", s.depth_units_per_metre,
                 "depth PNG units per metre (1000: millimetres; TUM datasets use 5000)")
      ->capture_default_str();
  app.add_option("--stereo-calibration", s.stereo_calibration,
                 "for zed:SOURCE inputs: OpenCV YAML or the camera's factory SN<serial>.conf");
  app.add_option("--stereo-resolution", s.stereo_resolution, "section of a ZED .conf: 2K, FHD, HD, VGA")
      ->capture_default_str();
}

// Cameras (/dev/videoN, zed:/dev/videoN); `camera_size` is parsed with ParseSize.
inline void AddCameraFlags(CLI::App& app, SourceOptions& s, std::string& camera_size) {
  app.add_option("--camera-size", camera_size, "cameras: WIDTHxHEIGHT to ask for (per eye for stereo)")
      ->capture_default_str();
  app.add_option("--camera-fps", s.fps, "cameras: frame rate to ask for; image folders: their rate")
      ->capture_default_str();
  app.add_option("--pixel-format", s.pixel_format, "cameras: auto, yuyv or mjpeg")->capture_default_str();
}

}  // namespace headcast
