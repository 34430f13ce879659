// The per-frame tracker shared by the live sender, the offline pass and the benchmark.
#include "common/tracking/frame_tracker.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "common/core/options.h"
#include "common/core/timer.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/skin_colour.h"
#include "common/tracking/mesh_fitter.h"
#include "common/tracking/tracked_fit.h"

namespace headcast {
namespace {

// A rigid point whose flow there and back misses its start by more than this is not used.
constexpr double kFlowRoundTripPx = 0.5;

RgbdFitOptions RgbdOptions(bool fit_shape) {
  RgbdFitOptions o;
  o.fit_shape = fit_shape;
  return o;
}

bool IsAvatarFile(const std::string& path) {
  return path.size() > 9 && path.compare(path.size() - 9, 9, ".hcavatar") == 0;
}

// The manifest only: trackers do not load networks.
nlohmann::json ReadAvatarManifest(const std::string& path) {
  try {
    return ReadZipJson(path, "manifest.json");
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("not a readable avatar: ") + e.what());
  }
}

// An avatar file's manifest entry `key` read by `parse`: nothing for other
// files or without the entry; a malformed entry throws naming the file.
template <typename T>
std::optional<T> ReadAvatarEntry(const std::string& path, const char* key, T (*parse)(const nlohmann::json&)) {
  if (!IsAvatarFile(path)) return std::nullopt;
  const nlohmann::json manifest = ReadAvatarManifest(path);
  if (!manifest.contains(key)) return std::nullopt;
  try {
    return parse(manifest.at(key));
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

}  // namespace

std::optional<CameraContract> ReadAvatarCameraContract(const std::string& path) {
  return ReadAvatarEntry(path, "camera", &CameraContract::FromJson);
}

std::optional<MatteRules> ReadAvatarMatteRules(const std::string& path) {
  const std::optional<nlohmann::json> config = ReadAvatarEntry(
      path, "config", +[](const nlohmann::json& j) { return j; });
  if (!config || !config->contains("matte_rules")) return std::nullopt;
  try {
    return MatteRules::FromJson(config->at("matte_rules"));
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

std::optional<AnchorReference> ReadAvatarAnchorReference(const std::string& path) {
  return ReadAvatarEntry(path, "tracking_anchor", &AnchorReference::FromJson);
}

std::optional<ExpressionFitSettings> ReadAvatarExpressionFit(const std::string& path) {
  if (!IsAvatarFile(path)) return std::nullopt;
  return ReadAvatarEntry(path, "tracking_fit", &ExpressionFitSettings::FromJson)
      .value_or(ExpressionFitSettings::Legacy());
}

Eigen::VectorXd ReadTrackingIdentity(const std::string& path, const HeadModel& model) {
  if (!IsAvatarFile(path)) return ReadIdentityFromMeshFit(path, model);
  const nlohmann::json manifest = ReadAvatarManifest(path);
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

void FrameTrackerOptions::Check() const {
  face.Check();
  fit.Check();
  OptionsCheck c("FrameTrackerOptions");
  c.InRange("rgbd_identity_frames", rgbd_identity_frames, 1, 10000);
  c.ThrowIfErrors();
}

void ApplyRgbdFit(const RgbdFitResult& r, FrameParams* f) {
  f->expression = r.params.expression.cast<float>();
  f->jaw = r.params.pose.segment<3>(3 * kJawJoint).cast<float>();
  f->SetCamFromHead({r.rotation, r.translation});
}

FrameTracker::FrameTracker(const HeadModel& model, const FrameTrackerOptions& options)
    : model_(model),
      options_((options.Check(), options)),
      faces_(options.face),
      fitter_(model, options.fit),
      identity_(Eigen::VectorXd::Zero(model.num_shape())) {
  last_.cam_translation.setZero();  // cold start
}

FrameTracker::~FrameTracker() = default;

void FrameTracker::SetIdentity(const Eigen::VectorXd& shape, bool frozen) {
  identity_ = shape;
  fitter_.SetIdentity(shape);
  if (rgbd_) rgbd_->SetIdentity(shape);
  identity_frozen_ = frozen;
  if (anchor_) MakeAnchor(anchor_->Exported());
}

void FrameTracker::SetAnchor(const AnchorReference& reference) {
  reference.options.Check();
  if (!reference.options.enabled())
    throw std::invalid_argument("photometric anchor: the references were made with weight 0");
  MakeAnchor(reference);
}

void FrameTracker::MakeAnchor(const AnchorReference& reference) {
  auto anchor = std::make_unique<PhotometricAnchor>(model_, identity_, reference.options);
  anchor->SetReference(reference.grey);
  HeadFitterOptions fit = options_.fit;
  fit.rigid_flow_weight = reference.options.weight;
  auto fitter = std::make_unique<HeadFitter>(model_, fit);
  fitter->SetIdentity(identity_);
  anchor_ = std::move(anchor);
  anchor_fitter_ = std::move(fitter);
}

void FrameTracker::AnchorFrame(const cv::Mat& bgr, const FaceObservation& face, const PinholeCamera& camera,
                               TrackedFrame* r) {
  Stopwatch watch;
  const double iod = (face.landmarks[45] - face.landmarks[36]).norm();
  AnchorAlignment a;
  r->anchored = anchor_->Refit(AnchorGray(bgr, anchor_->options().blur_iod * iod), face.landmarks, &face.irises, iod,
                               camera, *anchor_fitter_, &last_, &a);
  if (r->anchored) r->anchor_shift_px = a.shift_px;
  r->anchor_ms = watch.ElapsedMs();
}

RgbdFitter& FrameTracker::Rgbd(bool calibrating) {
  std::unique_ptr<RgbdFitter>& fitter = calibrating ? rgbd_calibrating_ : rgbd_;
  if (!fitter) {
    fitter = std::make_unique<RgbdFitter>(model_, RgbdOptions(calibrating));
    if (!calibrating) fitter->SetIdentity(identity_);
  }
  return *fitter;
}

void FrameTracker::Reset() {
  faces_.Reset();
  last_ = FrameParams{};
  last_.cam_translation.setZero();
  last_rgbd_ = RgbdFitResult{};
  reference_ = RigidObservations{};
}

bool FrameTracker::FreezeRgbdIdentity() {
  if (calibration_shapes_.empty()) return false;
  SetIdentity(MedianShape(calibration_shapes_), true);
  calibration_shapes_.clear();
  return true;
}

RgbdFitResult FrameTracker::RefitRgbd(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera,
                                      const RgbdFitResult* previous) {
  return Rgbd(false).Fit(landmarks, depth_m, camera, previous && previous->ok ? previous : nullptr);
}

// How far from the last frame's head origin this frame's face depth is looked for.
constexpr double kDepthReach = 0.2;

cv::Rect DepthBoxForFit(const Landmarks2d& landmarks, const cv::Size& image) {
  double u_lo = INFINITY, u_hi = -INFINITY, v_lo = INFINITY, v_hi = -INFINITY;
  for (const Eigen::Vector2d& p : landmarks) {
    if (!p.allFinite()) continue;
    u_lo = std::min(u_lo, p.x());
    u_hi = std::max(u_hi, p.x());
    v_lo = std::min(v_lo, p.y());
    v_hi = std::max(v_hi, p.y());
  }
  if (!(u_hi > u_lo && v_hi > v_lo)) return {};
  const double margin = 0.2 * (u_hi - u_lo), forehead = 0.45 * (v_hi - v_lo);
  const cv::Rect box(
      cv::Point(static_cast<int>(std::floor(u_lo - margin)), static_cast<int>(std::floor(v_lo - forehead))),
      cv::Point(static_cast<int>(std::ceil(u_hi + margin)), static_cast<int>(std::ceil(v_hi + margin))));
  return box & cv::Rect(cv::Point(0, 0), image);
}

RigidObservations FollowRigidPoints(const RigidObservations& reference, const cv::Mat& reference_gray,
                                    const cv::Mat& gray, const std::vector<Eigen::Vector2d>& predicted) {
  RigidObservations out;
  if (reference.head.empty() || predicted.size() != reference.observed.size()) return out;
  std::vector<cv::Point2f> from, to, back;
  for (size_t i = 0; i < predicted.size(); ++i) {
    from.emplace_back(static_cast<float>(reference.observed[i].x()), static_cast<float>(reference.observed[i].y()));
    to.emplace_back(static_cast<float>(predicted[i].x()), static_cast<float>(predicted[i].y()));
  }
  back = from;
  std::vector<uchar> ok, ok_back;
  std::vector<float> error;
  const cv::Size window(21, 21);
  const auto criteria = cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 0.01);
  cv::calcOpticalFlowPyrLK(reference_gray, gray, from, to, ok, error, window, 3, criteria,
                           cv::OPTFLOW_USE_INITIAL_FLOW);
  cv::calcOpticalFlowPyrLK(gray, reference_gray, to, back, ok_back, error, window, 3, criteria,
                           cv::OPTFLOW_USE_INITIAL_FLOW);
  for (size_t i = 0; i < from.size(); ++i) {
    // Kept where the flow comes back to where it started (texture to follow, not occluded).
    if (!ok[i] || !ok_back[i] || cv::norm(back[i] - from[i]) > kFlowRoundTripPx) continue;
    out.head.push_back(reference.head[i]);
    out.observed.emplace_back(to[i].x, to[i].y);
  }
  return out;
}

TrackedFrame FrameTracker::Track(const cv::Mat& bgr, const cv::Mat& depth_m, double time_s, const PinholeCamera& camera,
                                 FrameParams* params, const DepthOnDemand* depth_on_demand) {
  Stopwatch watch;
  const FaceObservation face = Observe(bgr, time_s);
  const double landmarks_ms = watch.ElapsedMs();
  TrackedFrame r = TrackObserved(bgr, depth_m, face, camera, params, depth_on_demand);
  r.landmarks_ms = landmarks_ms;
  return r;
}

FaceObservation FrameTracker::Observe(const cv::Mat& bgr, double time_s) { return faces_.Track(bgr, time_s); }

TrackedFrame FrameTracker::TrackObserved(const cv::Mat& bgr, const cv::Mat& depth_m, const FaceObservation& face,
                                         const PinholeCamera& camera, FrameParams* params,
                                         const DepthOnDemand* depth_on_demand) {
  TrackedFrame r;
  Stopwatch watch;
  r.face = face;
  r.depth_m = depth_m;
  if (r.face.status != FaceStatus::kNoFace && depth_m.empty() && depth_on_demand) {
    // Following a head, depth is looked for around where it was (the face lies
    // within ~12 cm of the head's origin): stereo searches fewer disparities.
    double near_m = 0, far_m = 0;
    if (identity_frozen_ && last_rgbd_.ok) {
      near_m = std::max(0.1, last_rgbd_.translation.z() - kDepthReach);
      far_m = last_rgbd_.translation.z() + kDepthReach;
    }
    r.depth_m = depth_on_demand->DepthIn(DepthBoxForFit(r.face.landmarks, bgr.size()), near_m, far_m);
    r.depth_ms = watch.ElapsedMs();
    watch.Restart();
  }
  if (r.face.status != FaceStatus::kNoFace && !r.depth_m.empty()) {
    // RGB-D (METHOD §3): the shape is fitted on the first frames, then frozen at their median.
    r.with_depth = true;
    if (!identity_frozen_ && options_.rgbd_identity_in_background) {
      if (!background_) {
        RgbdFitOptions o = RgbdOptions(true);
        o.shape_solve_threads = 1;  // the tracking thread keeps its core
        background_ = std::make_unique<BackgroundIdentity>(model_, o, options_.rgbd_identity_frames);
      }
      if (std::optional<Eigen::VectorXd> shape = background_->Identity()) {
        SetIdentity(*shape, true);
        r.identity_frozen_now = true;
        background_.reset();
      } else {
        r.provisional_identity = true;
        background_->Offer(r.face.landmarks, r.depth_m, camera);
      }
    }
    const bool tracking = identity_frozen_ || r.provisional_identity;
    const RgbdFitResult fit =
        tracking ? Rgbd(false).Fit(r.face.landmarks, r.depth_m, camera, last_rgbd_.ok ? &last_rgbd_ : nullptr)
                 : Rgbd(true).Fit(r.face.landmarks, r.depth_m, camera);
    if (fit.ok) {
      ApplyRgbdFit(fit, &last_);
      r.fitted = true;
      r.rgbd_accuracy_m = fit.accuracy_m;
      r.contour_rejected = fit.contour_rejected;
      if (!tracking) {
        r.identity_frame = true;
        calibration_shapes_.push_back(fit.params.shape);
        if (static_cast<int>(calibration_shapes_.size()) >= options_.rgbd_identity_frames) {
          FreezeRgbdIdentity();
          r.identity_frozen_now = true;
        }
      }
    } else {
      r.problem = "RGB-D fit: " + fit.problem;
      last_.cam_translation.setZero();
    }
    last_rgbd_ = fit;
  } else {
    cv::Mat gray;
    RigidObservations rigid;
    if (options_.fit.rigid_flow_weight > 0) {
      cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
      // A face followed from the previous fit: its rigid points are found
      // again from the reference frame (not the previous one, whose error
      // they would carry on), starting where the previous pose puts them.
      if (r.face.status == FaceStatus::kTracked && last_.cam_translation.z() > 0 &&
          reference_gray_.size() == gray.size() && !reference_.head.empty()) {
        std::vector<Eigen::Vector2d> predicted;
        fitter_.ProjectRigidPoints(last_, camera, reference_.head, &predicted);
        rigid = FollowRigidPoints(reference_, reference_gray_, gray, predicted);
      } else {
        reference_ = RigidObservations{};
      }
      r.rigid_points = static_cast<int>(rigid.head.size());
    }
    r.fitted = FitTrackedFace(fitter_, r.face, camera, &last_, r.rigid_points > 0 ? &rigid : nullptr).ok;
    if (r.fitted && anchor_) AnchorFrame(bgr, r.face, camera, &r);
    // A new reference when there is none or most of its points are lost.
    if (options_.fit.rigid_flow_weight > 0 && r.fitted &&
        (reference_.head.empty() || 2 * r.rigid_points < static_cast<int>(reference_.head.size()))) {
      fitter_.RigidPointsInView(last_, camera, &reference_.head, &reference_.observed);
      reference_gray_ = gray;
    }
    if (!r.fitted && r.face.status != FaceStatus::kNoFace) r.problem = "landmark fit did not converge";
  }
  r.fit_ms = watch.ElapsedMs();
  if (r.fitted) {
    *params = last_;
    r.model_landmarks = fitter_.Project(last_, camera);
    if (options_.skin_colour) params->skin_colour = SkinColour(bgr, r.model_landmarks);
  }
  return r;
}

}  // namespace headcast
