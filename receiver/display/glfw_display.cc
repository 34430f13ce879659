// GLFW window display.
#include "receiver/display/glfw_display.h"

#include <GLFW/glfw3.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <stdexcept>

#include "common/core/image_io.h"
#include "receiver/display/gl_blit.h"

namespace headcast {

struct GlfwDisplay::Gl {
  GlFunctions functions;
  std::unique_ptr<GlBlitter> blitter;
};

namespace {
std::string LastGlfwError() {
  const char* description = nullptr;
  glfwGetError(&description);
  return description ? description : "unknown error";
}
}  // namespace

GlfwDisplay::GlfwDisplay(const std::string& title, std::string screenshot_dir, int width, int height)
    : title_(title), screenshot_dir_(std::move(screenshot_dir)), width_(width), height_(height) {
  if (!glfwInit())
    throw std::runtime_error("cannot open a window: " + LastGlfwError() +
                             " (no display? set DISPLAY, or use --display offscreen)");
}

GlfwDisplay::~GlfwDisplay() {
  if (window_) {
    glfwMakeContextCurrent(window_);
    gl_.reset();  // deletes the texture while the context is current
    glfwDestroyWindow(window_);
  }
  glfwTerminate();
}

void GlfwDisplay::Open(int width, int height) {
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 2);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 1);
  window_ = glfwCreateWindow(width, height, title_.c_str(), nullptr, nullptr);
  if (!window_) throw std::runtime_error("cannot create a window: " + LastGlfwError());
  glfwMakeContextCurrent(window_);
  glfwSwapInterval(0);  // never block on vsync: the render loop paces itself
  glfwSetWindowUserPointer(window_, this);
  glfwSetKeyCallback(window_, [](GLFWwindow* w, int key, int, int action, int) {
    if (action == GLFW_PRESS) static_cast<GlfwDisplay*>(glfwGetWindowUserPointer(w))->HandleKey(key);
  });
  gl_ = std::make_unique<Gl>();
  gl_->functions.Load([](const char* name) { return reinterpret_cast<void*>(glfwGetProcAddress(name)); });
  gl_->blitter = std::make_unique<GlBlitter>(gl_->functions);
}

void GlfwDisplay::HandleKey(int key) {
  if (key == GLFW_KEY_Q || key == GLFW_KEY_ESCAPE) quit_ = true;
  if (key == GLFW_KEY_S) screenshot_ = true;
  if (key == GLFW_KEY_F && window_) {
    GLFWmonitor* monitor = glfwGetPrimaryMonitor();
    const GLFWvidmode* mode = monitor ? glfwGetVideoMode(monitor) : nullptr;
    if (!fullscreen_ && mode) {
      glfwGetWindowPos(window_, &windowed_x_, &windowed_y_);
      glfwGetWindowSize(window_, &windowed_w_, &windowed_h_);
      glfwSetWindowMonitor(window_, monitor, 0, 0, mode->width, mode->height, mode->refreshRate);
      fullscreen_ = true;
    } else if (fullscreen_) {
      glfwSetWindowMonitor(window_, nullptr, windowed_x_, windowed_y_, windowed_w_, windowed_h_, 0);
      fullscreen_ = false;
    }
  }
}

bool GlfwDisplay::Show(const cv::Mat& image, const DisplayOverlay& overlay) {
  if (!window_) Open(width_ > 0 ? width_ : image.cols, height_ > 0 ? height_ : image.rows);
  glfwMakeContextCurrent(window_);
  int fb_w = 0, fb_h = 0;
  glfwGetFramebufferSize(window_, &fb_w, &fb_h);
  gl_->blitter->Draw(image, fb_w, fb_h);
  if (capture_ || screenshot_) captured_ = gl_->blitter->Read(fb_w, fb_h, GL_BACK);
  if (screenshot_) {
    screenshot_ = false;
    const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    char stamp[32];
    std::strftime(stamp, sizeof(stamp), "%Y%m%d-%H%M%S", std::localtime(&now));
    last_screenshot_ = (std::filesystem::path(screenshot_dir_) / ("headcast-" + std::string(stamp) + ".png")).string();
    WriteImage(last_screenshot_, captured_);
  }
  glfwSwapBuffers(window_);
  glfwPollEvents();
  return !quit_ && !glfwWindowShouldClose(window_);
}

}  // namespace headcast
