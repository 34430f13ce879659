// Frame sources: V4L2 negotiation on fake device descriptions and errors on
// missing/non-V4L2 devices; recorded sequences (video, images, pacing, loops,
// corrupt frames); RGB-D folders; stereo calibration files; stereo depth on a
// synthetic side-by-side pair and the disparity error on the real aloe pair.
#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <thread>

#include "common/capture/frame_source.h"
#include "common/capture/newest_frame_source.h"
#include "common/capture/recorded_sources.h"
#include "common/capture/stereo_depth.h"
#include "common/capture/v4l2_source.h"
#include "common/core/image_io.h"
#include "common/core/median.h"
#include "common/core/timer.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

namespace fs = std::filesystem;

// A typical USB webcam: YUYV is slow at large sizes, MJPEG is not.
std::vector<V4l2Mode> Webcam() {
  return {{V4L2_PIX_FMT_YUYV, 640, 480, {30, 15}}, {V4L2_PIX_FMT_YUYV, 1280, 720, {10, 5}},
          {V4L2_PIX_FMT_MJPEG, 640, 480, {30}},    {V4L2_PIX_FMT_MJPEG, 1280, 720, {30, 15}},
          {V4L2_PIX_FMT_MJPEG, 1920, 1080, {30}},  {v4l2_fourcc('H', '2', '6', '4'), 1920, 1080, {30}}};
}

// A camera stand-in: `count` frames, one every `interval`; frame 3 unreadable;
// optionally failing for good after the last.
class TimedSource : public FrameSource {
 public:
  TimedSource(int count, std::chrono::milliseconds interval, bool fail_at_end)
      : count_(count), interval_(interval), fail_at_end_(fail_at_end) {}
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override {
    std::this_thread::sleep_for(interval_);
    if (next_ == count_) {
      if (fail_at_end_) throw std::runtime_error("camera unplugged");
      return ReadStatus::kEnd;
    }
    const int i = next_++;
    if (i == 3) {
      *problem = "frame 3 unreadable";
      return ReadStatus::kSkipped;
    }
    frame->bgr = cv::Mat(2, 2, CV_8UC3, cv::Scalar::all(i));
    frame->index = i;
    return ReadStatus::kFrame;
  }
  std::string Describe() const override { return "timed"; }
  double fps() const override { return 1000.0 / interval_.count(); }

 private:
  int count_, next_ = 0;
  std::chrono::milliseconds interval_;
  bool fail_at_end_;
};

TEST(NewestFrameSource, ASlowReaderGetsTheNewestFramesAndTheRestAreCountedDropped) {
  NewestFrameSource source(std::make_unique<TimedSource>(40, std::chrono::milliseconds(5), false));
  std::vector<uint64_t> got;
  CapturedFrame f;
  std::string problem;
  for (ReadStatus st; (st = source.Read(&f, &problem)) != ReadStatus::kEnd;) {
    if (st != ReadStatus::kFrame) continue;
    got.push_back(f.index);
    std::this_thread::sleep_for(std::chrono::milliseconds(40));  // a tracker eight times slower than the camera
  }
  ASSERT_GE(got.size(), 3u);
  EXPECT_LT(got.size(), 20u) << "a slow reader must not see every frame";
  for (size_t i = 1; i < got.size(); ++i) EXPECT_GT(got[i], got[i - 1]);
  EXPECT_EQ(got.back(), 39u) << "the last frame the camera gave is the last read";
  EXPECT_EQ(got.size() + source.dropped(), 39u) << "every good frame was read or counted dropped";
}

TEST(NewestFrameSource, ProblemsAndAFailingSourceAreSaid) {
  NewestFrameSource source(std::make_unique<TimedSource>(5, std::chrono::milliseconds(20), true));
  CapturedFrame f;
  std::string problem;
  std::vector<std::string> problems;
  int frames = 0;
  for (ReadStatus st; (st = source.Read(&f, &problem)) != ReadStatus::kEnd;) {
    if (st == ReadStatus::kSkipped) problems.push_back(problem);
    if (st == ReadStatus::kFrame) ++frames;
  }
  EXPECT_EQ(frames, 4);  // a fast reader misses nothing
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0], "frame 3 unreadable");
  EXPECT_EQ(problem, "camera unplugged") << "the end says why";
  EXPECT_EQ(source.dropped(), 0u);
}

TEST(V4l2Negotiation, PicksTheClosestModeAFrameRateCanKeepUpWith) {
  V4l2Choice c;
  std::string why;
  V4l2Request r;  // 640x480 at 30, auto
  ASSERT_TRUE(NegotiateV4l2Mode(Webcam(), r, &c, &why)) << why;
  EXPECT_EQ(c.mode.fourcc, static_cast<uint32_t>(V4L2_PIX_FMT_YUYV));  // no decoding when equal
  EXPECT_EQ(c.mode.width, 640);
  EXPECT_DOUBLE_EQ(c.fps, 30);
  r.width = 1280;
  r.height = 720;
  ASSERT_TRUE(NegotiateV4l2Mode(Webcam(), r, &c, &why));
  EXPECT_EQ(c.mode.fourcc, static_cast<uint32_t>(V4L2_PIX_FMT_MJPEG)) << c.why;  // YUYV only manages 10 fps there
  EXPECT_EQ(c.mode.width, 1280);
  r.pixel_format = "yuyv";  // asked for explicitly: the rate is what it is
  ASSERT_TRUE(NegotiateV4l2Mode(Webcam(), r, &c, &why));
  EXPECT_EQ(c.mode.fourcc, static_cast<uint32_t>(V4L2_PIX_FMT_YUYV));
  EXPECT_EQ(c.mode.width, 1280);
  EXPECT_DOUBLE_EQ(c.fps, 10);
  r = V4l2Request();
  r.width = 800;
  r.height = 600;  // not offered: the next larger wins over the smaller
  ASSERT_TRUE(NegotiateV4l2Mode(Webcam(), r, &c, &why));
  EXPECT_EQ(c.mode.width, 1280);
  r = V4l2Request();
  r.fps = 20;  // the lowest rate at least the one asked for
  ASSERT_TRUE(NegotiateV4l2Mode(Webcam(), r, &c, &why));
  EXPECT_DOUBLE_EQ(c.fps, 30);
  // A device that lists no rates: take the request.
  ASSERT_TRUE(NegotiateV4l2Mode({{V4L2_PIX_FMT_MJPEG, 640, 480, {}}}, V4l2Request(), &c, &why));
  EXPECT_DOUBLE_EQ(c.fps, 30);
}

TEST(V4l2Negotiation, SaysWhyNothingFits) {
  V4l2Choice c;
  std::string why;
  EXPECT_FALSE(NegotiateV4l2Mode({{v4l2_fourcc('G', 'R', 'E', 'Y'), 640, 480, {30}}}, V4l2Request(), &c, &why));
  EXPECT_NE(why.find("YUYV and MJPEG"), std::string::npos) << why;
  EXPECT_NE(why.find("GREY 640x480"), std::string::npos) << why;
  EXPECT_FALSE(NegotiateV4l2Mode({}, V4l2Request(), &c, &why));
  EXPECT_NE(why.find("offers: nothing"), std::string::npos) << why;
  V4l2Request r;
  r.pixel_format = "h264";
  EXPECT_FALSE(NegotiateV4l2Mode(Webcam(), r, &c, &why));
  EXPECT_NE(why.find("unknown pixel format"), std::string::npos);
}

std::string OpenError(const std::string& spec, const SourceOptions& o = {}) {
  try {
    OpenFrameSource(spec, o);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "opened";
}

TEST(V4l2Source, MissingAndForeignDevicesAreRefusedClearly) {
  EXPECT_NE(OpenError("/dev/video97").find("no such device"), std::string::npos) << OpenError("/dev/video97");
  EXPECT_NE(OpenError("v4l2:/dev/null").find("not a V4L2 device"), std::string::npos) << OpenError("v4l2:/dev/null");
}

// Only where a camera exists: it opens, negotiates and delivers frames.
TEST(V4l2Source, RealCameraWhenPresent) {
  if (!fs::exists("/dev/video0")) GTEST_SKIP() << "no /dev/video0 on this machine";
  std::unique_ptr<FrameSource> cam;
  try {
    cam = OpenFrameSource("/dev/video0", SourceOptions{});
  } catch (const std::exception& e) {
    GTEST_SKIP() << "/dev/video0 is not a usable camera: " << e.what();
  }
  CapturedFrame f;
  std::string problem;
  int frames = 0;
  for (int i = 0; i < 10; ++i) frames += cam->Read(&f, &problem) == ReadStatus::kFrame;
  EXPECT_GT(frames, 5) << problem;
  EXPECT_FALSE(f.bgr.empty());
  EXPECT_NEAR(f.capture_time_s, SteadyNowSeconds(), 1.0);
}

cv::Mat Pattern(int i, int w = 64, int h = 48) {
  cv::Mat m(h, w, CV_8UC3, cv::Scalar(10 * i, 100, 200 - 10 * i));
  cv::circle(m, {w / 2, h / 2}, 5 + i, cv::Scalar(255, 255, 255), cv::FILLED);
  return m;
}

TEST(RecordedSources, ImageFoldersSkipCorruptFilesPaceAndLoop) {
  const std::string dir = testing::TempDir("images");
  for (int i = 0; i < 3; ++i) WriteImage(dir + "/f" + std::to_string(i) + ".png", Pattern(i));
  std::ofstream(dir + "/f1b.png") << "not a png";  // sorted between f1 and f2
  SourceOptions o;
  o.realtime = true;
  o.fps = 50;
  auto src = OpenFrameSource(dir, o);
  CapturedFrame f;
  std::string problem;
  std::vector<ReadStatus> got;
  Stopwatch watch;
  for (ReadStatus s; (s = src->Read(&f, &problem)) != ReadStatus::kEnd;) got.push_back(s);
  EXPECT_EQ(
      got, (std::vector<ReadStatus>{ReadStatus::kFrame, ReadStatus::kFrame, ReadStatus::kSkipped, ReadStatus::kFrame}));
  EXPECT_NE(problem.find("f1b.png"), std::string::npos) << problem;
  EXPECT_GE(watch.ElapsedSeconds(), 3 / 50.0 - 1e-3);  // four frames at 50 fps: the last is due after 60 ms
  o.realtime = false;
  o.loop = true;
  auto looping = OpenFrameSource(dir, o);
  int frames = 0;
  for (int i = 0; i < 12; ++i) frames += looping->Read(&f, &problem) == ReadStatus::kFrame;
  EXPECT_EQ(frames, 9);                           // three passes of four files, one of them corrupt
  EXPECT_DOUBLE_EQ(f.capture_time_s, 11 / 50.0);  // media time when not paced
  const std::string empty = testing::TempDir("empty");
  EXPECT_NE(OpenError(empty).find("no images"), std::string::npos);
  EXPECT_NE(OpenError(dir + "/nothing_here.mp4").find("no such file"), std::string::npos);
}

TEST(RecordedSources, VideoFilesReadLoopAndSayWhenTruncated) {
  const std::string dir = testing::TempDir("video");
  {
    VideoWriter w(dir + "/v.mp4", 25);
    for (int i = 0; i < 20; ++i) w.Write(Pattern(i, 64, 48));
  }
  SourceOptions o;
  auto src = OpenFrameSource(dir + "/v.mp4", o);
  EXPECT_DOUBLE_EQ(src->fps(), 25);
  CapturedFrame f;
  std::string problem;
  int frames = 0;
  while (src->Read(&f, &problem) == ReadStatus::kFrame) ++frames;
  EXPECT_EQ(frames, 20);
  o.loop = true;
  auto looping = OpenFrameSource(dir + "/v.mp4", o);
  for (int i = 0; i < 45; ++i) ASSERT_EQ(looping->Read(&f, &problem), ReadStatus::kFrame) << i;
  EXPECT_EQ(f.index, 44u);
  // A truncated file: whatever decodes, then the end; never a crash.
  const auto size = fs::file_size(dir + "/v.mp4");
  {
    std::ifstream in(dir + "/v.mp4", std::ios::binary);
    std::string bytes(size / 2, '\0');
    in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    std::ofstream(dir + "/cut.mp4", std::ios::binary) << bytes;
  }
  try {
    auto cut = OpenFrameSource(dir + "/cut.mp4", SourceOptions{});
    int n = 0;
    while (cut->Read(&f, &problem) == ReadStatus::kFrame) ++n;
    EXPECT_LT(n, 20);
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("cut.mp4"), std::string::npos) << e.what();
  }
}

TEST(RgbdFolder, ReadsMillimetreDepthAndSkipsBadPairs) {
  const std::string dir = testing::TempDir("rgbd");
  fs::create_directories(dir + "/rgb");
  fs::create_directories(dir + "/depth");
  std::ofstream assoc(dir + "/associations.txt");
  assoc << "# t rgb t depth\n";
  for (int i = 0; i < 4; ++i) {
    const std::string name = std::to_string(i) + ".png";
    WriteImage(dir + "/rgb/" + name, Pattern(i));
    cv::Mat depth(48, 64, CV_16UC1, cv::Scalar(600 + 100 * i));  // millimetres
    depth(cv::Rect(0, 0, 8, 8)) = 0;                             // unknown
    if (i == 1)
      cv::imwrite(dir + "/depth/" + name, cv::Mat(48, 64, CV_8UC1, cv::Scalar(7)));  // 8-bit: refused
    else if (i == 2)
      cv::imwrite(dir + "/depth/" + name, cv::Mat(24, 32, CV_16UC1, cv::Scalar(600)));  // wrong size
    else
      cv::imwrite(dir + "/depth/" + name, depth);
    assoc << 0.1 * i << " rgb/" << name << " " << 0.1 * i + 0.01 << " depth/" << name << "\n";
  }
  assoc << 0.4 << " rgb/0.png " << 0.41 << " depth/missing.png\n";
  assoc.close();
  auto src = OpenFrameSource(dir, SourceOptions{});  // finds associations.txt
  EXPECT_TRUE(src->has_depth());
  EXPECT_NEAR(src->fps(), 10, 1e-9);
  CapturedFrame f;
  std::string problem;
  ASSERT_EQ(src->Read(&f, &problem), ReadStatus::kFrame);
  EXPECT_FLOAT_EQ(f.depth_m.at<float>(20, 20), 0.6f);
  EXPECT_FLOAT_EQ(f.depth_m.at<float>(2, 2), 0.f);
  EXPECT_EQ(src->Read(&f, &problem), ReadStatus::kSkipped);
  EXPECT_NE(problem.find("16-bit"), std::string::npos) << problem;
  EXPECT_EQ(src->Read(&f, &problem), ReadStatus::kSkipped);
  EXPECT_NE(problem.find("32x24"), std::string::npos) << problem;
  ASSERT_EQ(src->Read(&f, &problem), ReadStatus::kFrame);
  EXPECT_FLOAT_EQ(f.depth_m.at<float>(20, 20), 0.9f);
  EXPECT_EQ(src->Read(&f, &problem), ReadStatus::kSkipped);
  EXPECT_NE(problem.find("unreadable depth"), std::string::npos) << problem;
  EXPECT_EQ(src->Read(&f, &problem), ReadStatus::kEnd);
  std::ofstream(dir + "/bad.txt") << "0.1 rgb/0.png\n";
  SourceOptions o;
  o.depth_input = dir + "/bad.txt";
  EXPECT_NE(OpenError(dir, o).find("line 1"), std::string::npos) << OpenError(dir, o);
}

void WriteZedConf(const std::string& path, double baseline_mm) {
  std::ofstream f(path);
  f << "[LEFT_CAM_HD]\ncx=640.5\ncy=360.2\nfx=700\nfy=700\nk1=0\nk2=0\np1=0\np2=0\nk3=0\n\n"
    << "[RIGHT_CAM_HD]\ncx=640.5\ncy=360.2\nfx=700\nfy=700\nk1=0\nk2=0\np1=0\np2=0\nk3=0\n\n"
    << "[STEREO]\nBaseline=" << baseline_mm << "\nTY=0\nTZ=0\nCV_HD=0\nRX_HD=0\nRZ_HD=0\n";
}

TEST(StereoCalibration, ReadsZedConfAndYamlAndRefusesBadFiles) {
  const std::string dir = testing::TempDir("calib");
  WriteZedConf(dir + "/SN1.conf", 120);
  const StereoCalibration zed = ReadStereoCalibration(dir + "/SN1.conf", "HD");
  EXPECT_EQ(zed.size, cv::Size(1280, 720));
  EXPECT_NEAR(zed.T.at<double>(0), -0.12, 1e-12);
  EXPECT_DOUBLE_EQ(zed.K1.at<double>(0, 0), 700);
  {
    cv::FileStorage fs(dir + "/c.yml", cv::FileStorage::WRITE);
    fs << "image_width" << 1280 << "image_height" << 720 << "K1" << zed.K1 << "D1" << zed.D1 << "K2" << zed.K2 << "D2"
       << zed.D2 << "R" << zed.R << "T" << zed.T;
  }
  const StereoCalibration yaml = ReadStereoCalibration(dir + "/c.yml");
  EXPECT_EQ(cv::norm(yaml.T - zed.T), 0);
  auto error = [](const std::string& path, const std::string& res = "HD") {
    try {
      ReadStereoCalibration(path, res);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("read");
  };
  EXPECT_NE(error(dir + "/SN1.conf", "8K").find("2K, FHD, HD or VGA"), std::string::npos);
  std::ofstream(dir + "/SN2.conf") << "[LEFT_CAM_HD]\nfx=abc\n";
  EXPECT_NE(error(dir + "/SN2.conf").find("not a number"), std::string::npos) << error(dir + "/SN2.conf");
  std::ofstream(dir + "/SN3.conf") << "[LEFT_CAM_HD]\nfx=700\n";
  EXPECT_NE(error(dir + "/SN3.conf").find("in [LEFT_CAM_HD]"), std::string::npos) << error(dir + "/SN3.conf");
  std::ofstream(dir + "/d.yml") << "%YAML:1.0\nimage_width: 10\n";
  EXPECT_NE(error(dir + "/d.yml").find("image size missing"), std::string::npos) << error(dir + "/d.yml");
  EXPECT_NE(error(dir + "/none.yml").find("none.yml"), std::string::npos);
  EXPECT_NE(OpenError("zed:/dev/video0").find("needs a calibration"), std::string::npos);
}

// A textured plane at 0.8 m seen by a 12 cm-baseline pair, side by side, through
// the whole source: the depth comes back within 2 % over the overlap.
TEST(StereoDepth, SideBySideFramesGiveMetricDepth) {
  const std::string dir = testing::TempDir("zed");
  WriteZedConf(dir + "/SN1.conf", 120);
  const double z = 0.8, f = 700, baseline = 0.12, disparity = f * baseline / z;  // 105 px
  cv::Mat texture(720, 1280 + 200, CV_8UC3);
  cv::RNG rng(4);
  rng.fill(texture, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(texture, texture, {5, 5}, 1.2);
  // Left sees columns [100, 1380), the right camera (to the right) the same points 105 px further left.
  cv::Mat both(720, 2560, CV_8UC3);
  texture(cv::Rect(100, 0, 1280, 720)).copyTo(both(cv::Rect(0, 0, 1280, 720)));
  texture(cv::Rect(100 + static_cast<int>(disparity), 0, 1280 - 95, 720))
      .copyTo(both(cv::Rect(1280, 0, 1280 - 95, 720)));
  fs::create_directories(dir + "/frames");
  WriteImage(dir + "/frames/0.png", both);
  WriteImage(dir + "/frames/1.png", Pattern(1));  // the wrong size: a per-frame status
  SourceOptions o;
  o.stereo_calibration = dir + "/SN1.conf";
  auto src = OpenFrameSource("zed:" + dir + "/frames", o);
  ASSERT_TRUE(src->has_depth());
  CapturedFrame frame;
  std::string problem;
  ASSERT_EQ(src->Read(&frame, &problem), ReadStatus::kFrame) << problem;
  ASSERT_TRUE(frame.camera.has_value());
  EXPECT_NEAR(frame.camera->fx, 700, 1e-6);
  ASSERT_TRUE(frame.has_depth());
  ASSERT_TRUE(frame.depth_m.empty());  // made on demand, where the tracker asks
  ASSERT_NE(frame.depth_on_demand, nullptr);
  const cv::Rect box(400, 200, 600, 300);
  const cv::Mat depth = frame.depth_on_demand->DepthIn(box);
  EXPECT_EQ(depth.size(), cv::Size(1280, 720));
  EXPECT_EQ(cv::countNonZero(depth) - cv::countNonZero(depth(box)), 0);  // nothing outside the box
  const cv::Mat centre = depth(box);
  std::vector<float> values(centre.begin<float>(), centre.end<float>());
  const float median = MedianInPlace(values);
  int good = 0;
  for (float v : values) good += std::abs(v - z) < 0.02 * z;
  std::printf("synthetic plane at %.2f m: median depth %.4f m, %.1f %% of pixels within 2 %%\n", z, median,
              100.0 * good / values.size());
  EXPECT_NEAR(median, z, 0.01 * z);
  EXPECT_GT(good, 0.9 * values.size());
  // The box matched alone gives what matching the whole frame gives there.
  StereoDepth whole(ReadStereoCalibration(dir + "/SN1.conf", "HD"), o.depth_scale, o.wls_filter);
  cv::Mat rectified, full;
  whole.Compute(both(cv::Rect(0, 0, 1280, 720)), both(cv::Rect(1280, 0, 1280, 720)), &rectified, &full);
  // Pixels of the box where two depth images agree within a tolerance.
  auto agreeing = [&](const cv::Mat& a, const cv::Mat& b, float tolerance) {
    cv::Mat differs;
    cv::absdiff(a(box), b(box), differs);
    return cv::countNonZero(differs < tolerance);
  };
  EXPECT_GT(agreeing(full, depth, 0.01f * z), 0.95 * box.area());
  // Searched only around the expected depth: the same depths there; far from it, none right.
  EXPECT_GT(agreeing(frame.depth_on_demand->DepthIn(box, 0.6, 1.0), depth, 0.01f * z), 0.95 * box.area());
  const cv::Mat plane(depth.size(), CV_32F, cv::Scalar(z));
  EXPECT_LT(agreeing(frame.depth_on_demand->DepthIn(box, 0.3, 0.5), plane, 0.02f * z), 0.01 * box.area());
  // A box off the frame, or too small to match, gives no depth.
  EXPECT_EQ(cv::countNonZero(frame.depth_on_demand->DepthIn(cv::Rect(2000, 0, 100, 100))), 0);
  EXPECT_EQ(cv::countNonZero(frame.depth_on_demand->DepthIn(cv::Rect(10, 10, 4, 4))), 0);
  EXPECT_EQ(src->Read(&frame, &problem), ReadStatus::kSkipped);
  EXPECT_NE(problem.find("2560x720"), std::string::npos) << problem;
}

// Debian's opencv-doc ships the Middlebury aloe pair with ground truth: the
// disparity error of our matcher settings, raw SGBM and WLS-filtered.
TEST(StereoDepth, AloeDisparityErrorAgainstGroundTruth) {
  const std::string data = "/usr/share/doc/opencv-doc/examples/data/";
  if (!fs::exists(data + "aloeGT.png")) GTEST_SKIP() << "opencv-doc is not installed (aloe pair)";
  const cv::Mat left = cv::imread(data + "aloeL.jpg"), right = cv::imread(data + "aloeR.jpg");
  const cv::Mat gt = cv::imread(data + "aloeGT.png", cv::IMREAD_GRAYSCALE);  // disparity in pixels, 0 unknown
  ASSERT_EQ(left.size(), gt.size());
  cv::Mat raw_valid;
  for (bool wls : {false, true}) {
    StereoMatchOptions o;
    o.max_disparity = 160;
    o.wls_filter = wls;
    Stopwatch watch;
    const cv::Mat d = ComputeDisparity(left, right, o);
    const double ms = watch.ElapsedMs();
    if (!wls) raw_valid = d > 0;
    double abs_sum = 0, abs_sum_common = 0;
    int known = 0, matched = 0, bad = 0, common = 0;
    for (int y = 0; y < gt.rows; ++y)
      for (int x = 0; x < gt.cols; ++x) {
        const int g = gt.at<uchar>(y, x);
        if (g == 0) continue;
        ++known;
        const float v = d.at<float>(y, x);
        if (v <= 0) continue;
        ++matched;
        const double e = std::abs(v - g);
        abs_sum += e;
        bad += e > 2.0;
        if (raw_valid.at<uchar>(y, x)) {
          abs_sum_common += e;
          ++common;
        }
      }
    const double coverage = 100.0 * matched / known, bad2 = 100.0 * bad / matched, mae = abs_sum / matched;
    std::printf(
        "aloe %dx%d, %s: coverage %.1f %%, mean |error| %.2f px (%.2f px where raw SGBM has a value), "
        "bad > 2 px %.1f %%, %.0f ms\n",
        left.cols, left.rows, wls ? "SGBM + WLS" : "SGBM", coverage, mae, abs_sum_common / common, bad2, ms);
    EXPECT_GT(coverage, wls ? 80 : 70);
    EXPECT_LT(mae, wls ? 4.0 : 1.5);
    EXPECT_LT(bad2, wls ? 15 : 5);
  }
}

}  // namespace
}  // namespace headcast
