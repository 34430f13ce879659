// The RGB-D identity fitted beside live tracking. The identity's fits (free
// shape, METHOD §3) cost ten times a tracking fit; made on the tracking thread
// they held a live camera at a few frames a second for its first seconds.
// Here they run on a thread of their own, in turn, on the first frames offered
// (copied and queued), and the identity is the per-component median of their
// shapes: the frames and the rule of the synchronous path (FrameTracker), so
// the same identity. (Frames spread over the first seconds were tried: a
// talking face's single-frame shapes vary more than those of consecutive
// frames, and the identity came out worse.)
#pragma once

#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "common/tracking/rgbd_fitter.h"

namespace headcast {

// The per-component median of `shapes` (not empty).
Eigen::VectorXd MedianShape(const std::vector<Eigen::VectorXd>& shapes);

class BackgroundIdentity {
 public:
  // `options.fit_shape` is forced on; `shapes_wanted` successful fits make the identity.
  BackgroundIdentity(const HeadModel& model, RgbdFitOptions options, int shapes_wanted);
  ~BackgroundIdentity();  // waits for the fit under way, then stops

  // Queues this frame (copied) for a fit while the frames queued, under way
  // and fitted are fewer than `shapes_wanted` (a failed fit makes room for
  // another); false otherwise (the frame is not kept).
  bool Offer(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera);
  // The identity, once `shapes_wanted` fits succeeded.
  std::optional<Eigen::VectorXd> Identity() const;
  int fits_done() const;  // tried, successful or not

 private:
  struct Job {
    Landmarks2d landmarks;
    cv::Mat depth_m;
    PinholeCamera camera;
  };
  void Run();

  // Made on the worker: its bases are large (ICT-FaceKit: ~100 MB) and
  // building them would stall the tracking thread's first frame.
  const HeadModel& model_;
  const RgbdFitOptions options_;
  const int wanted_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Job> jobs_;
  bool busy_ = false, stop_ = false;  // busy_: a fit under way
  int fits_ = 0;
  std::vector<Eigen::VectorXd> shapes_;
  std::optional<Eigen::VectorXd> identity_;
  std::thread worker_;  // last: starts once everything above exists
};

}  // namespace headcast
