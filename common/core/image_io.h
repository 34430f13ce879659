// Image and video reading/writing with errors that name the file.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <string>
#include <vector>

namespace headcast {

// 8-bit BGR (or as stored with `flags`, cv::IMREAD_*); throws if unreadable.
cv::Mat ReadImage(const std::string& path, int flags = 1 /* cv::IMREAD_COLOR */);
// Creates the parent folder; throws if the encoder fails.
void WriteImage(const std::string& path, const cv::Mat& image);

// Float image in [0,1] (any channel count of 1 or 3) to 8-bit, clamped.
cv::Mat ToUint8(const cv::Mat& float_image);

// The image files (png, jpg, jpeg, bmp, ppm, tif, tiff; any case) directly in
// `folder`, sorted by name: the order of every image-folder input.
std::vector<std::string> ListImageFiles(const std::string& folder);

// "NNNNN.png": how per-frame images (masks, crops) are named by frame number.
std::string FrameFileName(int frame);

// A TUM-style RGB-D association file: lines "t_rgb rgb/x.png t_depth depth/x.png"
// ('#' comments), paths relative to the file's folder. Throws naming the file
// and line when it cannot be read or a line is malformed, or when it lists nothing.
struct RgbdPair {
  double time = 0;  // the colour image's timestamp, seconds
  std::string colour, depth;
};
std::vector<RgbdPair> ReadRgbdAssociations(const std::string& path);

// Frames of a video file, or throws naming the file if it cannot be opened.
class VideoReader {
 public:
  explicit VideoReader(const std::string& path);
  bool Read(cv::Mat* frame);  // false at the end or on a decode failure
  double fps() const { return fps_; }
  int frame_count() const { return frame_count_; }  // as the container says; may be 0
  cv::Size size() const { return size_; }

 private:
  std::string path_;
  cv::VideoCapture capture_;
  double fps_ = 0;
  int frame_count_ = 0;
  cv::Size size_;
};

// MP4 writer; the frame size is fixed by the first frame. Frames of another
// size are resized to it rather than silently dropped by OpenCV.
class VideoWriter {
 public:
  VideoWriter(std::string path, double fps);
  ~VideoWriter();
  void Write(const cv::Mat& frame_bgr8);
  void Close();
  int frames_written() const { return frames_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  double fps_;
  cv::VideoWriter writer_;
  cv::Size size_;
  int frames_ = 0;
};

}  // namespace headcast
