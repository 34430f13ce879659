// The virtual camera and the raw pipe: V4L2 output negotiation and writing
// against a fake device that behaves like v4l2loopback, the pictures read
// back through the same decoding the capture side uses, frames that keep
// flowing between sessions, a pipe whose reader leaves. On a machine with a
// v4l2loopback device, the receiver's frames read back through headcast's own
// V4L2 capture source.
#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "common/capture/v4l2_source.h"
#include "receiver/display/display.h"
#include "receiver/display/raw_frames.h"
#include "receiver/display/stream_display.h"
#include "receiver/display/v4l2_output.h"

namespace headcast {
namespace {

// What v4l2loopback does with the calls the output makes.
class FakeLoopback : public V4l2OutputDevice {
 public:
  uint32_t caps = V4L2_CAP_VIDEO_OUTPUT | V4L2_CAP_READWRITE | V4L2_CAP_STREAMING;
  std::vector<uint32_t> offered = {V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_YUV420, V4L2_PIX_FMT_RGB24};
  cv::Size keeps_size;        // non-empty: the device keeps this size whatever is asked
  uint32_t pad_lines_to = 0;  // non-zero: bytesperline rounded up to this
  bool rate_settable = true;
  int fail_writes_after = -1;  // >= 0: writes fail with ENODEV after this many frames
  std::vector<std::string> frames;
  double fps = 0;
  v4l2_pix_format set{};

  int Ioctl(unsigned long request, void* arg) override {
    switch (request) {
      case VIDIOC_QUERYCAP: {
        auto* c = static_cast<v4l2_capability*>(arg);
        std::strcpy(reinterpret_cast<char*>(c->driver), "v4l2 loopback");
        std::strcpy(reinterpret_cast<char*>(c->card), "headcast test camera");
        c->capabilities = caps | V4L2_CAP_DEVICE_CAPS;
        c->device_caps = caps;
        return 0;
      }
      case VIDIOC_ENUM_FMT: {
        auto* d = static_cast<v4l2_fmtdesc*>(arg);
        if (d->type != V4L2_BUF_TYPE_VIDEO_OUTPUT || d->index >= offered.size()) return Fail(EINVAL);
        d->pixelformat = offered[d->index];
        return 0;
      }
      case VIDIOC_S_FMT: {
        auto* f = static_cast<v4l2_format*>(arg);
        if (f->type != V4L2_BUF_TYPE_VIDEO_OUTPUT) return Fail(EINVAL);
        v4l2_pix_format& p = f->fmt.pix;
        // Like real drivers: an unknown format becomes one the device has.
        if (std::find(offered.begin(), offered.end(), p.pixelformat) == offered.end()) p.pixelformat = offered[0];
        if (!keeps_size.empty()) {
          p.width = keeps_size.width;
          p.height = keeps_size.height;
        }
        const uint32_t bpp = p.pixelformat == V4L2_PIX_FMT_YUYV ? 2 : p.pixelformat == V4L2_PIX_FMT_RGB24 ? 3 : 1;
        p.bytesperline = p.width * bpp;
        if (pad_lines_to) p.bytesperline = (p.bytesperline + pad_lines_to - 1) / pad_lines_to * pad_lines_to;
        p.sizeimage =
            p.pixelformat == V4L2_PIX_FMT_YUV420 ? p.bytesperline * p.height * 3 / 2 : p.bytesperline * p.height;
        set = p;
        return 0;
      }
      case VIDIOC_S_PARM: {
        if (!rate_settable) return Fail(ENOTTY);
        auto* parm = static_cast<v4l2_streamparm*>(arg);
        fps =
            static_cast<double>(parm->parm.output.timeperframe.denominator) / parm->parm.output.timeperframe.numerator;
        return 0;
      }
      default:
        return Fail(ENOTTY);
    }
  }
  ssize_t Write(const void* data, size_t bytes) override {
    if (fail_writes_after >= 0 && static_cast<int>(frames.size()) >= fail_writes_after) return Fail(ENODEV);
    // Takes big frames in two pieces, as a driver may: the writer must finish them.
    const size_t taken = bytes > 4096 && partial_ ? bytes / 2 : bytes;
    pending_.append(static_cast<const char*>(data), taken);
    partial_ = !partial_;
    if (pending_.size() >= set.sizeimage || pending_.size() == expected_) {
      frames.push_back(pending_);
      pending_.clear();
    }
    return static_cast<ssize_t>(taken);
  }
  std::string path() const override { return "/dev/fake-video9"; }
  size_t expected_ = 0;  // the frame size the writer negotiated

 private:
  static int Fail(int e) {
    errno = e;
    return -1;
  }
  std::string pending_;
  bool partial_ = true;
};

// A smooth picture (chroma subsampling keeps it) with a mark in one corner,
// so a flipped or shifted copy fails.
cv::Mat Picture(int w = 200, int h = 240) {
  cv::Mat m(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      m.at<cv::Vec3b>(y, x) = cv::Vec3b(40 + (150 * x) / w, 60 + (120 * y) / h, 200 - (100 * (x + y)) / (w + h));
  cv::rectangle(m, cv::Rect(8, 8, 30, 30), cv::Scalar(250, 250, 250), cv::FILLED);
  return m;
}

double Psnr(const cv::Mat& a, const cv::Mat& b) { return cv::PSNR(a, b); }

struct Camera {
  FakeLoopback* device = nullptr;
  std::unique_ptr<StreamDisplay> display;
  V4l2OutputFormat format;
};

Camera OpenFake(std::unique_ptr<FakeLoopback> fake, const V4l2OutputRequest& request, double hold_s = 2,
                cv::Scalar background = {64, 177, 0}) {
  Camera c;
  c.device = fake.get();
  c.format = NegotiateV4l2Output(*fake, request);
  fake->expected_ = c.format.frame_bytes;
  StreamDisplayOptions s;
  s.size = c.format.size;
  s.format = c.format.format;
  s.background = background;
  s.hold_s = hold_s;
  c.display = std::make_unique<StreamDisplay>(std::make_unique<V4l2Sink>(std::move(fake), c.format), s, "v4l2");
  return c;
}

std::string NegotiationError(std::unique_ptr<FakeLoopback> fake, const V4l2OutputRequest& request) {
  try {
    NegotiateV4l2Output(*fake, request);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(RawFrames, YuvFramesDecodeBackToThePicture) {
  const cv::Mat picture = Picture(320, 240);
  for (RawPixelFormat f : {RawPixelFormat::kBgr24, RawPixelFormat::kYuyv, RawPixelFormat::kI420}) {
    std::string raw;
    ToRawFrame(picture, f, &raw);
    ASSERT_EQ(raw.size(), RawFrameBytes(f, 320, 240));
    cv::Mat back;
    ASSERT_TRUE(FromRawFrame(raw, f, {320, 240}, &back));
    if (f == RawPixelFormat::kBgr24)
      EXPECT_EQ(cv::norm(back, picture, cv::NORM_INF), 0);
    else
      EXPECT_GT(Psnr(back, picture), 38) << FfmpegPixelFormatName(f);
    EXPECT_FALSE(FromRawFrame(raw.substr(1), f, {320, 240}, &back));
  }
  // Limited range, as players assume: white is Y 235, black Y 16.
  std::string raw;
  ToRawFrame(cv::Mat(2, 2, CV_8UC3, cv::Scalar(255, 255, 255)), RawPixelFormat::kI420, &raw);
  EXPECT_EQ(static_cast<uint8_t>(raw[0]), 235);
  ToRawFrame(cv::Mat(2, 2, CV_8UC3, cv::Scalar(0, 0, 0)), RawPixelFormat::kYuyv, &raw);
  EXPECT_EQ(static_cast<uint8_t>(raw[0]), 16);
  EXPECT_EQ(static_cast<uint8_t>(raw[1]), 128);
  EXPECT_THROW(ToRawFrame(cv::Mat(3, 3, CV_8UC3), RawPixelFormat::kYuyv, &raw), std::invalid_argument);
}

TEST(RawFrames, ThePictureKeepsItsAspectOnTheBackground) {
  const cv::Scalar green(64, 177, 0);
  const cv::Mat canvas = PlaceOnCanvas(Picture(200, 240), {640, 480}, green);
  ASSERT_EQ(canvas.size(), cv::Size(640, 480));
  // 200x240 fills the height: 400x480 in the middle, green bars of 120 each side.
  EXPECT_EQ(canvas.at<cv::Vec3b>(240, 60), cv::Vec3b(64, 177, 0));
  EXPECT_EQ(canvas.at<cv::Vec3b>(240, 579), cv::Vec3b(64, 177, 0));
  cv::Mat inner;
  cv::resize(Picture(200, 240), inner, {400, 480}, 0, 0, cv::INTER_CUBIC);
  EXPECT_GT(Psnr(canvas(cv::Rect(120, 0, 400, 480)), inner), 40);
  EXPECT_EQ(canvas.at<cv::Vec3b>(30, 150), cv::Vec3b(250, 250, 250));  // the mark, top left of the picture
}

TEST(RawFrames, FlagsAreCheckedAndNamed) {
  EXPECT_EQ(ParseOutputSize("1280x720"), cv::Size(1280, 720));
  for (const char* bad : {"640", "640x", "x480", "641x480", "8x8", "99999x480", "640x480x3", "axb"})
    EXPECT_THROW(ParseOutputSize(bad), std::invalid_argument) << bad;
  EXPECT_EQ(ParseBackground("#FF8000"), cv::Scalar(0, 128, 255));
  EXPECT_EQ(ParseBackground("green"), cv::Scalar(64, 177, 0));
  for (const char* bad : {"#12345", "#GG0000", "purple", ""}) EXPECT_THROW(ParseBackground(bad), std::invalid_argument);
  EXPECT_EQ(ParseRawPixelFormat("yuv420p"), RawPixelFormat::kI420);
  EXPECT_THROW(ParseRawPixelFormat("nv12"), std::invalid_argument);
  std::string device;
  EXPECT_EQ(ParseDisplayKind("v4l2:/dev/video7", &device), DisplayKind::kV4l2);
  EXPECT_EQ(device, "/dev/video7");
  EXPECT_EQ(ParseDisplayKind("pipe"), DisplayKind::kPipe);
  EXPECT_THROW(ParseDisplayKind("v4l2:"), std::invalid_argument);
}

TEST(VirtualCamera, NegotiatesYuyvAndWritesThePicture) {
  auto fake = std::make_unique<FakeLoopback>();
  Camera cam = OpenFake(std::move(fake), V4l2OutputRequest());
  EXPECT_EQ(cam.format.format, RawPixelFormat::kYuyv);
  EXPECT_EQ(cam.format.size, cv::Size(640, 480));
  EXPECT_EQ(cam.format.frame_bytes, 640u * 480 * 2);
  EXPECT_EQ(cam.format.card, "headcast test camera");
  EXPECT_DOUBLE_EQ(cam.device->fps, 30);
  EXPECT_EQ(cam.device->set.colorspace, V4L2_COLORSPACE_SMPTE170M);
  const cv::Mat picture = Picture();
  ASSERT_TRUE(cam.display->Show(picture, {}));
  ASSERT_EQ(cam.device->frames.size(), 1u);  // a whole frame, although the device took it in pieces
  cv::Mat back;
  ASSERT_TRUE(FromRawFrame(cam.device->frames[0], RawPixelFormat::kYuyv, {640, 480}, &back));
  EXPECT_GT(Psnr(back, PlaceOnCanvas(picture, {640, 480}, {64, 177, 0})), 35);
}

TEST(VirtualCamera, TakesI420WhenThatIsWhatTheDeviceHas) {
  auto fake = std::make_unique<FakeLoopback>();
  fake->offered = {V4L2_PIX_FMT_YUV420};
  Camera cam = OpenFake(std::move(fake), V4l2OutputRequest());
  EXPECT_EQ(cam.format.format, RawPixelFormat::kI420);
  ASSERT_TRUE(cam.display->Show(Picture(), {}));
  cv::Mat back;
  ASSERT_TRUE(FromRawFrame(cam.device->frames.at(0), RawPixelFormat::kI420, {640, 480}, &back));
  EXPECT_GT(Psnr(back, PlaceOnCanvas(Picture(), {640, 480}, {64, 177, 0})), 35);
}

TEST(VirtualCamera, UsesTheSizeTheDeviceKeepsAndLivesWithoutARate) {
  auto fake = std::make_unique<FakeLoopback>();
  fake->keeps_size = {320, 240};
  fake->rate_settable = false;
  V4l2OutputRequest request;
  request.size = {1280, 720};
  Camera cam = OpenFake(std::move(fake), request);
  EXPECT_EQ(cam.format.size, cv::Size(320, 240));
  EXPECT_NE(cam.format.why.find("keeps its size"), std::string::npos) << cam.format.why;
  EXPECT_NE(cam.format.why.find("frame rate not set"), std::string::npos) << cam.format.why;
  ASSERT_TRUE(cam.display->Show(Picture(), {}));
  EXPECT_EQ(cam.device->frames.at(0).size(), 320u * 240 * 2);
}

TEST(VirtualCamera, RefusesWhatItCannotWriteSayingWhy) {
  auto capture_only = std::make_unique<FakeLoopback>();
  capture_only->caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
  EXPECT_NE(NegotiationError(std::move(capture_only), {}).find("a camera, not a video output"), std::string::npos);

  auto mjpeg_only = std::make_unique<FakeLoopback>();
  mjpeg_only->offered = {V4L2_PIX_FMT_MJPEG};
  const std::string mjpeg = NegotiationError(std::move(mjpeg_only), {});
  EXPECT_NE(mjpeg.find("MJPG"), std::string::npos) << mjpeg;

  auto no_yuyv = std::make_unique<FakeLoopback>();
  no_yuyv->offered = {V4L2_PIX_FMT_YUV420};
  V4l2OutputRequest yuyv;
  yuyv.pixel_format = "yuyv";
  const std::string asked = NegotiationError(std::move(no_yuyv), yuyv);
  EXPECT_NE(asked.find("YU12"), std::string::npos) << asked;

  auto padded = std::make_unique<FakeLoopback>();
  padded->pad_lines_to = 1024;
  const std::string pad = NegotiationError(std::move(padded), {});
  EXPECT_NE(pad.find("bytes a line"), std::string::npos) << pad;

  V4l2OutputRequest bgr;
  bgr.pixel_format = "bgr24";
  EXPECT_NE(NegotiationError(std::make_unique<FakeLoopback>(), bgr).find("yuyv or i420"), std::string::npos);

  EXPECT_THROW(OpenV4l2OutputDevice("/dev/headcast-no-such-camera"), std::runtime_error);
  EXPECT_THROW(OpenV4l2OutputDevice("/etc/hostname"), std::runtime_error);  // not a device node
  try {
    auto null_device = OpenV4l2OutputDevice("/dev/null");
    NegotiateV4l2Output(*null_device, {});
    ADD_FAILURE() << "/dev/null taken for a camera";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("not a V4L2 device"), std::string::npos) << e.what();
  }
}

TEST(VirtualCamera, FramesKeepFlowingBetweenSessions) {
  auto fake = std::make_unique<FakeLoopback>();
  Camera cam = OpenFake(std::move(fake), V4l2OutputRequest(), /*hold_s=*/0.2, {0, 0, 0});
  auto& frames = cam.device->frames;
  // Before any sender: the waiting card, the background with light text on it.
  ASSERT_TRUE(cam.display->Idle());
  ASSERT_EQ(frames.size(), 1u);
  cv::Mat card;
  ASSERT_TRUE(FromRawFrame(frames[0], RawPixelFormat::kYuyv, {640, 480}, &card));
  cv::Mat gray;
  cv::cvtColor(card, gray, cv::COLOR_BGR2GRAY);
  const int ink = cv::countNonZero(gray > 128);
  EXPECT_GT(ink, 500);
  EXPECT_LT(ink, 640 * 480 / 10);
  // A picture, then idle ticks: the same picture again while the hold lasts...
  ASSERT_TRUE(cam.display->Show(Picture(), {}));
  ASSERT_TRUE(cam.display->Idle());
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[2], frames[1]);
  // ...then the card.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_TRUE(cam.display->Idle());
  EXPECT_EQ(frames[3], frames[0]);
}

TEST(VirtualCamera, ADeviceThatFailsStopsTheOutputWithItsName) {
  auto fake = std::make_unique<FakeLoopback>();
  fake->fail_writes_after = 1;
  Camera cam = OpenFake(std::move(fake), V4l2OutputRequest());
  ASSERT_TRUE(cam.display->Show(Picture(), {}));
  try {
    cam.display->Show(Picture(), {});
    ADD_FAILURE() << "a failed write passed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/fake-video9"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(std::strerror(ENODEV)), std::string::npos) << e.what();
  }
}

TEST(RawPipe, WritesWholeFramesAndEndsWhenTheReaderLeaves) {
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  StreamDisplayOptions s;
  s.size = {64, 48};
  s.format = RawPixelFormat::kBgr24;
  StreamDisplay display(std::make_unique<PipeSink>(fds[1]), s, "pipe");
  std::string got;
  std::thread reader([&] {
    char buf[4096];
    while (got.size() < 2 * 64 * 48 * 3) {
      const ssize_t n = read(fds[0], buf, sizeof(buf));
      if (n <= 0) break;
      got.append(buf, static_cast<size_t>(n));
    }
  });
  ASSERT_TRUE(display.Show(Picture(64, 48), {}));
  ASSERT_TRUE(display.Idle());
  reader.join();
  ASSERT_EQ(got.size(), 2u * 64 * 48 * 3);
  cv::Mat back;
  ASSERT_TRUE(FromRawFrame(got.substr(0, 64 * 48 * 3), RawPixelFormat::kBgr24, {64, 48}, &back));
  EXPECT_EQ(cv::norm(back, PlaceOnCanvas(Picture(64, 48), {64, 48}, {0, 0, 0}), cv::NORM_INF), 0);
  close(fds[0]);
  EXPECT_FALSE(display.Show(Picture(64, 48), {}));  // EPIPE: the stream ends, the process lives
  close(fds[1]);
}

// Where the machine has a v4l2loopback device (modprobe v4l2loopback
// exclusive_caps=1): write through the receiver's output, read back through
// headcast's own capture source.
TEST(VirtualCamera, ReadsBackThroughHeadcastsCaptureOnARealLoopbackDevice) {
  const std::vector<std::string> devices = FindV4l2LoopbackDevices();
  if (devices.empty())
    GTEST_SKIP() << "no v4l2loopback device here (sudo modprobe v4l2loopback exclusive_caps=1 card_label=headcast)";
  DisplayOptions o;
  o.kind = DisplayKind::kV4l2;
  o.device = devices[0];
  o.output_format = "yuyv";
  auto display = MakeDisplay(o);
  const cv::Mat picture = Picture();
  std::atomic<bool> writing{true};
  std::thread writer([&] {
    while (writing) {
      display->Show(picture, {});
      std::this_thread::sleep_for(std::chrono::milliseconds(33));
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  SourceOptions so;
  so.width = 640;
  so.height = 480;
  so.pixel_format = "yuyv";
  cv::Mat back;
  {
    V4l2Source camera(devices[0], so);
    CapturedFrame frame;
    std::string problem;
    for (int i = 0; i < 5; ++i) ASSERT_EQ(camera.Read(&frame, &problem), ReadStatus::kFrame) << problem;
    back = frame.bgr;
  }
  writing = false;
  writer.join();
  EXPECT_GT(Psnr(back, PlaceOnCanvas(picture, {640, 480}, {0, 0, 0})), 30);
}

}  // namespace
}  // namespace headcast
