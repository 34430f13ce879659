#include "sender/outline_pipeline.h"

#include <spdlog/spdlog.h>

#include <stdexcept>

#include "common/core/timer.h"

namespace headcast {

OutlinePipeline::OutlinePipeline(std::unique_ptr<FrameOutliner> outliner, int depth)
    : outliner_(std::move(outliner)), depth_(depth) {
  if (!outliner_) throw std::invalid_argument("OutlinePipeline: no outliner");
  if (depth < 1) throw std::invalid_argument("OutlinePipeline: depth " + std::to_string(depth) + " (at least 1)");
  worker_ = std::thread([this] { Work(); });
}

OutlinePipeline::~OutlinePipeline() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  worker_.join();
}

void OutlinePipeline::Push(OutlineJob job) {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return static_cast<int>(waiting_.size()) + (busy_ ? 1 : 0) < depth_; });
  waiting_.push_back(std::move(job));
  lock.unlock();
  changed_.notify_all();
}

std::optional<OutlinePipeline::Done> OutlinePipeline::TryPop() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (done_.empty()) return std::nullopt;
  Done d = std::move(done_.front());
  done_.pop_front();
  return d;
}

std::optional<OutlinePipeline::Done> OutlinePipeline::Pop() {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return !done_.empty() || (waiting_.empty() && !busy_); });
  if (done_.empty()) return std::nullopt;
  Done d = std::move(done_.front());
  done_.pop_front();
  return d;
}

int OutlinePipeline::pending() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(waiting_.size() + done_.size()) + (busy_ ? 1 : 0);
}

void OutlinePipeline::Work() {
  for (;;) {
    OutlineJob job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || !waiting_.empty(); });
      if (stop_) return;
      job = std::move(waiting_.front());
      waiting_.pop_front();
      busy_ = true;
    }
    Stopwatch watch;
    Done d{job.params, 0};
    try {
      d.params.outline = outliner_->Measure(job);
    } catch (const std::exception& e) {  // a frame the mask cannot be cut on goes without an outline
      spdlog::warn("frame without the hair's outline: {}", e.what());
      d.params.outline.clear();
    }
    d.outline_ms = watch.ElapsedMs();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      busy_ = false;
      done_.push_back(std::move(d));
    }
    changed_.notify_all();
  }
}

}  // namespace headcast
