// Parameter recordings.
#include "proto/recording.h"

#include <google/protobuf/io/zero_copy_stream_impl.h>
#include <google/protobuf/util/delimited_message_util.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "proto/convert.h"

namespace headcast {
namespace {
constexpr char kMagic[8] = {'H', 'C', 'A', 'S', 'T', 'R', 'E', 'C'};
constexpr double kMaxCaptureTimeS = 1e12;  // ~31,700 years: any clock's seconds fit
}  // namespace

RecordingWriter::RecordingWriter(const std::string& path, const RecordingInfo& info) : path_(path) {
  const auto parent = std::filesystem::path(path).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  out_.open(path, std::ios::binary | std::ios::trunc);
  if (!out_) throw std::runtime_error(path + ": cannot create recording");
  out_.write(kMagic, sizeof(kMagic));
  v1::RecordingHeader header;
  header.set_format_version(kRecordingFormatVersion);
  header.set_head_model_name(info.head_model_name);
  header.set_head_model_fingerprint(info.head_model_fingerprint);
  header.set_num_expression(info.num_expression);
  header.set_fps(info.fps);
  ToProto(info.subject, header.mutable_subject());
  header.set_source(info.source);
  header.set_created_unix_s(
      std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count());
  if (!google::protobuf::util::SerializeDelimitedToOstream(header, &out_))
    throw std::runtime_error(path + ": cannot write recording header");
}

RecordingInfo MakeRecordingInfo(const HeadModel& model, double fps, const SubjectParams& subject, std::string source) {
  RecordingInfo info;
  info.head_model_name = model.data().name;
  info.head_model_fingerprint = model.fingerprint();
  info.num_expression = model.num_expression();
  info.fps = fps;
  info.subject = subject;
  info.source = std::move(source);
  return info;
}

void WriteRecording(const std::string& path, const RecordingInfo& info, const std::vector<FrameParams>& frames) {
  RecordingWriter writer(path, info);
  for (const FrameParams& f : frames) writer.Write(f);
  writer.Close();
}

RecordingWriter::~RecordingWriter() { Close(); }

void RecordingWriter::Write(const FrameParams& frame) {
  v1::FrameParams message;
  ToProto(frame, &message);
  if (!google::protobuf::util::SerializeDelimitedToOstream(message, &out_) || !out_.flush())
    throw std::runtime_error(path_ + ": write failed");
  ++frames_;
}

void RecordingWriter::Close() {
  if (out_.is_open()) {
    out_.flush();
    out_.close();
  }
}

struct RecordingReader::Impl {
  std::ifstream file;
  std::unique_ptr<google::protobuf::io::IstreamInputStream> stream;
};

RecordingReader::RecordingReader(const std::string& path) : impl_(std::make_unique<Impl>()), path_(path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path + ": no such recording");
  impl_->file.open(path, std::ios::binary);
  char magic[sizeof(kMagic)] = {};
  impl_->file.read(magic, sizeof(magic));
  if (!impl_->file || !std::equal(magic, magic + sizeof(magic), kMagic))
    throw std::runtime_error(path + ": not a headcast parameter recording (bad magic)");
  impl_->stream = std::make_unique<google::protobuf::io::IstreamInputStream>(&impl_->file);
  v1::RecordingHeader header;
  bool clean_eof = false;
  if (!google::protobuf::util::ParseDelimitedFromZeroCopyStream(&header, impl_->stream.get(), &clean_eof))
    throw std::runtime_error(path + ": corrupt or truncated recording header");
  if (header.format_version() != kRecordingFormatVersion)
    throw std::runtime_error(path + ": recording format version " + std::to_string(header.format_version()) +
                             ", this build reads version " + std::to_string(kRecordingFormatVersion));
  info_.head_model_name = header.head_model_name();
  info_.head_model_fingerprint = header.head_model_fingerprint();
  info_.num_expression = static_cast<int>(header.num_expression());
  info_.fps = header.fps() > 0 ? header.fps() : 30;
  info_.source = header.source();
  std::string why;
  if (!FromProto(header.subject(), &info_.subject, &why)) throw std::runtime_error(path + ": bad subject: " + why);
}

RecordingReader::~RecordingReader() = default;

bool RecordingReader::Next(FrameParams* frame) {
  if (!error_.empty()) return false;
  v1::FrameParams message;
  bool clean_eof = false;
  if (!google::protobuf::util::ParseDelimitedFromZeroCopyStream(&message, impl_->stream.get(), &clean_eof)) {
    if (!clean_eof) error_ = path_ + ": truncated or corrupt record; the recording ends there";
    return false;
  }
  std::string why;
  if (!FromProto(message, frame, &why)) {
    error_ = path_ + ": bad record: " + why;
    return false;
  }
  // Pacing waits for capture times: a NaN or 1e300 one would never come.
  if (!std::isfinite(frame->capture_time_s) || std::abs(frame->capture_time_s) > kMaxCaptureTimeS) {
    error_ = path_ + ": bad record: capture time " + std::to_string(frame->capture_time_s) +
             " is not a time; the recording ends there";
    return false;
  }
  return true;
}

std::vector<FrameParams> ReadRecording(const std::string& path, RecordingInfo* info, std::string* cut) {
  RecordingReader reader(path);
  std::vector<FrameParams> frames;
  FrameParams f;
  while (reader.Next(&f)) frames.push_back(f);
  if (!reader.error().empty()) {
    if (frames.empty()) throw std::runtime_error(reader.error());
    const std::string reason = reader.error() + " (" + std::to_string(frames.size()) + " frames before it kept)";
    if (cut)
      *cut = reason;
    else
      spdlog::warn("{}", reason);
  }
  if (info) *info = reader.info();
  return frames;
}

}  // namespace headcast
