// V4L2 capture.
#include "common/capture/v4l2_source.h"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "common/core/timer.h"

namespace headcast {

std::string FourccName(uint32_t f) {
  std::string s;
  for (int i = 0; i < 4; ++i) s += static_cast<char>((f >> (8 * i)) & 0xff);
  return s;
}

namespace {
bool Decodable(uint32_t fourcc) { return fourcc == V4L2_PIX_FMT_YUYV || fourcc == V4L2_PIX_FMT_MJPEG; }
}  // namespace

bool NegotiateV4l2Mode(const std::vector<V4l2Mode>& modes, const V4l2Request& r, V4l2Choice* choice, std::string* why) {
  uint32_t wanted = 0;
  if (r.pixel_format == "yuyv")
    wanted = V4L2_PIX_FMT_YUYV;
  else if (r.pixel_format == "mjpeg")
    wanted = V4L2_PIX_FMT_MJPEG;
  else if (r.pixel_format != "auto") {
    if (why) *why = "unknown pixel format '" + r.pixel_format + "' (auto, yuyv, mjpeg)";
    return false;
  }
  const double area = static_cast<double>(r.width) * r.height;
  double best = INFINITY;
  for (const V4l2Mode& m : modes) {
    if (!Decodable(m.fourcc) || (wanted && m.fourcc != wanted) || m.width <= 0 || m.height <= 0) continue;
    // Size: log-ratio of pixel counts, smaller sizes weigh double (detail is lost, not just time).
    const double ratio = std::log(static_cast<double>(m.width) * m.height / area);
    double cost = ratio < 0 ? -2 * ratio : ratio;
    // Rate: the lowest offered rate >= the request, else the highest offered, with the shortfall as cost.
    double fps = r.fps;
    if (!m.fps.empty()) {
      double at_least = INFINITY, highest = 0;
      for (double f : m.fps) {
        if (f >= r.fps - 1e-6) at_least = std::min(at_least, f);
        highest = std::max(highest, f);
      }
      fps = std::isfinite(at_least) ? at_least : highest;
      if (fps < r.fps) cost += 3 * (r.fps - fps) / r.fps;
    }
    if (m.fourcc == V4L2_PIX_FMT_MJPEG) cost += 0.01;  // decoding costs a little CPU
    if (cost < best) {
      best = cost;
      choice->mode = m;
      choice->fps = fps;
    }
  }
  if (!std::isfinite(best)) {
    std::string offered;
    for (const V4l2Mode& m : modes)
      offered += " " + FourccName(m.fourcc) + " " + std::to_string(m.width) + "x" + std::to_string(m.height);
    if (why)
      *why = std::string("no usable mode") + (wanted ? " in " + FourccName(wanted) : "") +
             " (headcast decodes YUYV and MJPEG); the device offers:" + (offered.empty() ? " nothing" : offered);
    return false;
  }
  choice->why = FourccName(choice->mode.fourcc) + " " + std::to_string(choice->mode.width) + "x" +
                std::to_string(choice->mode.height) + " at " + std::to_string(choice->fps) + " fps for a request of " +
                std::to_string(r.width) + "x" + std::to_string(r.height) + " at " + std::to_string(r.fps) + " fps";
  return true;
}

int V4l2Source::Ioctl(unsigned long request, void* arg) const {
  int r;
  do {
    r = ioctl(fd_, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

V4l2Source::V4l2Source(std::string device, const SourceOptions& options) : device_(std::move(device)) {
  fd_ = open(device_.c_str(), O_RDWR | O_NONBLOCK);
  if (fd_ < 0) {
    const int e = errno;
    if (e == ENOENT) throw std::runtime_error(device_ + ": no such device (is the camera plugged in? ls /dev/video*)");
    if (e == EACCES) throw std::runtime_error(device_ + ": permission denied (add the user to the 'video' group)");
    if (e == EBUSY) throw std::runtime_error(device_ + ": busy (another program is using the camera)");
    throw std::runtime_error(device_ + ": cannot open: " + std::strerror(e));
  }
  v4l2_capability cap{};
  if (Ioctl(VIDIOC_QUERYCAP, &cap) < 0) {
    const int e = errno;
    close(fd_);
    fd_ = -1;
    throw std::runtime_error(device_ + ": not a V4L2 device (" + std::strerror(e) + ")");
  }
  card_ = reinterpret_cast<const char*>(cap.card);
  const uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  auto fail = [&](const std::string& what) {
    close(fd_);
    fd_ = -1;
    throw std::runtime_error(device_ + " (" + card_ + "): " + what);
  };
  if (!(caps & V4L2_CAP_VIDEO_CAPTURE))
    fail("not a video capture device (metadata node? try the other /dev/video* of this camera)");
  if (!(caps & V4L2_CAP_STREAMING)) fail("does not support streaming I/O");

  modes_ = EnumerateModes();
  V4l2Request request;
  request.width = options.width;
  request.height = options.height;
  request.fps = options.fps;
  request.pixel_format = options.pixel_format;
  std::string why;
  if (!NegotiateV4l2Mode(modes_, request, &choice_, &why)) fail(why);

  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = static_cast<uint32_t>(choice_.mode.width);
  fmt.fmt.pix.height = static_cast<uint32_t>(choice_.mode.height);
  fmt.fmt.pix.pixelformat = choice_.mode.fourcc;
  fmt.fmt.pix.field = V4L2_FIELD_ANY;
  if (Ioctl(VIDIOC_S_FMT, &fmt) < 0) {
    if (errno == EBUSY) fail("busy (another program is using the camera)");
    fail(std::string("VIDIOC_S_FMT failed: ") + std::strerror(errno));
  }
  // The driver may adjust: keep what it set.
  choice_.mode.width = static_cast<int>(fmt.fmt.pix.width);
  choice_.mode.height = static_cast<int>(fmt.fmt.pix.height);
  choice_.mode.fourcc = fmt.fmt.pix.pixelformat;
  if (!Decodable(choice_.mode.fourcc)) fail("the driver switched to " + FourccName(choice_.mode.fourcc));

  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(VIDIOC_G_PARM, &parm) == 0 && (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME)) {
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator = static_cast<uint32_t>(std::lround(choice_.fps * 1000));
    if (Ioctl(VIDIOC_S_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator > 0)
      choice_.fps =
          static_cast<double>(parm.parm.capture.timeperframe.denominator) / parm.parm.capture.timeperframe.numerator;
  }

  v4l2_requestbuffers req{};
  req.count = 4;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (Ioctl(VIDIOC_REQBUFS, &req) < 0 || req.count < 2)
    fail(std::string("cannot get capture buffers: ") + (errno == EBUSY ? "busy" : std::strerror(errno)));
  for (uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (Ioctl(VIDIOC_QUERYBUF, &buf) < 0) fail("VIDIOC_QUERYBUF failed");
    void* start = mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (start == MAP_FAILED) fail("mmap of a capture buffer failed");
    buffers_.push_back({start, buf.length});
    if (Ioctl(VIDIOC_QBUF, &buf) < 0) fail("VIDIOC_QBUF failed");
  }
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(VIDIOC_STREAMON, &type) < 0)
    fail(errno == EBUSY ? "busy (another program is using the camera)"
                        : std::string("VIDIOC_STREAMON failed: ") + std::strerror(errno));
  streaming_ = true;
}

std::vector<V4l2Mode> V4l2Source::EnumerateModes() const {
  std::vector<V4l2Mode> modes;
  v4l2_fmtdesc desc{};
  desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  for (desc.index = 0; Ioctl(VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index) {
    v4l2_frmsizeenum size{};
    size.pixel_format = desc.pixelformat;
    std::vector<std::pair<int, int>> sizes;
    for (size.index = 0; Ioctl(VIDIOC_ENUM_FRAMESIZES, &size) == 0; ++size.index) {
      if (size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
        sizes.emplace_back(size.discrete.width, size.discrete.height);
      } else {  // stepwise/continuous: offer the common sizes inside the range
        for (auto [w, h] : {std::pair{640, 480}, {1280, 720}, {1920, 1080}, {320, 240}})
          if (w >= static_cast<int>(size.stepwise.min_width) && w <= static_cast<int>(size.stepwise.max_width) &&
              h >= static_cast<int>(size.stepwise.min_height) && h <= static_cast<int>(size.stepwise.max_height))
            sizes.emplace_back(w, h);
        break;
      }
    }
    for (auto [w, h] : sizes) {
      V4l2Mode m;
      m.fourcc = desc.pixelformat;
      m.width = w;
      m.height = h;
      v4l2_frmivalenum ival{};
      ival.pixel_format = desc.pixelformat;
      ival.width = static_cast<uint32_t>(w);
      ival.height = static_cast<uint32_t>(h);
      for (ival.index = 0; Ioctl(VIDIOC_ENUM_FRAMEINTERVALS, &ival) == 0; ++ival.index) {
        if (ival.type != V4L2_FRMIVAL_TYPE_DISCRETE) break;
        if (ival.discrete.numerator > 0)
          m.fps.push_back(static_cast<double>(ival.discrete.denominator) / ival.discrete.numerator);
      }
      modes.push_back(m);
    }
  }
  return modes;
}

V4l2Source::~V4l2Source() {
  if (fd_ < 0) return;
  if (streaming_) {
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    Ioctl(VIDIOC_STREAMOFF, &type);
  }
  for (const Buffer& b : buffers_) munmap(b.start, b.length);
  close(fd_);
}

std::string V4l2Source::Describe() const { return "V4L2 " + device_ + " (" + card_ + "): " + choice_.why; }

ReadStatus V4l2Source::Read(CapturedFrame* frame, std::string* problem) {
  pollfd p{fd_, POLLIN, 0};
  const int ready = poll(&p, 1, 2000);
  if (ready <= 0) {
    if (problem) *problem = device_ + (ready == 0 ? ": no frame for 2 s" : ": poll failed");
    return ready == 0 ? ReadStatus::kSkipped : ReadStatus::kEnd;
  }
  v4l2_buffer buf{};
  buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buf.memory = V4L2_MEMORY_MMAP;
  if (Ioctl(VIDIOC_DQBUF, &buf) < 0) {
    if (errno == EAGAIN) return ReadStatus::kSkipped;
    if (problem) *problem = device_ + ": the camera went away (" + std::strerror(errno) + ")";
    return ReadStatus::kEnd;
  }
  // Kernel timestamps are CLOCK_MONOTONIC, the steady clock here.
  const bool monotonic = (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  frame->capture_time_s = monotonic ? buf.timestamp.tv_sec + 1e-6 * buf.timestamp.tv_usec : SteadyNowSeconds();
  frame->index = index_++;
  frame->depth_m.release();
  frame->depth_on_demand.reset();
  frame->camera.reset();
  const Buffer& b = buffers_[buf.index];
  ReadStatus status = ReadStatus::kFrame;
  if (buf.flags & V4L2_BUF_FLAG_ERROR) {
    status = ReadStatus::kSkipped;
    if (problem) *problem = device_ + ": the driver flagged a corrupt frame";
  } else if (choice_.mode.fourcc == V4L2_PIX_FMT_YUYV) {
    const cv::Mat yuyv(choice_.mode.height, choice_.mode.width, CV_8UC2, b.start);
    cv::cvtColor(yuyv, frame->bgr, cv::COLOR_YUV2BGR_YUYV);
  } else {
    const cv::Mat jpeg(1, static_cast<int>(buf.bytesused), CV_8UC1, b.start);
    frame->bgr = cv::imdecode(jpeg, cv::IMREAD_COLOR);
    if (frame->bgr.empty()) {
      status = ReadStatus::kSkipped;
      if (problem) *problem = device_ + ": undecodable MJPEG frame";
    }
  }
  Ioctl(VIDIOC_QBUF, &buf);
  return status;
}

}  // namespace headcast
