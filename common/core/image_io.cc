// Image and video I/O.
#include "common/core/image_io.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

namespace headcast {
namespace {
void MakeParentDir(const std::string& path) {
  const auto parent = std::filesystem::path(path).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
}
}  // namespace

cv::Mat ReadImage(const std::string& path, int flags) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such image file");
  cv::Mat image = cv::imread(path, flags);
  if (image.empty()) throw std::runtime_error(path + ": cannot decode image (corrupt or unsupported format)");
  return image;
}

void WriteImage(const std::string& path, const cv::Mat& image) {
  if (image.empty()) throw std::invalid_argument(path + ": refusing to write an empty image");
  MakeParentDir(path);
  bool ok = false;
  try {
    ok = cv::imwrite(path, image);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(path + ": cannot write image: " + e.what());
  }
  if (!ok) throw std::runtime_error(path + ": cannot write image (unknown extension or unwritable folder)");
}

cv::Mat ToUint8(const cv::Mat& f) {
  cv::Mat out;
  f.convertTo(out, CV_8U, 255.0);  // saturate_cast clamps
  return out;
}

VideoReader::VideoReader(const std::string& path) : path_(path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such video file");
  if (!capture_.open(path)) throw std::runtime_error(path + ": cannot open video (corrupt or unsupported)");
  fps_ = capture_.get(cv::CAP_PROP_FPS);
  frame_count_ = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_COUNT));
  size_ = {static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_WIDTH)),
           static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_HEIGHT))};
}

bool VideoReader::Read(cv::Mat* frame) {
  try {
    return capture_.read(*frame) && !frame->empty();
  } catch (const cv::Exception&) {
    return false;
  }
}

VideoWriter::VideoWriter(std::string path, double fps) : path_(std::move(path)), fps_(fps) {
  if (!(fps_ > 0)) throw std::invalid_argument(path_ + ": video frame rate must be > 0");
  MakeParentDir(path_);
}

VideoWriter::~VideoWriter() { Close(); }

void VideoWriter::Write(const cv::Mat& frame) {
  if (frame.empty()) throw std::invalid_argument(path_ + ": empty video frame");
  cv::Mat bgr = frame;
  if (frame.channels() == 1) cv::cvtColor(frame, bgr, cv::COLOR_GRAY2BGR);
  if (!writer_.isOpened()) {
    size_ = {bgr.cols & ~1, bgr.rows & ~1};  // encoders want even sizes
    if (!writer_.open(path_, cv::VideoWriter::fourcc('a', 'v', 'c', '1'), fps_, size_))
      throw std::runtime_error(path_ + ": cannot open video writer (is OpenCV built with FFmpeg?)");
  }
  if (bgr.size() != size_) cv::resize(bgr, bgr, size_, 0, 0, cv::INTER_AREA);
  writer_.write(bgr);
  ++frames_;
}

void VideoWriter::Close() {
  if (writer_.isOpened()) writer_.release();
}

std::vector<std::string> ListImageFiles(const std::string& folder) {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(folder)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (e.is_regular_file() && (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".ppm" ||
                                ext == ".tif" || ext == ".tiff"))
      files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<RgbdPair> ReadRgbdAssociations(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open the RGB-D association file");
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  std::vector<RgbdPair> pairs;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    RgbdPair p;
    double depth_time;
    std::string colour, depth;
    if (!(fields >> p.time >> colour >> depth_time >> depth))
      throw std::runtime_error(path + ": line " + std::to_string(number) +
                               ": expected 'time colour.png time depth.png'");
    p.colour = (base / colour).string();
    p.depth = (base / depth).string();
    pairs.push_back(p);
  }
  if (pairs.empty()) throw std::runtime_error(path + ": no colour/depth pairs listed");
  return pairs;
}

std::string FrameFileName(int frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "%05d.png", frame);
  return name;
}

}  // namespace headcast
