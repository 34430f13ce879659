// The frames' outlines measured on a worker thread while the tracker fits the
// next frame: the sender's frame then costs the longer of the two instead of
// their sum. Frames come out in the order they went in, each with its outline
// (empty when its mask could not be cut); none is dropped.
#pragma once

#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "sender/frame_outliner.h"

namespace headcast {

class OutlinePipeline {
 public:
  struct Done {
    FrameParams params;  // the job's, with its outline
    double outline_ms = 0;
  };
  // `depth`: frames waiting or being measured at most; Push waits beyond it
  // (the tracker then falls behind a live source, which skips frames, rather
  // than frames ageing in a queue). Throws std::invalid_argument below 1.
  OutlinePipeline(std::unique_ptr<FrameOutliner> outliner, int depth = 2);
  // Stops after the job being measured; jobs not yet measured are dropped.
  ~OutlinePipeline();
  OutlinePipeline(const OutlinePipeline&) = delete;
  OutlinePipeline& operator=(const OutlinePipeline&) = delete;

  void Push(OutlineJob job);
  std::optional<Done> TryPop();  // the oldest finished frame; never waits
  std::optional<Done> Pop();     // the oldest frame pushed, waiting for it; nothing when none is pending
  int pending() const;           // pushed and not popped

 private:
  void Work();

  std::unique_ptr<FrameOutliner> outliner_;
  const int depth_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<OutlineJob> waiting_;
  bool busy_ = false;  // the worker holds a job
  std::deque<Done> done_;
  bool stop_ = false;
  std::thread worker_;
};

}  // namespace headcast
