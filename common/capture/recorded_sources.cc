// Video files, image folders and RGB-D association files as frame sources.
#include "common/capture/recorded_sources.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <thread>

namespace headcast {

namespace fs = std::filesystem;

double Pacer::Stamp(uint64_t index) {
  if (!realtime_) return index / fps_;
  const double now = SteadyNowSeconds();
  if (start_ < 0) start_ = now - index / fps_;
  const double due = start_ + index / fps_;
  if (due > now) std::this_thread::sleep_for(std::chrono::duration<double>(due - now));
  return std::max(now, due);
}

VideoFileSource::VideoFileSource(std::string path, const SourceOptions& options)
    : path_(std::move(path)), options_(options), pacer_(options.realtime, 30) {
  reader_ = std::make_unique<VideoReader>(path_);  // throws naming the file
  fps_ = reader_->fps() > 0 ? reader_->fps() : options.fps;
  pacer_ = Pacer(options.realtime, fps_);
}

ReadStatus VideoFileSource::Read(CapturedFrame* frame, std::string* problem) {
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (reader_->Read(&frame->bgr)) {
      ++in_pass_;
      frame->index = index_;
      frame->capture_time_s = pacer_.Stamp(index_++);
      frame->depth_m.release();
      frame->depth_on_demand.reset();
      frame->camera.reset();
      return ReadStatus::kFrame;
    }
    const int expected = reader_->frame_count();
    if (expected > 0 && static_cast<int>(in_pass_) + 1 < expected && problem)
      *problem = path_ + ": the video ended after " + std::to_string(in_pass_) + " of " + std::to_string(expected) +
                 " frames (truncated or corrupt?)";
    if (!options_.loop || in_pass_ == 0) return ReadStatus::kEnd;
    reader_ = std::make_unique<VideoReader>(path_);
    in_pass_ = 0;
  }
  return ReadStatus::kEnd;
}

ImageFolderSource::ImageFolderSource(std::string folder, const SourceOptions& options)
    : folder_(std::move(folder)), options_(options), pacer_(options.realtime, options.fps) {
  if (!fs::is_directory(folder_)) throw std::runtime_error(folder_ + ": not a folder");
  files_ = ListImageFiles(folder_);
  if (files_.empty()) throw std::runtime_error(folder_ + ": no images in this folder (png, jpg, bmp, ppm, tif)");
}

ReadStatus ImageFolderSource::Read(CapturedFrame* frame, std::string* problem) {
  if (next_ == files_.size()) {
    if (!options_.loop) return ReadStatus::kEnd;
    next_ = 0;
  }
  const std::string& file = files_[next_++];
  frame->index = index_;
  frame->capture_time_s = pacer_.Stamp(index_++);
  frame->depth_m.release();
  frame->depth_on_demand.reset();
  frame->camera.reset();
  try {
    frame->bgr = ReadImage(file);
  } catch (const std::exception& e) {
    if (problem) *problem = e.what();
    return ReadStatus::kSkipped;
  }
  return ReadStatus::kFrame;
}

RgbdFolderSource::RgbdFolderSource(std::string associations, const SourceOptions& options)
    : associations_(std::move(associations)), options_(options), pacer_(options.realtime, options.fps) {
  pairs_ = ReadRgbdAssociations(associations_);  // throws naming the file
  if (pairs_.size() > 1) {
    const double span = pairs_.back().time - pairs_.front().time;
    if (span > 0) fps_ = (pairs_.size() - 1) / span;
  }
  pacer_ = Pacer(options.realtime, fps_);
}

ReadStatus RgbdFolderSource::Read(CapturedFrame* frame, std::string* problem) {
  if (next_ == pairs_.size()) {
    if (!options_.loop) return ReadStatus::kEnd;
    next_ = 0;
  }
  const RgbdPair& p = pairs_[next_++];
  frame->index = index_;
  frame->capture_time_s = pacer_.Stamp(index_++);
  frame->camera.reset();
  try {
    frame->bgr = ReadImage(p.colour);
  } catch (const std::exception& e) {
    if (problem) *problem = e.what();
    return ReadStatus::kSkipped;
  }
  const cv::Mat raw = cv::imread(p.depth, cv::IMREAD_ANYDEPTH);
  if (raw.empty() || raw.type() != CV_16UC1) {
    if (problem)
      *problem = p.depth + (raw.empty() ? ": unreadable depth image" : ": depth must be a 16-bit single-channel PNG");
    return ReadStatus::kSkipped;
  }
  if (raw.size() != frame->bgr.size()) {
    if (problem)
      *problem = p.depth + ": depth is " + std::to_string(raw.cols) + "x" + std::to_string(raw.rows) +
                 ", the colour image " + std::to_string(frame->bgr.cols) + "x" + std::to_string(frame->bgr.rows);
    return ReadStatus::kSkipped;
  }
  raw.convertTo(frame->depth_m, CV_32F, 1.0 / options_.depth_units_per_metre);
  frame->depth_on_demand.reset();
  return ReadStatus::kFrame;
}

}  // namespace headcast
