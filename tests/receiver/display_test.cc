// Displays: a known image through the real GLFW window (under Xvfb in ctest)
// and through OSMesa, read back from OpenGL; overlay; video output.
#include "receiver/display/display.h"

#include <GLFW/glfw3.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "receiver/display/glfw_display.h"
#include "receiver/display/osmesa_display.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

// Distinct colours everywhere, so a flipped, shifted or channel-swapped copy fails.
cv::Mat KnownImage(int w = 96, int h = 64) {
  cv::Mat m(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<cv::Vec3b>(y, x) = cv::Vec3b((x * 255) / w, (y * 255) / h, (x * 7 + y * 13) % 256);
  return m;
}

double MaxDiff(const cv::Mat& a, const cv::Mat& b) { return cv::norm(a, b, cv::NORM_INF); }

TEST(OsMesaDisplay, DrawsTheImageExactly) {
  OsMesaDisplay display;
  const cv::Mat image = KnownImage();
  ASSERT_TRUE(display.Show(image, {}));
  ASSERT_EQ(display.last_frame().size(), image.size());
  EXPECT_LE(MaxDiff(display.last_frame(), image), 1);
  const cv::Mat second = 255 - image;
  ASSERT_TRUE(display.Show(second, {}));
  EXPECT_LE(MaxDiff(display.last_frame(), second), 1);
  WriteImage(testing::TempDir("osmesa") + "/offscreen.png", display.last_frame());
}

TEST(OsMesaDisplay, ScalesToAGivenSize) {
  OsMesaDisplay display(192, 128);
  ASSERT_TRUE(display.Show(KnownImage(), {}));
  cv::Mat down;
  cv::resize(display.last_frame(), down, {96, 64}, 0, 0, cv::INTER_AREA);
  EXPECT_LE(cv::norm(down, KnownImage(), cv::NORM_L1) / (96 * 64 * 3), 4.0);
}

TEST(GlfwDisplay, RefusesClearlyWithoutADisplay) {
  const char* display = std::getenv("DISPLAY");
  const std::string saved = display ? display : "";
  unsetenv("DISPLAY");
  unsetenv("WAYLAND_DISPLAY");
  try {
    GlfwDisplay window("t", ".");
    ADD_FAILURE() << "a window opened without DISPLAY";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("offscreen"), std::string::npos) << e.what();
  }
  if (!saved.empty()) setenv("DISPLAY", saved.c_str(), 1);
}

class WindowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::getenv("DISPLAY")) GTEST_SKIP() << "no DISPLAY: ctest runs this under xvfb-run";
  }
};

TEST_F(WindowTest, DrawsTheImageAndReadsItBack) {
  GlfwDisplay window("headcast test", testing::TempDir("window"));
  window.set_capture(true);
  const cv::Mat image = KnownImage();
  ASSERT_TRUE(window.Show(image, {}));
  ASSERT_EQ(window.captured().size(), image.size());
  EXPECT_LE(MaxDiff(window.captured(), image), 1);
  WriteImage(testing::TempDir("window_png") + "/window.png", window.captured());
}

TEST_F(WindowTest, KeysScreenshotFullscreenAndQuit) {
  const std::string dir = testing::TempDir("shots");
  GlfwDisplay window("headcast keys", dir);
  const cv::Mat image = KnownImage();
  ASSERT_TRUE(window.Show(image, {}));
  window.HandleKey(GLFW_KEY_S);
  ASSERT_TRUE(window.Show(image, {}));
  ASSERT_FALSE(window.last_screenshot().empty());
  EXPECT_LE(MaxDiff(ReadImage(window.last_screenshot()), image), 1);
  window.HandleKey(GLFW_KEY_F);
  EXPECT_TRUE(window.fullscreen());
  EXPECT_TRUE(window.Show(image, {}));
  window.HandleKey(GLFW_KEY_F);
  EXPECT_FALSE(window.fullscreen());
  window.HandleKey(GLFW_KEY_Q);
  EXPECT_FALSE(window.Show(image, {}));
}

TEST(Display, OverlayVideoAndKinds) {
  cv::Mat image(120, 200, CV_8UC3, cv::Scalar(40, 40, 40));
  cv::Mat drawn = image.clone();
  DisplayOverlay o;
  o.fps = 29.7;
  o.latency_ms = 85;
  o.kbps = 6.4;
  DrawOverlay(o, &drawn);
  cv::Mat diff;
  cv::absdiff(image, drawn, diff);
  cv::Mat gray;
  cv::cvtColor(diff, gray, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(gray(cv::Rect(0, 0, 200, 30))), 50);  // text in the top band
  EXPECT_EQ(cv::countNonZero(gray(cv::Rect(0, 60, 200, 60))), 0);  // nothing below it

  DisplayOptions options;
  options.kind = DisplayKind::kVideo;
  options.video_path = testing::TempDir("video") + "/shown.mp4";
  {
    auto display = MakeDisplay(options);
    for (int i = 0; i < 12; ++i) ASSERT_TRUE(display->Show(image, o));
  }
  VideoReader reader(options.video_path);
  cv::Mat frame;
  int n = 0;
  while (reader.Read(&frame)) ++n;
  EXPECT_EQ(n, 12);
  EXPECT_THROW(ParseDisplayKind("hologram"), std::invalid_argument);
  options.video_path.clear();
  EXPECT_THROW(MakeDisplay(options), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
