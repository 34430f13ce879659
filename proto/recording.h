// Parameter recordings: "HCASTREC", then a length-delimited RecordingHeader,
// then length-delimited FrameParams messages. The tracker writes them, either
// end of a session can record one, and replaying one drives loopback tests.
#pragma once

#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "proto/headcast.pb.h"

namespace headcast {

constexpr int kRecordingFormatVersion = 1;

struct RecordingInfo {
  std::string head_model_name;
  std::string head_model_fingerprint;
  int num_expression = 0;
  double fps = 30;
  SubjectParams subject;
  std::string source;
};

// The header of a recording of `model`'s parameters.
RecordingInfo MakeRecordingInfo(const HeadModel& model, double fps, const SubjectParams& subject, std::string source);

// Writes a whole recording; throws naming the file.
void WriteRecording(const std::string& path, const RecordingInfo& info, const std::vector<FrameParams>& frames);

class RecordingWriter {
 public:
  // Throws naming the file if it cannot be created.
  RecordingWriter(const std::string& path, const RecordingInfo& info);
  ~RecordingWriter();
  // Each frame is handed to the operating system before Write returns, so a
  // crash or SIGKILL loses at most the frame being written.
  void Write(const FrameParams& frame);
  void Close();  // also done by the destructor
  int frames_written() const { return frames_; }

 private:
  std::string path_;
  std::ofstream out_;
  int frames_ = 0;
};

class RecordingReader {
 public:
  // Throws naming the file for a missing file, a foreign file, another format
  // version or a corrupt header.
  explicit RecordingReader(const std::string& path);
  ~RecordingReader();
  const RecordingInfo& info() const { return info_; }
  // Next frame; false at the end. A truncated or corrupt record (a capture
  // time that is not a time included) ends the recording there: `error()`
  // then says so (the frames before it are kept).
  bool Next(FrameParams* frame);
  const std::string& error() const { return error_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  RecordingInfo info_;
  std::string path_, error_;
};

// Reads a whole recording; throws like RecordingReader. A recording cut or
// corrupt after some frames (a recorder killed mid-write) gives the frames
// before the cut, with the reason in *cut, or logged as a warning when `cut`
// is null; one without a single whole frame throws.
std::vector<FrameParams> ReadRecording(const std::string& path, RecordingInfo* info = nullptr,
                                       std::string* cut = nullptr);

}  // namespace headcast
