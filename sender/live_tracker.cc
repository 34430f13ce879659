// Live tracking for the sender.
#include "sender/live_tracker.h"

#include "common/tracking/tracked_fit.h"

#include <nlohmann/json.hpp>

#include "common/core/timer.h"
#include "common/core/zip_archive.h"
#include "common/tracking/mesh_fitter.h"

namespace headcast {
namespace {

FaceTrackerOptions TrackerOptions(const LiveTrackerOptions& o) {
  FaceTrackerOptions t;
  if (!o.predictor.empty()) t.predictor_path = o.predictor;
  return t;
}

}  // namespace

Eigen::VectorXd ReadTrackingIdentity(const std::string& path, const HeadModel& model) {
  const bool avatar = path.size() > 9 && path.compare(path.size() - 9, 9, ".hcavatar") == 0;
  if (!avatar) return ReadIdentityFromMeshFit(path, model);
  // The manifest only: the sender does not load networks.
  nlohmann::json manifest;
  try {
    const ZipEntries entries = ReadZip(path);
    const auto it = entries.find("manifest.json");
    if (it == entries.end()) throw std::runtime_error("no manifest.json");
    manifest = nlohmann::json::parse(it->second);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": not a readable avatar (" + e.what() + ")");
  }
  const std::string fingerprint = manifest.value("head_model", nlohmann::json::object()).value("fingerprint", "");
  if (fingerprint != model.fingerprint())
    throw std::runtime_error(path + ": an avatar for head model " + fingerprint + ", not " + model.data().name + " (" +
                             model.fingerprint() + ")");
  const std::vector<double> shape = manifest.at("subject").at("shape").get<std::vector<double>>();
  Eigen::VectorXd beta = Eigen::VectorXd::Zero(model.num_shape());
  for (size_t k = 0; k < shape.size() && static_cast<int>(k) < model.num_shape(); ++k) {
    if (!std::isfinite(shape[k])) throw std::runtime_error(path + ": non-finite shape");
    beta[static_cast<Eigen::Index>(k)] = shape[k];
  }
  return beta;
}

LiveTracker::LiveTracker(const HeadModel& model, const LiveTrackerOptions& options)
    : options_(options), tracker_(TrackerOptions(options)), fitter_(model), camera_(options.camera) {
  if (options.identity.size() > 0) fitter_.SetIdentity(options.identity);
  last_.cam_translation.setZero();  // cold start
}

LiveTrackResult LiveTracker::Process(const cv::Mat& bgr, double time_s,
                                     const std::optional<PinholeCamera>& source_camera, FrameParams* params) {
  if (!camera_)
    camera_ = source_camera ? *source_camera : PinholeCamera::FromFovY(bgr.cols, bgr.rows, options_.fov_deg);
  camera_->width = bgr.cols;  // given intrinsics: the frame says how big it is
  camera_->height = bgr.rows;
  LiveTrackResult r;
  Stopwatch watch;
  const FaceObservation obs = tracker_.Track(bgr, time_s);
  r.landmarks_ms = watch.ElapsedMs();
  r.status = obs.status;
  watch.Restart();
  r.fitted = FitTrackedFace(fitter_, obs, *camera_, &last_).ok;
  r.fit_ms = watch.ElapsedMs();
  if (!r.fitted) return r;
  *params = last_;
  return r;
}

}  // namespace headcast
