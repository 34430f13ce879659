// V4L2 webcams, written directly against the kernel API (ioctl, mmap'ed
// buffers): pixel format, size and frame-rate negotiation, capture timestamps,
// and clear errors for a missing, busy or incapable device.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/capture/frame_source.h"

namespace headcast {

// One size of one pixel format a device offers, with its frame rates.
struct V4l2Mode {
  uint32_t fourcc = 0;
  int width = 0, height = 0;
  std::vector<double> fps;  // empty: the device did not list rates (assume any)
};

struct V4l2Request {
  int width = 640, height = 480;
  double fps = 30;
  std::string pixel_format = "auto";  // auto (YUYV or MJPEG, whichever fits better), yuyv, mjpeg
};

struct V4l2Choice {
  V4l2Mode mode;
  double fps = 0;
  std::string why;  // the trade-off taken, for the log
};

// The decoder-supported mode closest to the request: the size nearest in
// pixel count (smaller sizes cost more than larger ones), then a rate at
// least the one asked for; YUYV over MJPEG when equal (no decoding). Returns
// false and says why when nothing usable is offered.
bool NegotiateV4l2Mode(const std::vector<V4l2Mode>& modes, const V4l2Request& request, V4l2Choice* choice,
                       std::string* why);
std::string FourccName(uint32_t fourcc);

class V4l2Source final : public FrameSource {
 public:
  // Opens, negotiates and starts streaming; throws std::runtime_error saying
  // what is wrong (no such device, permission, busy, not a capture device, no
  // usable format).
  V4l2Source(std::string device, const SourceOptions& options);
  ~V4l2Source() override;
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override;
  double fps() const override { return choice_.fps; }
  // The modes the device offers (for --list-modes style diagnostics).
  const std::vector<V4l2Mode>& modes() const { return modes_; }

 private:
  std::vector<V4l2Mode> EnumerateModes() const;
  int Ioctl(unsigned long request, void* arg) const;

  std::string device_;
  int fd_ = -1;
  std::string card_;
  std::vector<V4l2Mode> modes_;
  V4l2Choice choice_;
  struct Buffer {
    void* start = nullptr;
    size_t length = 0;
  };
  std::vector<Buffer> buffers_;
  bool streaming_ = false;
  uint64_t index_ = 0;
};

}  // namespace headcast
