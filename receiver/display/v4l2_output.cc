// The virtual camera and the raw pipe.
#include "receiver/display/v4l2_output.h"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "common/capture/v4l2_source.h"

namespace headcast {
namespace {

class FdDevice : public V4l2OutputDevice {
 public:
  FdDevice(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~FdDevice() override { close(fd_); }
  int Ioctl(unsigned long request, void* arg) override {
    int r;
    do r = ioctl(fd_, request, arg);
    while (r < 0 && errno == EINTR);
    return r;
  }
  ssize_t Write(const void* data, size_t bytes) override { return write(fd_, data, bytes); }
  std::string path() const override { return path_; }

 private:
  int fd_;
  std::string path_;
};

uint32_t Fourcc(RawPixelFormat f) {
  switch (f) {
    case RawPixelFormat::kYuyv:
      return V4L2_PIX_FMT_YUYV;
    case RawPixelFormat::kI420:
      return V4L2_PIX_FMT_YUV420;
    case RawPixelFormat::kBgr24:
      return V4L2_PIX_FMT_BGR24;
  }
  return 0;
}

size_t PackedLineBytes(RawPixelFormat f, int width) {
  switch (f) {
    case RawPixelFormat::kYuyv:
      return 2 * static_cast<size_t>(width);
    case RawPixelFormat::kI420:
      return static_cast<size_t>(width);  // of the Y plane
    case RawPixelFormat::kBgr24:
      return 3 * static_cast<size_t>(width);
  }
  return 0;
}

// Writes all of `bytes`, retrying interrupted and partial writes.
template <typename WriteFn>
ssize_t WriteAll(const std::string& bytes, WriteFn write_some) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = write_some(bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return n < 0 ? -1 : static_cast<ssize_t>(done);
    done += static_cast<size_t>(n);
  }
  return static_cast<ssize_t>(done);
}

}  // namespace

std::unique_ptr<V4l2OutputDevice> OpenV4l2OutputDevice(const std::string& path) {
  struct stat st {};
  if (stat(path.c_str(), &st) != 0)
    throw std::runtime_error(path + ": " + std::strerror(errno) +
                             " (no virtual camera there; create one with v4l2loopback, see docs/calls.md)");
  if (!S_ISCHR(st.st_mode)) throw std::runtime_error(path + ": not a device node (a V4L2 camera is /dev/videoN)");
  const int fd = open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    throw std::runtime_error(path + ": cannot open for writing: " + std::strerror(e) +
                             (e == EACCES ? " (add the user to the 'video' group)" : ""));
  }
  return std::make_unique<FdDevice>(fd, path);
}

V4l2OutputFormat NegotiateV4l2Output(V4l2OutputDevice& device, const V4l2OutputRequest& request) {
  const std::string& path = device.path();
  v4l2_capability cap{};
  if (device.Ioctl(VIDIOC_QUERYCAP, &cap) < 0)
    throw std::runtime_error(path + ": not a V4L2 device (" + std::strerror(errno) + ")");
  V4l2OutputFormat out;
  out.card = std::string(reinterpret_cast<const char*>(cap.card),
                         strnlen(reinterpret_cast<const char*>(cap.card), sizeof(cap.card)));
  auto fail = [&](const std::string& what) { throw std::runtime_error(path + " (" + out.card + "): " + what); };
  const uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  if (!(caps & V4L2_CAP_VIDEO_OUTPUT))
    fail(std::string((caps & V4L2_CAP_VIDEO_CAPTURE) ? "a camera, not a video output" : "not a video output") +
         " (headcast writes to a v4l2loopback device; see docs/calls.md)");
  if (!(caps & V4L2_CAP_READWRITE)) fail("does not accept write()");

  // What the device offers for output. v4l2loopback lists every format it
  // takes until a producer has set one, then (keep_format) only that one.
  std::vector<uint32_t> offered;
  for (uint32_t i = 0; i < 64; ++i) {
    v4l2_fmtdesc d{};
    d.index = i;
    d.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    if (device.Ioctl(VIDIOC_ENUM_FMT, &d) < 0) break;
    offered.push_back(d.pixelformat);
  }
  auto offers = [&](RawPixelFormat f) {
    return offered.empty() || std::find(offered.begin(), offered.end(), Fourcc(f)) != offered.end();
  };
  std::string listed;
  for (uint32_t f : offered) listed += " " + FourccName(f);
  if (listed.empty()) listed = " (nothing listed)";
  std::vector<RawPixelFormat> wanted;
  if (request.pixel_format == "auto") {
    // YUYV first: every call program and browser takes it; I420 next.
    wanted = {RawPixelFormat::kYuyv, RawPixelFormat::kI420};
  } else {
    const RawPixelFormat f = ParseRawPixelFormat(request.pixel_format);
    if (f == RawPixelFormat::kBgr24) fail("a virtual camera takes yuyv or i420, not bgr24");
    wanted = {f};
  }
  std::vector<RawPixelFormat> candidates;
  for (RawPixelFormat f : wanted)
    if (offers(f)) candidates.push_back(f);
  if (candidates.empty())
    fail("offers none of the formats asked for (" + request.pixel_format + "); it lists:" + listed);

  std::string last_error;
  for (RawPixelFormat f : candidates) {
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    fmt.fmt.pix.width = static_cast<uint32_t>(request.size.width);
    fmt.fmt.pix.height = static_cast<uint32_t>(request.size.height);
    fmt.fmt.pix.pixelformat = Fourcc(f);
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    fmt.fmt.pix.bytesperline = static_cast<uint32_t>(PackedLineBytes(f, request.size.width));
    fmt.fmt.pix.sizeimage = static_cast<uint32_t>(RawFrameBytes(f, request.size.width, request.size.height));
    fmt.fmt.pix.colorspace = V4L2_COLORSPACE_SMPTE170M;  // BT.601, as ToRawFrame writes
    if (device.Ioctl(VIDIOC_S_FMT, &fmt) < 0) {
      last_error = FourccName(Fourcc(f)) + ": " +
                   (errno == EBUSY ? "busy (another program writes to it)" : std::string(std::strerror(errno)));
      continue;
    }
    if (fmt.fmt.pix.pixelformat != Fourcc(f)) {
      last_error = "asked for " + FourccName(Fourcc(f)) + ", the device set " + FourccName(fmt.fmt.pix.pixelformat);
      continue;
    }
    const int w = static_cast<int>(fmt.fmt.pix.width), h = static_cast<int>(fmt.fmt.pix.height);
    if (w < 16 || h < 16 || w > 7680 || h > 4320 || w % 2 || h % 2)
      fail("the device set an unusable size " + std::to_string(w) + "x" + std::to_string(h));
    const size_t frame_bytes = RawFrameBytes(f, w, h);
    // Frames are written packed: a padded line layout would need another writer.
    if (fmt.fmt.pix.bytesperline != 0 && fmt.fmt.pix.bytesperline != PackedLineBytes(f, w))
      fail("the device wants " + std::to_string(fmt.fmt.pix.bytesperline) + " bytes a line, headcast writes " +
           std::to_string(PackedLineBytes(f, w)));
    if (fmt.fmt.pix.sizeimage != 0 && fmt.fmt.pix.sizeimage < frame_bytes)
      fail("the device's frame size " + std::to_string(fmt.fmt.pix.sizeimage) + " is smaller than a " +
           std::to_string(w) + "x" + std::to_string(h) + " frame (" + std::to_string(frame_bytes) + " bytes)");
    out.format = f;
    out.size = {w, h};
    out.frame_bytes = frame_bytes;
    out.why = FourccName(Fourcc(f)) + " " + std::to_string(w) + "x" + std::to_string(h);
    if (out.size != request.size)
      out.why += " (asked for " + std::to_string(request.size.width) + "x" + std::to_string(request.size.height) +
                 "; the device keeps its size)";
    break;
  }
  if (out.frame_bytes == 0) fail("no format could be set: " + last_error);

  // The rate the camera advertises; a driver without it still takes frames.
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
  parm.parm.output.timeperframe.numerator = 1000;
  parm.parm.output.timeperframe.denominator = static_cast<uint32_t>(std::lround(request.fps * 1000));
  if (device.Ioctl(VIDIOC_S_PARM, &parm) == 0 && parm.parm.output.timeperframe.numerator > 0) {
    const double fps =
        static_cast<double>(parm.parm.output.timeperframe.denominator) / parm.parm.output.timeperframe.numerator;
    out.why += ", " + std::to_string(static_cast<int>(std::lround(fps))) + " fps";
  } else {
    out.why += ", frame rate not set (" + std::string(std::strerror(errno)) + ")";
  }
  return out;
}

V4l2Sink::V4l2Sink(std::unique_ptr<V4l2OutputDevice> device, V4l2OutputFormat format)
    : device_(std::move(device)), format_(std::move(format)) {}

bool V4l2Sink::Write(const std::string& frame) {
  if (frame.size() != format_.frame_bytes)
    throw std::logic_error("a frame of " + std::to_string(frame.size()) + " bytes for a device that takes " +
                           std::to_string(format_.frame_bytes));
  const ssize_t n = WriteAll(frame, [&](const char* p, size_t k) { return device_->Write(p, k); });
  if (n < 0) {
    const int e = errno;
    // A reader that is slow or absent makes no error on v4l2loopback; anything else is the device failing.
    throw std::runtime_error(device_->path() + ": writing a frame failed: " + std::strerror(e));
  }
  if (static_cast<size_t>(n) != frame.size())
    throw std::runtime_error(device_->path() + ": the device took " + std::to_string(n) + " of " +
                             std::to_string(frame.size()) + " bytes of a frame");
  return true;
}

std::string V4l2Sink::Describe() const { return "v4l2:" + device_->path() + " (" + format_.why + ")"; }

PipeSink::PipeSink(int fd) : fd_(fd) {
  // A reader that goes away must end the stream, not kill the process.
  std::signal(SIGPIPE, SIG_IGN);
}

bool PipeSink::Write(const std::string& frame) {
  const ssize_t n = WriteAll(frame, [&](const char* p, size_t k) { return write(fd_, p, k); });
  if (n < 0 && errno == EPIPE) return false;  // the reader closed the pipe: the stream ends
  if (n < 0) throw std::runtime_error(std::string("writing frames to the pipe failed: ") + std::strerror(errno));
  return static_cast<size_t>(n) == frame.size();
}

std::vector<std::string> FindV4l2LoopbackDevices() {
  std::vector<std::string> found;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("video", 0) != 0) continue;
    const int fd = open(entry.path().c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) continue;
    v4l2_capability cap{};
    if (ioctl(fd, VIDIOC_QUERYCAP, &cap) == 0 &&
        std::string(reinterpret_cast<const char*>(cap.driver)).find("loopback") != std::string::npos)
      found.push_back(entry.path().string());
    close(fd);
  }
  std::sort(found.begin(), found.end());
  return found;
}

}  // namespace headcast
