// The virtual camera: frames written to a V4L2 output device (a v4l2loopback
// camera that call programs list as a webcam), against the kernel API:
// capability check, pixel-format and size negotiation, frame rate, write().
// The device calls go through V4l2OutputDevice so that tests can put a fake
// device behind the same negotiation and writing code.
#pragma once

#include <sys/types.h>

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "receiver/display/raw_frames.h"

namespace headcast {

// The kernel calls the output needs.
class V4l2OutputDevice {
 public:
  virtual ~V4l2OutputDevice() = default;
  virtual int Ioctl(unsigned long request, void* arg) = 0;    // -1 with errno set on failure
  virtual ssize_t Write(const void* data, size_t bytes) = 0;  // -1 with errno set on failure
  virtual std::string path() const = 0;
};

// Opens a device node for writing frames; throws std::runtime_error saying
// what is wrong (no such device, permission, not a device).
std::unique_ptr<V4l2OutputDevice> OpenV4l2OutputDevice(const std::string& path);

struct V4l2OutputRequest {
  cv::Size size{640, 480};
  std::string pixel_format = "auto";  // auto (YUYV, else I420), yuyv, i420
  double fps = 30;                    // advertised to the programs reading the camera
};

struct V4l2OutputFormat {
  RawPixelFormat format = RawPixelFormat::kYuyv;
  cv::Size size;
  size_t frame_bytes = 0;  // what one write() carries
  std::string card;        // the device's name (v4l2loopback: its card_label)
  std::string why;         // what was negotiated and why, for the log
};

// Checks that `device` is a video output, picks the pixel format (YUYV or
// I420, what the device offers), sets format, size and frame rate, and reads
// back what the device took: a size it changed is used; a format or line
// layout it changed is refused. Throws std::runtime_error saying why.
V4l2OutputFormat NegotiateV4l2Output(V4l2OutputDevice& device, const V4l2OutputRequest& request);

// Where a stream of raw frames goes (a V4L2 device, a pipe).
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  // Writes one whole frame. Returns false when the reader is gone for good
  // (a closed pipe): the stream ends. Throws std::runtime_error for a failure
  // that must not pass silently (the device vanished).
  virtual bool Write(const std::string& frame) = 0;
  virtual std::string Describe() const = 0;
};

// Writes frames to a negotiated V4L2 output device.
class V4l2Sink : public FrameSink {
 public:
  V4l2Sink(std::unique_ptr<V4l2OutputDevice> device, V4l2OutputFormat format);
  bool Write(const std::string& frame) override;
  std::string Describe() const override;
  const V4l2OutputFormat& format() const { return format_; }

 private:
  std::unique_ptr<V4l2OutputDevice> device_;
  V4l2OutputFormat format_;
};

// Writes frames to a file descriptor (standard output), whole frames only.
class PipeSink : public FrameSink {
 public:
  explicit PipeSink(int fd = 1);
  bool Write(const std::string& frame) override;
  std::string Describe() const override { return "pipe"; }

 private:
  int fd_;
};

// V4L2 output devices on this machine whose driver is v4l2loopback (for the
// read-back test and for diagnostics): their /dev paths.
std::vector<std::string> FindV4l2LoopbackDevices();

}  // namespace headcast
