// Benchmark suite "track": the sender's per-frame tracking cost (face tracker,
// landmarks, head-model fit) on a video, through the FrameTracker the sender and
// headcast-track use.
#include <deque>
#include <memory>
#include <optional>

#include "bench/bench.h"
#include "common/core/image_io.h"
#include "common/core/timer.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/frame_tracker.h"

namespace headcast::bench {
namespace {

// Raw landmarks found on consecutive frames: their jitter, the second
// difference of each point (mean over the 68, over the eye distance).
class Jitter {
 public:
  void Add(const FaceObservation& o) {
    if (o.status == FaceStatus::kNoFace) return last_.clear();
    last_.push_back(o.raw);
    if (last_.size() > 3) last_.pop_front();
    if (last_.size() < 3) return;
    stats_.Add(LandmarkJitterIod(last_[0], last_[1], last_[2]));
  }
  const SampleStats& stats() const { return stats_; }

 private:
  std::deque<Landmarks2d> last_;
  SampleStats stats_;
};

}  // namespace

nlohmann::json RunTrackSuite(const BenchOptions& options) {
  if (options.video.empty())
    throw std::invalid_argument("track: give --video (e.g. ../shared/data/video/talking_d9.mp4)");
  const HeadModel model = LoadHeadModelSpec(options.head_model);
  FrameTracker tracker(model);
  // With an avatar carrying the photometric anchor: the sender's rule with it
  // on the same frames beside the landmark fit (both with the avatar's identity).
  std::unique_ptr<FrameTracker> anchored;
  if (!options.avatar.empty()) {
    const std::optional<AnchorReference> reference = ReadAvatarAnchorReference(options.avatar);
    if (!reference) throw std::invalid_argument("track: " + options.avatar + " carries no photometric anchor");
    const Eigen::VectorXd identity = ReadTrackingIdentity(options.avatar, model);
    tracker.SetIdentity(identity);
    anchored = std::make_unique<FrameTracker>(model);
    anchored->SetIdentity(identity);
    anchored->SetAnchor(*reference);
  }
  SampleStats anchored_total, anchor_ms;
  int anchored_frames = 0;
  FrameParams anchored_params;
  // Drift: the tracked landmarks against those of a detection on every frame
  // (untimed), with the box drawn by the last detection's margins (the
  // default) and by fixed margins.
  FaceTrackerOptions fixed_margins, every_frame;
  fixed_margins.box_from_detection = false;
  every_frame.redetect_interval = 1;
  FaceTracker fixed_tracker(fixed_margins), reference(every_frame);
  SampleStats drift, fixed_drift;
  // The shape predictor on every view of the face (FaceTrackerOptions::
  // predictor_views) against the one box: its cost and the landmarks' jitter.
  FaceTrackerOptions one_view, all_views;
  one_view.filter = all_views.filter = false;
  all_views.predictor_views = kMaxPredictorViews;
  FaceTracker one_view_tracker(one_view), all_views_tracker(all_views);
  SampleStats one_view_ms, all_views_ms;
  Jitter one_view_jitter, all_views_jitter;
  VideoReader video(options.video);
  const double fps = video.fps() > 0 ? video.fps() : 30;
  SampleStats total, track_ms, fit_ms, error;
  int frames = 0, fitted = 0;
  FrameParams params;
  cv::Mat frame;
  while (video.Read(&frame) && (options.repeats <= 0 || frames < options.repeats)) {
    const PinholeCamera camera = PinholeCamera::FromFovY(frame.cols, frame.rows, 40);
    const TrackedFrame t = tracker.Track(frame, cv::Mat(), frames / fps, camera, &params);
    const FaceObservation& obs = t.face;
    total.Add(t.landmarks_ms + t.fit_ms);
    track_ms.Add(t.landmarks_ms);
    fit_ms.Add(t.fit_ms);
    if (anchored) {
      const TrackedFrame a = anchored->Track(frame, cv::Mat(), frames / fps, camera, &anchored_params);
      anchored_total.Add(a.landmarks_ms + a.fit_ms);
      if (a.fitted) anchor_ms.Add(a.anchor_ms);
      anchored_frames += a.anchored;
    }
    ++frames;
    const FaceObservation fixed_obs = fixed_tracker.Track(frame, frames / fps);
    const FaceObservation ref = reference.Track(frame, frames / fps);
    Stopwatch clock;
    one_view_jitter.Add(one_view_tracker.Track(frame, frames / fps));
    one_view_ms.Add(clock.ElapsedMs());
    clock.Restart();
    all_views_jitter.Add(all_views_tracker.Track(frame, frames / fps));
    all_views_ms.Add(clock.ElapsedMs());
    if (ref.status != FaceStatus::kNoFace && obs.status == FaceStatus::kTracked &&
        fixed_obs.status == FaceStatus::kTracked) {
      drift.Add(LandmarkErrorIod(obs.raw, ref.raw));
      fixed_drift.Add(LandmarkErrorIod(fixed_obs.raw, ref.raw));
    }
    if (t.fitted) {
      ++fitted;
      error.Add(LandmarkErrorIod(tracker.fitter().Project(params, camera), obs.raw));
    }
  }
  nlohmann::json out;
  out["suite"] = "track";
  out["what"] =
      "FrameTracker::Track per frame (detect/track + 68 landmarks + fit, as the sender and headcast-track run it), ms; "
      "run under taskset -c 0 "
      "for one core";
  out["video"] = options.video;
  out["head_model"] = model.data().name;
  out["frames"] = frames;
  out["fitted_frames"] = fitted;
  out["landmark_error_iod_mean"] = error.Mean();
  out["ms_per_frame_median"] = total.Median();
  out["ms_per_frame_p95"] = total.Percentile(95);
  out["track_ms_median"] = track_ms.Median();
  out["drift_what"] =
      "tracked frames: mean distance of the raw landmarks from those found in a detector box on the same frame, over "
      "the outer-eye-corner distance; box from the last detection's margins (default) and from fixed margins";
  out["drift_frames"] = drift.count();
  out["drift_iod_mean"] = drift.Mean();
  out["drift_iod_p95"] = drift.Percentile(95);
  out["drift_iod_max"] = drift.Max();
  out["fixed_margins_drift_iod_mean"] = fixed_drift.Mean();
  out["fixed_margins_drift_iod_p95"] = fixed_drift.Percentile(95);
  out["fixed_margins_drift_iod_max"] = fixed_drift.Max();
  out["fit_ms_median"] = fit_ms.Median();
  out["views_what"] =
      "FaceTracker::Track unfiltered (as prep runs it) with the shape predictor on one box and on all " +
      std::to_string(kMaxPredictorViews) +
      " views (--predictor-views): ms per frame, and the raw landmarks' jitter (second difference over consecutive "
      "frames, mean over the 68, over the outer-eye-corner distance)";
  if (anchored) {
    out["anchored_what"] =
        "the same frames tracked as the sender does with an avatar carrying the photometric anchor (--avatar): the "
        "landmark fit, the alignment to its references, the fit again; ms per frame, the anchor's share, frames "
        "anchored (the others kept their landmark fit)";
    out["anchored_ms_per_frame_median"] = anchored_total.Median();
    out["anchored_ms_per_frame_p95"] = anchored_total.Percentile(95);
    out["anchor_ms_median"] = anchor_ms.empty() ? 0.0 : anchor_ms.Median();
    out["anchor_ms_p95"] = anchor_ms.empty() ? 0.0 : anchor_ms.Percentile(95);
    out["anchored_frames"] = anchored_frames;
  }
  out["one_view_ms_median"] = one_view_ms.Median();
  out["all_views_ms_median"] = all_views_ms.Median();
  out["one_view_jitter_iod_median"] = one_view_jitter.stats().Median();
  out["all_views_jitter_iod_median"] = all_views_jitter.stats().Median();
  return out;
}

}  // namespace headcast::bench
