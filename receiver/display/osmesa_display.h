// Offscreen display: the window's OpenGL drawing, into memory through OSMesa
// (loaded at run time, so it never clashes with libGL in the same process).
#pragma once

#include <memory>

#include "receiver/display/display.h"

namespace headcast {

class OsMesaDisplay : public Display {
 public:
  // Throws std::runtime_error if libOSMesa cannot be loaded or a context made.
  OsMesaDisplay(int width = 0, int height = 0);
  ~OsMesaDisplay() override;
  bool Show(const cv::Mat& image_bgr, const DisplayOverlay& overlay) override;
  std::string name() const override { return "offscreen"; }
  // The last frame as OpenGL drew it, read back from the OSMesa buffer.
  const cv::Mat& last_frame() const { return last_; }

 private:
  void Open(int width, int height);
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int width_, height_;
  cv::Mat last_;
};

}  // namespace headcast
