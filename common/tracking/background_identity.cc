#include "common/tracking/background_identity.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <stdexcept>

#include "common/core/median.h"

namespace headcast {
namespace {

RgbdFitOptions WithShape(RgbdFitOptions o) {
  o.fit_shape = true;
  return o;
}

}  // namespace

Eigen::VectorXd MedianShape(const std::vector<Eigen::VectorXd>& shapes) {
  if (shapes.empty()) throw std::invalid_argument("MedianShape: no shapes");
  const Eigen::Index n = shapes.front().size();
  Eigen::VectorXd median(n);
  std::vector<double> v(shapes.size());
  for (Eigen::Index k = 0; k < n; ++k) {
    for (size_t i = 0; i < shapes.size(); ++i) v[i] = shapes[i][k];
    median[k] = MedianInPlace(v);
  }
  return median;
}

BackgroundIdentity::BackgroundIdentity(const HeadModel& model, RgbdFitOptions options, int shapes_wanted)
    : model_(model), options_(WithShape(std::move(options))), wanted_(shapes_wanted) {
  if (shapes_wanted < 1) throw std::invalid_argument("BackgroundIdentity: shapes_wanted must be at least 1");
  options_.Check();  // here, not on the worker, where it could only terminate
  worker_ = std::thread([this] { Run(); });
}

BackgroundIdentity::~BackgroundIdentity() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
}

bool BackgroundIdentity::Offer(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera) {
  std::lock_guard<std::mutex> lock(mutex_);
  const size_t pending = jobs_.size() + (busy_ ? 1 : 0) + shapes_.size();
  if (identity_ || stop_ || pending >= static_cast<size_t>(wanted_)) return false;
  jobs_.push_back(Job{landmarks, depth_m.clone(), camera});
  cv_.notify_all();
  return true;
}

std::optional<Eigen::VectorXd> BackgroundIdentity::Identity() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return identity_;
}

int BackgroundIdentity::fits_done() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return fits_;
}

void BackgroundIdentity::Run() {
  // Below the tracking thread and the camera's reader: the identity may take
  // a little longer, the frames of the call must not.
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10);
  RgbdFitter fitter(model_, options_);
  for (;;) {
    Job job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
      if (stop_) return;
      job = std::move(jobs_.front());
      jobs_.pop_front();
      busy_ = true;
    }
    // Each fit starts cold, as the synchronous path's: a warm start would
    // carry one frame's shape errors into the next.
    const RgbdFitResult fit = fitter.Fit(job.landmarks, job.depth_m, job.camera);
    std::lock_guard<std::mutex> lock(mutex_);
    ++fits_;
    if (fit.ok) shapes_.push_back(fit.params.shape);
    if (static_cast<int>(shapes_.size()) >= wanted_) identity_ = MedianShape(shapes_);
    busy_ = false;
  }
}

}  // namespace headcast
