// Recorded sequences: video files and image folders, read as fast as possible
// or paced in real time, optionally looping.
#pragma once

#include <vector>

#include "common/capture/frame_source.h"
#include "common/core/image_io.h"
#include "common/core/timer.h"

namespace headcast {

// Real-time pacing shared by the recorded sources: waits until frame i is due
// and stamps it with the steady clock; or stamps media time when not paced.
class Pacer {
 public:
  Pacer(bool realtime, double fps) : realtime_(realtime), fps_(fps) {}
  double Stamp(uint64_t index);

 private:
  bool realtime_;
  double fps_;
  double start_ = -1;
};

class VideoFileSource final : public FrameSource {
 public:
  VideoFileSource(std::string path, const SourceOptions& options);
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override { return "video " + path_; }
  double fps() const override { return fps_; }
  int64_t frame_count() const override { return options_.loop ? 0 : reader_->frame_count(); }

 private:
  std::string path_;
  SourceOptions options_;
  std::unique_ptr<VideoReader> reader_;
  double fps_ = 30;
  uint64_t index_ = 0, in_pass_ = 0;
  Pacer pacer_;
};

class ImageFolderSource final : public FrameSource {
 public:
  ImageFolderSource(std::string folder, const SourceOptions& options);
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override { return "images in " + folder_; }
  double fps() const override { return options_.fps; }
  int64_t frame_count() const override { return options_.loop ? 0 : static_cast<int64_t>(files_.size()); }
  size_t size() const { return files_.size(); }

 private:
  std::string folder_;
  SourceOptions options_;
  std::vector<std::string> files_;
  size_t next_ = 0;
  uint64_t index_ = 0;
  Pacer pacer_;
};

// Colour + 16-bit depth PNG pairs listed in a TUM-style association file:
// lines "t_rgb rgb/x.png t_depth depth/x.png" ('#' comments), paths relative
// to the file. Depth values are units of 1/depth_units_per_metre metres; 0 is unknown.
class RgbdFolderSource final : public FrameSource {
 public:
  RgbdFolderSource(std::string associations, const SourceOptions& options);
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override;
  std::string Describe() const override { return "RGB-D pairs from " + associations_; }
  double fps() const override { return fps_; }
  bool has_depth() const override { return true; }
  size_t size() const { return pairs_.size(); }

 private:
  std::string associations_;
  SourceOptions options_;
  std::vector<RgbdPair> pairs_;
  double fps_ = 30;
  size_t next_ = 0;
  uint64_t index_ = 0;
  Pacer pacer_;
};

}  // namespace headcast
