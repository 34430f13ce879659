// Bounded queue, statistics, options checks, image and video I/O.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

#include "common/core/bounded_queue.h"
#include "common/core/camera.h"
#include "common/core/check.h"
#include "common/core/cli_flags.h"
#include "common/core/image_io.h"
#include "common/core/median.h"
#include "common/core/options.h"
#include "common/core/program.h"
#include "common/core/service_notify.h"
#include "common/core/timer.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

TEST(BoundedQueue, DropsTheOldestWhenFull) {
  BoundedQueue<int> q(3);
  EXPECT_FALSE(q.Push(1));
  EXPECT_FALSE(q.Push(2));
  EXPECT_FALSE(q.Push(3));
  EXPECT_TRUE(q.Push(4));  // 1 is dropped
  EXPECT_EQ(q.dropped(), 1u);
  EXPECT_EQ(*q.TryPop(), 2);
  EXPECT_EQ(*q.TryPop(), 3);
  EXPECT_EQ(*q.TryPop(), 4);
  EXPECT_FALSE(q.TryPop().has_value());
}

TEST(BoundedQueue, PopWaitsAndCloseWakes) {
  BoundedQueue<int> q(2);
  std::thread producer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    q.Push(7);
  });
  auto v = q.Pop(std::chrono::seconds(5));
  producer.join();
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(*v, 7);
  std::thread closer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    q.Close();
  });
  Stopwatch w;
  EXPECT_FALSE(q.Pop(std::chrono::seconds(5)).has_value());
  EXPECT_LT(w.ElapsedSeconds(), 4.0);
  closer.join();
  EXPECT_FALSE(q.Push(1));
  EXPECT_EQ(q.size(), 0u);
}

// A socket standing in for systemd's NOTIFY_SOCKET.
class NotifySocket {
 public:
  explicit NotifySocket(const std::string& path) : fd_(socket(AF_UNIX, SOCK_DGRAM, 0)) {
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::memcpy(a.sun_path, path.data(), path.size());
    if (path[0] == '@') a.sun_path[0] = '\0';
    EXPECT_EQ(bind(fd_, reinterpret_cast<sockaddr*>(&a), offsetof(sockaddr_un, sun_path) + path.size()), 0);
    timeval timeout{2, 0};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  }
  ~NotifySocket() { close(fd_); }
  std::string Receive() {
    char buffer[256];
    const ssize_t n = recv(fd_, buffer, sizeof buffer, 0);
    return n > 0 ? std::string(buffer, static_cast<size_t>(n)) : "";
  }

 private:
  int fd_;
};

TEST(ServiceNotifier, SpeaksSystemdsNotifyProtocol) {
  unsetenv("NOTIFY_SOCKET");
  EXPECT_FALSE(ServiceNotifier().Notify("READY=1"));  // outside systemd: nothing
  const std::string path = testing::TempDir("notify") + "/notify.sock";
  for (const std::string& where : {path, "@headcast-notify-test-" + std::to_string(getpid())}) {
    NotifySocket socket(where);
    setenv("NOTIFY_SOCKET", where.c_str(), 1);
    setenv("WATCHDOG_USEC", "3000000", 1);
    const ServiceNotifier notifier;
    EXPECT_DOUBLE_EQ(notifier.watchdog_interval_s(), 1.5);
    EXPECT_TRUE(notifier.Notify("READY=1"));
    EXPECT_EQ(socket.Receive(), "READY=1") << where;
    EXPECT_TRUE(notifier.Notify("WATCHDOG=1"));
    EXPECT_EQ(socket.Receive(), "WATCHDOG=1") << where;
  }
  setenv("WATCHDOG_PID", "1", 1);  // another process's watchdog
  EXPECT_EQ(ServiceNotifier().watchdog_interval_s(), 0);
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  unsetenv("WATCHDOG_PID");
}

TEST(SampleStats, ABoundedOneKeepsAnUnbiasedSubset) {
  SampleStats bounded(1000), all;
  for (int i = 0; i < 200000; ++i) {
    bounded.Add(i % 1000);
    all.Add(i % 1000);
  }
  EXPECT_EQ(bounded.values().size(), 1000u);  // memory stays bounded
  EXPECT_EQ(bounded.count(), 200000u);
  EXPECT_NEAR(bounded.Median(), all.Median(), 40);  // a uniform subset: the same distribution
  EXPECT_NEAR(bounded.Percentile(95), all.Percentile(95), 20);
  EXPECT_NEAR(bounded.Mean(), all.Mean(), 25);
}

TEST(SampleStats, Percentiles) {
  SampleStats s;
  EXPECT_TRUE(std::isnan(s.Median()));
  for (int i = 1; i <= 101; ++i) s.Add(i);
  EXPECT_DOUBLE_EQ(s.Median(), 51);
  EXPECT_DOUBLE_EQ(s.Percentile(95), 96);
  EXPECT_DOUBLE_EQ(s.Percentile(0), 1);
  EXPECT_DOUBLE_EQ(s.Mean(), 51);
}

TEST(Median, TheUpperMiddleValueOrARefusal) {
  std::vector<double> odd = {5, -1, 3, 9, 2};
  EXPECT_DOUBLE_EQ(Median(odd), 3);
  EXPECT_EQ(odd, (std::vector<double>{5, -1, 3, 9, 2}));  // Median works on a copy
  std::vector<float> even = {4, 1, 3, 2};
  EXPECT_FLOAT_EQ(MedianInPlace(even), 3);  // the upper of the two middle values
  EXPECT_EQ(even.size(), 4u);
  std::vector<int> none;
  EXPECT_THROW(MedianInPlace(none), std::invalid_argument);
}

TEST(OptionsCheck, CollectsEveryError) {
  OptionsCheck c("FooOptions");
  c.Positive("rate", 0).InRange("q", 5, 0, 1).Finite("x", std::nan("")).NotEmpty("path", "").Positive("ok", 1);
  EXPECT_EQ(c.errors().size(), 4u);
  try {
    c.ThrowIfErrors();
    FAIL();
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("FooOptions: ", 0), 0u);
    for (const char* field : {"rate", "q", "x", "path"}) EXPECT_NE(m.find(field), std::string::npos) << m;
  }
  EXPECT_NO_THROW(OptionsCheck("Ok").Positive("a", 2).ThrowIfErrors());
}

TEST(ImageIo, RoundTripsAndNamesBadFiles) {
  const std::string dir = testing::TempDir("img");
  cv::Mat image(32, 48, CV_8UC3, cv::Scalar(10, 20, 30));
  WriteImage(dir + "/sub/a.png", image);
  const cv::Mat back = ReadImage(dir + "/sub/a.png");
  EXPECT_EQ(cv::norm(back, image, cv::NORM_INF), 0);
  { std::ofstream(dir + "/bad.png") << "not a png"; }
  for (const std::string name : {"bad.png", "missing.png"}) {
    try {
      ReadImage(dir + "/" + name);
      ADD_FAILURE();
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos);
    }
  }
}

TEST(VideoIo, WritesAndReadsAnMp4) {
  const std::string dir = testing::TempDir("video");
  {
    VideoWriter writer(dir + "/v.mp4", 25);
    for (int i = 0; i < 10; ++i) writer.Write(cv::Mat(64, 80, CV_8UC3, cv::Scalar(i * 20, 100, 200)));
    EXPECT_EQ(writer.frames_written(), 10);
  }
  // H.264 in yuv420p: what browsers, code hosts and call programs play.
  FILE* probe = popen(
      ("ffprobe -v error -select_streams v:0 -show_entries stream=codec_name,pix_fmt -of csv=p=0 " + dir + "/v.mp4")
          .c_str(),
      "r");
  ASSERT_NE(probe, nullptr);
  char line[128] = {};
  const bool read = fgets(line, sizeof line, probe) != nullptr;
  pclose(probe);
  ASSERT_TRUE(read) << "ffprobe said nothing";
  EXPECT_EQ(std::string(line), "h264,yuv420p\n");
  VideoReader reader(dir + "/v.mp4");
  EXPECT_EQ(reader.size(), cv::Size(80, 64));
  EXPECT_NEAR(reader.fps(), 25, 0.1);
  cv::Mat frame;
  int n = 0;
  while (reader.Read(&frame)) ++n;
  EXPECT_EQ(n, 10);
  EXPECT_THROW(VideoReader(dir + "/none.mp4"), std::runtime_error);
  { std::ofstream(dir + "/junk.mp4") << "junk"; }
  try {
    VideoReader junk(dir + "/junk.mp4");
    cv::Mat f;
    EXPECT_FALSE(junk.Read(&f));  // opened or not, no frames and no crash
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("junk.mp4"), std::string::npos);
  }
}

TEST(CheckDeathTest, ABrokenInvariantAbortsSayingWhereAndWhy) {
  const int frames = 3;
  HEADCAST_CHECK(frames == 3) << "never printed";
  EXPECT_DEATH(HEADCAST_CHECK(frames == 4) << "frames " << frames, "check failed: frames == 4 frames 3");
}

TEST(Flags, IntrinsicsAndSizesAreParsedOrRefusedNamingTheFlag) {
  const PinholeCamera k = ParseIntrinsics("640,641,320.5,240", "--intrinsics");
  EXPECT_EQ(k.fx, 640);
  EXPECT_EQ(k.fy, 641);
  EXPECT_EQ(k.cx, 320.5);
  for (const char* bad : {"640,640,320", "a,b,c,d", "640,640,320,240,1", "-1,640,320,240", "nan,640,320,240"}) {
    try {
      ParseIntrinsics(bad, "--intrinsics");
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("--intrinsics"), std::string::npos) << e.what();
    }
  }
  int w = 0, h = 0;
  ParseSize("1280x720", "--camera-size", &w, &h);
  EXPECT_EQ(w, 1280);
  EXPECT_EQ(h, 720);
  for (const char* bad : {"1280", "1280x", "0x720", "1280x720p", "99999x1"})
    EXPECT_THROW(ParseSize(bad, "--camera-size", &w, &h), std::invalid_argument) << bad;
}

// An options check's field names come back as the flags the user typed.
TEST(Flags, CheckErrorsNameTheFlags) {
  CLI::App app;
  std::string ca, out;
  int iterations = 0;
  app.add_option("--tls-ca", ca);
  app.add_subcommand("train")->add_option("--iterations", iterations);
  app.add_option("--out", out);
  EXPECT_EQ(InFlagNames(app, "sender: cannot read tls_ca; iterations must be > 0 (got 0)"),
            "sender: cannot read --tls-ca; --iterations must be > 0 (got 0)");
  // One-word names stay words except where a bound is stated; longer names are not cut.
  EXPECT_EQ(InFlagNames(app, "the out folder; my_tls_ca_file"), "the out folder; my_tls_ca_file");
  // A key of a file's entry is not a flag.
  EXPECT_EQ(InFlagNames(app, "a.hcavatar: server.tls_ca wants a string"), "a.hcavatar: server.tls_ca wants a string");
}

// One name per concept: --json, --pacing, --max-frames; old names are hidden aliases.
TEST(Flags, SharedFlagsAndTheirOldNames) {
  CLI::App app;
  std::string json;
  bool realtime = true;
  int frames = 0;
  AddJsonFlag(app, &json, "the report", {"--stats-json"});
  AddPacingFlag(app, &realtime, {"--realtime"}, {"--unpaced"});
  AddMaxFramesFlag(app, &frames, "at most", {"--frames"});
  app.parse("--pacing none --max-frames 5 --json a.json", false);
  EXPECT_EQ(json, "a.json");
  EXPECT_FALSE(realtime);
  EXPECT_EQ(frames, 5);
  app.parse("--frames 7 --unpaced --stats-json b.json", false);
  EXPECT_EQ(json, "b.json");
  EXPECT_EQ(frames, 7);
  EXPECT_FALSE(realtime);
  EXPECT_THROW(app.parse("--pacing sometimes", false), CLI::ValidationError);
  const std::string help = app.help();
  EXPECT_NE(help.find("--json"), std::string::npos);
  EXPECT_EQ(help.find("--stats-json"), std::string::npos);
  EXPECT_EQ(help.find("--unpaced"), std::string::npos);
}

}  // namespace
}  // namespace headcast
