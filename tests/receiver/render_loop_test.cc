// The render loop: paces, skips rather than lags, refuses bad parameters, stops on quit.
#include "receiver/render_loop.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <optional>
#include <thread>

#include "common/avatar/avatar_renderer.h"
#include "common/codec/param_codec.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/convert.h"
#include "proto/message_channel.h"
#include "proto/protocol.h"
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
  bool Idle() override {
    ++idled;
    return idle_quit_after <= 0 || idled < idle_quit_after;
  }
  std::string name() const override { return "fake"; }
  int shown = 0, quit_after = 0, delay_ms = 0, size = 128, idled = 0, idle_quit_after = 0;
  std::vector<int> first_pixel;  // the blue value at (0, 0) of every frame shown
};

// The avatar-backend seam with a fake: paints each frame's sequence number,
// or its own `paint` value when one is given (to tell avatars apart).
class FakeBackend : public AvatarBackend {
 public:
  explicit FakeBackend(int paint = -1) : paint_(paint) {}
  bool Render(const FrameParams& p, cv::Mat* image, AvatarTimings* timings, std::string* why) override {
    if (!p.IsValid(why)) return false;
    image->create(64, 64, CV_8UC3);
    image->setTo(cv::Scalar::all(static_cast<double>(paint_ >= 0 ? paint_ : p.sequence % 256)));
    if (timings) timings->total_ms = 1;
    return true;
  }
  const AvatarCommonConfig& common_config() const override { return config_; }
  std::string kind() const override { return "fake"; }
  const SubjectParams& subject() const override { return subject_; }

 private:
  int paint_;
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

TEST_F(RenderLoopTest, TicksWithoutNewFramesReachTheDisplayAndItMayEndTheLoop) {
  // Three frames half a second apart at 30 ticks a second: most ticks have nothing new.
  std::vector<FrameParams> sparse = {frames_[0], frames_[1], frames_[2]};
  for (int i = 0; i < 3; ++i) sparse[i].capture_time_s = 0.5 * i;
  {
    SequenceSource source(sparse, /*paced=*/true);
    FakeDisplay display;
    const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, RenderLoopOptions());
    EXPECT_EQ(display.shown, 3);
    EXPECT_GT(s.idle_ticks, 10);
    EXPECT_EQ(display.idled, s.idle_ticks);  // a virtual camera writes a frame at each of them
  }
  SequenceSource source(sparse, /*paced=*/true);
  FakeDisplay display;
  display.idle_quit_after = 5;  // the output went away (a closed pipe)
  const RenderLoopStats s = RunRenderLoop(*renderer_, source, display, RenderLoopOptions());
  EXPECT_EQ(display.idled, 5);
  EXPECT_EQ(display.shown, 1);
  EXPECT_LT(s.seconds, 0.45);
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

TEST_F(RenderLoopTest, CaptureTimesThatCannotBePacedAreRefusedNotWaitedFor) {
  for (double bad : {std::nan(""), 1e300}) {
    std::vector<FrameParams> frames = frames_;
    frames[5].capture_time_s = bad;
    EXPECT_THROW(SequenceSource(frames, /*paced=*/true), std::invalid_argument) << bad;
  }
  std::vector<FrameParams> far = frames_;
  far[5].capture_time_s = 1e300;
  EXPECT_NO_THROW(SequenceSource(far, /*paced=*/false));  // unpaced export does not wait for times
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

// One sender of a receiver's in-memory session: Hello, then frames on demand.
class RawSender {
 public:
  RawSender(ReceiverSessions& receiver, const HeadModel& model, const std::string& avatar, const std::string& name)
      : pair_(MakeInMemoryChannelPair("0123456789abcdef")), encoder_(CodecLayout::FromModel(model)), model_(model) {
    serve_ = std::thread([&receiver, this] { receiver.Serve(*pair_.receiver); });
    v1::Uplink hello;
    hello.mutable_hello()->set_protocol_version(kProtocolVersion);
    hello.mutable_hello()->set_avatar_id(avatar);
    hello.mutable_hello()->set_sender_name(name);
    ToProto(CodecLayout::FromModel(model), 30, hello.mutable_hello()->mutable_layout());
    EXPECT_TRUE(pair_.sender->Write(hello));
    v1::Downlink reply;
    EXPECT_TRUE(pair_.sender->Read(&reply));
    EXPECT_TRUE(reply.has_welcome()) << reply.DebugString();
  }
  ~RawSender() {
    pair_.sender->Cancel();
    serve_.join();
  }
  void Send() {
    FrameParams f = SyntheticTalkingHead(model_, static_cast<int>(sequence_));
    f.sequence = sequence_++;
    f.capture_time_s = SteadyNowSeconds();
    v1::Uplink up;
    up.mutable_frames()->set_payload(PackPackets({encoder_.Encode(f)}));
    up.mutable_frames()->set_count(1);
    up.mutable_frames()->set_first_capture_time_s(f.capture_time_s);
    EXPECT_TRUE(pair_.sender->Write(up));
  }

 private:
  InMemoryChannelPair pair_;
  ParamEncoder encoder_;
  const HeadModel& model_;
  uint64_t sequence_ = 0;
  std::thread serve_;
};

// Feeds every sender a frame per 20 ms while `keep` says so (per sender).
std::optional<std::string> ShownAvatarAfter(SessionFrameSource& source, std::vector<RawSender*> senders,
                                            std::vector<bool> keep, double seconds) {
  std::optional<std::string> shown;
  const double end = SteadyNowSeconds() + seconds;
  while (SteadyNowSeconds() < end) {
    for (size_t i = 0; i < senders.size(); ++i)
      if (keep[i]) senders[i]->Send();
    bool finished = false;
    shown.reset();
    if (source.Next(0, &finished)) shown = source.shown().avatar_id;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return shown;
}

TEST_F(RenderLoopTest, EachSessionIsShownWithItsOwnAvatarAndASilentOneIsPassedOver) {
  ReceiverSessionOptions o;
  o.tokens = {"0123456789abcdef"};
  o.target_delay_s = 0.05;
  const AvatarEntry entry{model_->fingerprint(), model_->num_expression()};
  ReceiverSessions receiver(o, {{"rand", entry}, {"demo", entry}});
  RawSender alice(receiver, *model_, "rand", "alice");
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // alice's session is the older one
  RawSender bob(receiver, *model_, "demo", "bob");
  SessionFrameSource first(receiver, ShowPolicy::Parse("first"));
  EXPECT_EQ(ShownAvatarAfter(first, {&alice, &bob}, {true, true}, 0.4), "rand");
  SessionFrameSource named(receiver, ShowPolicy::Parse("name:bob"));
  EXPECT_EQ(ShownAvatarAfter(named, {&alice, &bob}, {true, true}, 0.4), "demo");
  SessionFrameSource latest(receiver, ShowPolicy::Parse("latest"));
  EXPECT_EQ(ShownAvatarAfter(latest, {&alice, &bob}, {true, true}, 0.4), "demo");
  // Alice stops sending but stays connected: once her buffer has nothing to show, bob is shown.
  EXPECT_EQ(ShownAvatarAfter(first, {&alice, &bob}, {false, true}, 1.0), "demo");

  // Through the render loop: bob's frames are drawn with bob's avatar.
  std::map<std::string, std::unique_ptr<AvatarBackend>> avatars;
  avatars["rand"] = std::make_unique<FakeBackend>(10);
  avatars["demo"] = std::make_unique<FakeBackend>(200);
  FakeDisplay display;
  display.size = 64;
  RenderLoopOptions loop;
  loop.max_seconds = 0.5;
  std::atomic<bool> sending{true};
  std::thread feed([&] {
    while (sending) {
      bob.Send();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
  RunRenderLoop([&]() -> AvatarBackend& { return *avatars.at(first.shown().avatar_id); }, first, display, loop);
  sending = false;
  feed.join();
  ASSERT_FALSE(display.first_pixel.empty());
  for (int v : display.first_pixel) EXPECT_EQ(v, 200);
  EXPECT_THROW(ShowPolicy::Parse("oldest"), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
