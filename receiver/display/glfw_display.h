// A real window: GLFW + OpenGL texture upload. Keys: q/Esc quit, f fullscreen, s screenshot.
#pragma once

#include <memory>
#include <string>

#include "receiver/display/display.h"

struct GLFWwindow;

namespace headcast {

class GlfwDisplay : public Display {
 public:
  // Throws std::runtime_error if no display can be opened (DISPLAY unset, no X server).
  GlfwDisplay(const std::string& title, std::string screenshot_dir, int width = 0, int height = 0);
  ~GlfwDisplay() override;
  bool Show(const cv::Mat& image_bgr, const DisplayOverlay& overlay) override;
  std::string name() const override { return "window"; }

  // Acts on a key as if it were pressed (GLFW key codes); used by the key callback.
  void HandleKey(int key);
  // Keep a copy of each frame as drawn in the window (read back from GL).
  void set_capture(bool capture) { capture_ = capture; }
  const cv::Mat& captured() const { return captured_; }
  bool fullscreen() const { return fullscreen_; }
  const std::string& last_screenshot() const { return last_screenshot_; }

 private:
  void Open(int width, int height);
  struct Gl;
  std::unique_ptr<Gl> gl_;
  GLFWwindow* window_ = nullptr;
  std::string title_, screenshot_dir_, last_screenshot_;
  int width_, height_;
  bool capture_ = false, quit_ = false, fullscreen_ = false, screenshot_ = false;
  int windowed_x_ = 0, windowed_y_ = 0, windowed_w_ = 0, windowed_h_ = 0;
  cv::Mat captured_;
};

}  // namespace headcast
