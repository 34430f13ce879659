// The newest-frame hand-off.
#include "common/capture/newest_frame_source.h"

namespace headcast {

NewestFrameSource::NewestFrameSource(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {
  reader_ = std::thread([this] { Run(); });
}

NewestFrameSource::~NewestFrameSource() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  reader_.join();
}

void NewestFrameSource::Run() {
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return;
    }
    CapturedFrame frame;
    std::string problem;
    ReadStatus status;
    try {
      status = inner_->Read(&frame, &problem);
    } catch (const std::exception& e) {  // a source that fails for good ends the stream, saying why
      problem = e.what();
      status = ReadStatus::kEnd;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (status == ReadStatus::kEnd) {
      if (!problem.empty()) problem_ = problem;
      ended_ = true;
      changed_.notify_all();
      return;
    }
    if (status == ReadStatus::kSkipped) {
      problem_ = problem;
    } else {
      if (newest_) ++dropped_;
      newest_ = std::move(frame);
      problem_.reset();  // a good frame after a bad one: the bad one no longer matters
    }
    changed_.notify_all();
  }
}

ReadStatus NewestFrameSource::Read(CapturedFrame* frame, std::string* problem) {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return newest_ || problem_ || ended_; });
  if (newest_) {
    *frame = std::move(*newest_);
    newest_.reset();
    return ReadStatus::kFrame;
  }
  if (problem_) {
    if (problem) *problem = *problem_;
    problem_.reset();
    return ended_ ? ReadStatus::kEnd : ReadStatus::kSkipped;
  }
  return ReadStatus::kEnd;
}

uint64_t NewestFrameSource::dropped() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return dropped_;
}

}  // namespace headcast
