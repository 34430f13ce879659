// The render loop: paces, skips rather than lags, refuses bad parameters, stops on quit.
#include "receiver/render_loop.h"

#include <gtest/gtest.h>

#include <thread>

#include "common/avatar/avatar_renderer.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/synthetic_motion.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

AvatarConfig Tiny() { return testing::TinyAvatarConfig(); }

// Counts frames; can be told to quit, or to be slow (to test skipping).
class FakeDisplay : public Display {
 public:
  bool Show(const cv::Mat& image, const DisplayOverlay&) override {
    EXPECT_EQ(image.size(), cv::Size(size, size));
    ++shown;
    first_pixel.push_back(image.at<cv::Vec3b>(0, 0)[0]);
    if (delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    return quit_after <= 0 || shown < quit_after;
  }
  std::string name() const override { return "fake"; }
  int shown = 0, quit_after = 0, delay_ms = 0, size = 128;
  std::vector<int> first_pixel;  // the blue value at (0, 0) of every frame shown
};

// The avatar-backend seam with a fake: paints each frame's sequence number.
class FakeBackend : public AvatarBackend {
 public:
  bool Render(const FrameParams& p, cv::Mat* image, AvatarTimings* timings, std::string* why) override {
    if (!p.IsValid(why)) return false;
    image->create(64, 64, CV_8UC3);
    image->setTo(cv::Scalar::all(static_cast<double>(p.sequence % 256)));
    if (timings) timings->total_ms = 1;
    return true;
  }
  const AvatarCommonConfig& common_config() const override { return config_; }
  std::string kind() const override { return "fake"; }
  const SubjectParams& subject() const override { return subject_; }

 private:
  SubjectParams subject_;
  AvatarCommonConfig config_ = [] {
    AvatarCommonConfig c;
    c.output_size = 64;
    return c;
  }();
};

class RenderLoopTest : public ::testing::Test {
 protected:
  void SetUp() override {
    model_ = std::make_shared<const HeadModel>(MakeBuiltinHead());
    renderer_ =
        std::make_unique<AvatarRenderer>(model_, Avatar::CreateRandom(Tiny(), *model_, DefaultSubject(*model_, 128)));
    for (int i = 0; i < 30; ++i) frames_.push_back(SyntheticTalkingHead(*model_, i));  // 1 s at 30 fps
  }
  std::shared_ptr<const HeadModel> model_;
  std::unique_ptr<AvatarRenderer> renderer_;
  std::vector<FrameParams> frames_;
};

TEST_F(RenderLoopTest, UnpacedRendersEveryFrame) {
  SequenceSource source(frames_, /*paced=*/false);
  FakeDisplay display;
  RenderLoopOptions o;
  o.paced = false;
  const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, o);
  EXPECT_EQ(s.rendered, 30);
  EXPECT_EQ(display.shown, 30);
  EXPECT_EQ(s.render_ms.count(), 30u);
  EXPECT_GT(s.fps(), 0);
}

TEST_F(RenderLoopTest, PacedTakesAboutTheRecordingsDuration) {
  SequenceSource source(frames_, /*paced=*/true);
  FakeDisplay display;
  RenderLoopOptions o;
  o.target_fps = 30;
  const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, o);
  EXPECT_GT(s.seconds, 0.9);
  EXPECT_LT(s.seconds, 3.0);  // generous: CI machines are shared
  EXPECT_GT(s.rendered, 10);
  EXPECT_LE(s.rendered, 30);
}

TEST_F(RenderLoopTest, SlowDisplaySkipsTicksInsteadOfLagging) {
  SequenceSource source(frames_, /*paced=*/true);
  FakeDisplay display;
  display.delay_ms = 100;  // each frame takes > 3 ticks
  RenderLoopOptions o;
  o.target_fps = 30;
  const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, o);
  // Lagging would show all 30 frames (> 3 s); skipping keeps to the recording's ~1 s.
  EXPECT_LT(s.seconds, 2.5);
  EXPECT_LT(s.rendered, 20);
  EXPECT_GT(s.missed_ticks, 5);
}

TEST_F(RenderLoopTest, RefusesBadFramesAndStopsOnQuit) {
  frames_[3].expression[0] = std::nanf("");
  frames_[5].cam_translation.z() = -2;
  SequenceSource source(frames_, false);
  FakeDisplay display;
  display.quit_after = 10;
  RenderLoopOptions o;
  o.paced = false;
  const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, o);
  EXPECT_EQ(s.refused, 2);
  EXPECT_EQ(display.shown, 10);
  EXPECT_EQ(s.rendered, 10);
}

TEST_F(RenderLoopTest, AnyBackendRendersThroughTheLoop) {
  for (size_t i = 0; i < frames_.size(); ++i) frames_[i].sequence = i;
  frames_[4].expression[0] = std::nanf("");
  SequenceSource source(frames_, /*paced=*/false);
  FakeDisplay display;
  display.size = 64;
  FakeBackend backend;
  RenderLoopOptions o;
  o.paced = false;
  const RenderLoopStats s = RunRenderLoop(backend, source, display, o);
  EXPECT_EQ(s.rendered, 29);
  EXPECT_EQ(s.refused, 1);
  ASSERT_EQ(display.first_pixel.size(), 29u);
  EXPECT_EQ(display.first_pixel[3], 3);
  EXPECT_EQ(display.first_pixel[4], 5) << "frame 4 was refused; the next one is shown";
}

}  // namespace
}  // namespace headcast
