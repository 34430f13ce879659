// Raw frames: canvas placement, waiting card, pixel-format conversion.
#include "receiver/display/raw_frames.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "common/core/camera.h"

namespace headcast {

RawPixelFormat ParseRawPixelFormat(const std::string& name) {
  if (name == "bgr24") return RawPixelFormat::kBgr24;
  if (name == "yuyv" || name == "yuyv422") return RawPixelFormat::kYuyv;
  if (name == "i420" || name == "yuv420p") return RawPixelFormat::kI420;
  throw std::invalid_argument("unknown pixel format '" + name + "' (bgr24, yuyv, i420)");
}

std::string FfmpegPixelFormatName(RawPixelFormat format) {
  switch (format) {
    case RawPixelFormat::kBgr24:
      return "bgr24";
    case RawPixelFormat::kYuyv:
      return "yuyv422";
    case RawPixelFormat::kI420:
      return "yuv420p";
  }
  return "?";
}

size_t RawFrameBytes(RawPixelFormat format, int width, int height) {
  const size_t pixels = static_cast<size_t>(width) * static_cast<size_t>(height);
  switch (format) {
    case RawPixelFormat::kBgr24:
      return 3 * pixels;
    case RawPixelFormat::kYuyv:
      return 2 * pixels;
    case RawPixelFormat::kI420:
      return pixels + 2 * (pixels / 4);
  }
  return 0;
}

cv::Size ParseOutputSize(const std::string& text) {
  int w = 0, h = 0;
  ParseSize(text, "--output-size", &w, &h);
  if (w < 16 || w > 7680 || h < 16 || h > 4320 || w % 2 || h % 2)
    throw std::invalid_argument("--output-size " + text + ": sides must be even, 16..7680 by 16..4320");
  return {w, h};
}

cv::Scalar ParseBackground(const std::string& text) {
  if (text == "black") return {0, 0, 0};
  if (text == "white") return {255, 255, 255};
  if (text == "gray" || text == "grey") return {128, 128, 128};
  if (text == "green") return {64, 177, 0};  // chroma-key green (#00B140)
  if (text == "blue") return {187, 71, 0};   // chroma-key blue (#0047BB)
  if (text.size() == 7 && text[0] == '#' && text.find_first_not_of("0123456789abcdefABCDEF", 1) == std::string::npos) {
    const long rgb = std::stol(text.substr(1), nullptr, 16);
    return {static_cast<double>(rgb & 0xff), static_cast<double>((rgb >> 8) & 0xff),
            static_cast<double>((rgb >> 16) & 0xff)};
  }
  throw std::invalid_argument("--background wants black, white, gray, green, blue or #RRGGBB (got '" + text + "')");
}

cv::Mat PlaceOnCanvas(const cv::Mat& image, cv::Size size, const cv::Scalar& background) {
  cv::Mat canvas(size, CV_8UC3, background);
  if (image.empty()) return canvas;
  const double scale =
      std::min(static_cast<double>(size.width) / image.cols, static_cast<double>(size.height) / image.rows);
  const cv::Size fitted(std::clamp(static_cast<int>(std::lround(image.cols * scale)), 1, size.width),
                        std::clamp(static_cast<int>(std::lround(image.rows * scale)), 1, size.height));
  const cv::Rect where((size.width - fitted.width) / 2, (size.height - fitted.height) / 2, fitted.width, fitted.height);
  // Area averaging shrinks without aliasing; cubic enlarges a small avatar smoothly.
  cv::resize(image, canvas(where), fitted, 0, 0, scale < 1 ? cv::INTER_AREA : cv::INTER_CUBIC);
  return canvas;
}

cv::Mat WaitingCard(cv::Size size, const cv::Scalar& background, const std::string& text) {
  cv::Mat card(size, CV_8UC3, background);
  const double luma = 0.299 * background[2] + 0.587 * background[1] + 0.114 * background[0];
  const cv::Scalar ink = luma > 128 ? cv::Scalar(40, 40, 40) : cv::Scalar(235, 235, 235);
  const double scale = std::max(0.4, size.width / 900.0);
  int baseline = 0;
  const cv::Size extent = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 2, &baseline);
  cv::putText(card, text, {(size.width - extent.width) / 2, (size.height + extent.height) / 2},
              cv::FONT_HERSHEY_SIMPLEX, scale, ink, 2, cv::LINE_AA);
  return card;
}

namespace {

uint8_t Clamp8(double v) { return static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L)); }
// BT.601, limited range (Y 16..235, U/V 16..240).
double Luma(double b, double g, double r) { return 16 + 0.256788 * r + 0.504129 * g + 0.0979059 * b; }
double ChromaU(double b, double g, double r) { return 128 - 0.148223 * r - 0.290993 * g + 0.439216 * b; }
double ChromaV(double b, double g, double r) { return 128 + 0.439216 * r - 0.367788 * g - 0.0714274 * b; }

}  // namespace

void ToRawFrame(const cv::Mat& bgr, RawPixelFormat format, std::string* out) {
  if (bgr.type() != CV_8UC3) throw std::invalid_argument("raw frames are made from 8-bit BGR pictures");
  const int w = bgr.cols, h = bgr.rows;
  if (format != RawPixelFormat::kBgr24 && (w % 2 || h % 2))
    throw std::invalid_argument("YUV frames need an even width and height");
  out->resize(RawFrameBytes(format, w, h));
  auto* dst = reinterpret_cast<uint8_t*>(out->data());
  switch (format) {
    case RawPixelFormat::kBgr24:
      for (int y = 0; y < h; ++y) std::copy_n(bgr.ptr<uint8_t>(y), 3 * w, dst + static_cast<size_t>(3 * w) * y);
      return;
    case RawPixelFormat::kYuyv:
      for (int y = 0; y < h; ++y) {
        const cv::Vec3b* row = bgr.ptr<cv::Vec3b>(y);
        uint8_t* o = dst + static_cast<size_t>(2 * w) * y;
        for (int x = 0; x < w; x += 2, o += 4) {
          const cv::Vec3b a = row[x], b = row[x + 1];
          const double mb = 0.5 * (a[0] + b[0]), mg = 0.5 * (a[1] + b[1]), mr = 0.5 * (a[2] + b[2]);
          o[0] = Clamp8(Luma(a[0], a[1], a[2]));
          o[1] = Clamp8(ChromaU(mb, mg, mr));
          o[2] = Clamp8(Luma(b[0], b[1], b[2]));
          o[3] = Clamp8(ChromaV(mb, mg, mr));
        }
      }
      return;
    case RawPixelFormat::kI420: {
      uint8_t* plane_y = dst;
      uint8_t* plane_u = dst + static_cast<size_t>(w) * h;
      uint8_t* plane_v = plane_u + static_cast<size_t>(w / 2) * (h / 2);
      for (int y = 0; y < h; ++y) {
        const cv::Vec3b* row = bgr.ptr<cv::Vec3b>(y);
        for (int x = 0; x < w; ++x)
          plane_y[static_cast<size_t>(w) * y + x] = Clamp8(Luma(row[x][0], row[x][1], row[x][2]));
      }
      for (int y = 0; y < h / 2; ++y) {
        const cv::Vec3b* r0 = bgr.ptr<cv::Vec3b>(2 * y);
        const cv::Vec3b* r1 = bgr.ptr<cv::Vec3b>(2 * y + 1);
        for (int x = 0; x < w / 2; ++x) {
          double m[3];
          for (int c = 0; c < 3; ++c) m[c] = 0.25 * (r0[2 * x][c] + r0[2 * x + 1][c] + r1[2 * x][c] + r1[2 * x + 1][c]);
          plane_u[static_cast<size_t>(w / 2) * y + x] = Clamp8(ChromaU(m[0], m[1], m[2]));
          plane_v[static_cast<size_t>(w / 2) * y + x] = Clamp8(ChromaV(m[0], m[1], m[2]));
        }
      }
      return;
    }
  }
}

bool FromRawFrame(const std::string& bytes, RawPixelFormat format, cv::Size size, cv::Mat* bgr) {
  if (bytes.size() != RawFrameBytes(format, size.width, size.height)) return false;
  auto* data = const_cast<char*>(bytes.data());  // wrapped read-only below
  switch (format) {
    case RawPixelFormat::kBgr24:
      cv::Mat(size, CV_8UC3, data).copyTo(*bgr);
      return true;
    case RawPixelFormat::kYuyv:
      cv::cvtColor(cv::Mat(size, CV_8UC2, data), *bgr, cv::COLOR_YUV2BGR_YUYV);
      return true;
    case RawPixelFormat::kI420:
      cv::cvtColor(cv::Mat(size.height * 3 / 2, size.width, CV_8UC1, data), *bgr, cv::COLOR_YUV2BGR_I420);
      return true;
  }
  return false;
}

}  // namespace headcast
