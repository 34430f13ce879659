// Frames for other programs: the shown picture placed on a fixed-size canvas
// (aspect kept, a background colour around it) and converted to the raw pixel
// formats cameras and video tools use. Shared by the virtual camera (V4L2
// output) and the raw pipe.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

namespace headcast {

enum class RawPixelFormat {
  kBgr24,  // 3 bytes a pixel, B G R (FFmpeg: bgr24)
  kYuyv,   // 4:2:2, Y0 U Y1 V (V4L2 YUYV, FFmpeg: yuyv422)
  kI420,   // 4:2:0 planar, Y then U then V (V4L2 YU12, FFmpeg: yuv420p)
};

// "bgr24", "yuyv", "i420" (also the FFmpeg names yuyv422 and yuv420p).
// Throws std::invalid_argument for anything else.
RawPixelFormat ParseRawPixelFormat(const std::string& name);
std::string FfmpegPixelFormatName(RawPixelFormat format);
// Bytes of one frame; sizes must be even for the YUV formats.
size_t RawFrameBytes(RawPixelFormat format, int width, int height);

// "640x480": both sides even, 16..7680 x 16..4320. Throws std::invalid_argument otherwise.
cv::Size ParseOutputSize(const std::string& text);
// "black", "white", "gray", "green" (chroma-key green), "blue" (chroma blue)
// or "#RRGGBB". Returns BGR. Throws std::invalid_argument otherwise.
cv::Scalar ParseBackground(const std::string& text);

// `image` scaled to fit `size` with its aspect kept, centred on `background`.
cv::Mat PlaceOnCanvas(const cv::Mat& image_bgr, cv::Size size, const cv::Scalar& background);

// What a camera shows before a sender arrives or after one stopped: the
// background with a line of text, so call programs see a live camera.
cv::Mat WaitingCard(cv::Size size, const cv::Scalar& background, const std::string& text);

// BGR (CV_8UC3, even width and height for the YUV formats) to raw bytes.
// YUV is BT.601 limited range (what webcams send and players assume);
// chroma is the mean of the pixels it covers.
void ToRawFrame(const cv::Mat& bgr, RawPixelFormat format, std::string* out);
// The reverse, for tests and read-back: raw bytes of a `size` frame to BGR.
// Returns false if the byte count does not match.
bool FromRawFrame(const std::string& bytes, RawPixelFormat format, cv::Size size, cv::Mat* bgr);

}  // namespace headcast
