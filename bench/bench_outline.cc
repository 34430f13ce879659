// Benchmark suite "outline": what the sender's hair outline costs a frame and
// what cutting only near the last outline (HeadMaskOptions::band) changes,
// side by side on the same frames: the frames tracked once as the sender
// tracks them with the avatar, then each outlined by two FrameOutliners on
// this thread (a learning every refit_every frames included), one cutting the
// whole region and one the band.
#include <cmath>

#include "bench/bench.h"
#include "common/core/image_io.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_outline.h"
#include "common/tracking/frame_tracker.h"
#include "sender/frame_outliner.h"
#include "sender/live_tracker.h"

namespace headcast::bench {

nlohmann::json RunOutlineSuite(const BenchOptions& options) {
  if (options.video.empty() || options.avatar.empty())
    throw std::invalid_argument("outline: give --video and --avatar (an avatar that records its camera)");
  const HeadModel model = LoadHeadModelSpec(options.head_model);
  const std::optional<CameraContract> contract = ReadAvatarCameraContract(options.avatar);
  if (!contract) throw std::invalid_argument("outline: " + options.avatar + " records no camera");
  FrameTracker tracker(model);
  const Eigen::VectorXd identity = ReadTrackingIdentity(options.avatar, model);
  tracker.SetIdentity(identity);
  if (const std::optional<AnchorReference> anchor = ReadAvatarAnchorReference(options.avatar))
    tracker.SetAnchor(*anchor);
  LiveTrackerOptions live;  // the sender's settings of the outline's mask
  const MatteRules rules = ReadAvatarMatteRules(options.avatar).value_or(live.matte_rules);
  HeadMaskOptions whole = live.outline_mask, banded = live.outline_mask;
  whole.band = 0;
  banded.band = options.outline_band;
  banded.Check();

  VideoReader video(options.video);
  const double fps = video.fps() > 0 ? video.fps() : 30;
  std::optional<FrameCrop> crop;
  std::optional<PinholeCamera> camera;
  std::unique_ptr<FrameOutliner> a, b;
  SampleStats whole_ms, band_ms, difference_mm, learn_with_mask_ms, learn_alone_ms;
  int learnings = 0, learnings_equal = 0;
  int frames = 0, outlined = 0, bins = 0, equal_bins = 0;
  cv::Mat frame;
  FrameParams params;
  while (video.Read(&frame) && (options.repeats <= 0 || frames < options.repeats)) {
    if (!camera) {
      camera = ContractCameraFor(*contract, frame.cols, frame.rows);
      if (!camera) throw std::invalid_argument("outline: the video's frames are not of the avatar's camera");
      crop = ContractCrop(*contract, *camera, live.outline_resolution);
      if (!crop) throw std::invalid_argument("outline: no crop of the avatar's square in these frames");
      a = std::make_unique<FrameOutliner>(model, *crop, rules, whole, false);
      b = std::make_unique<FrameOutliner>(model, *crop, rules, banded, false);
    }
    const FaceObservation face = tracker.Observe(frame, frames / fps);
    ++frames;
    if (face.status == FaceStatus::kNoFace) {
      a->Forget();
      b->Forget();
      continue;
    }
    a->Start(frame, face.raw);
    b->Start(frame, face.raw);
    const TrackedFrame t = tracker.TrackObserved(frame, cv::Mat(), face, *camera, &params);
    if (!t.fitted) {
      a->Forget();
      b->Forget();
      continue;
    }
    const Landmarks2d fitted = tracker.fitter().Project(params, crop->camera);
    std::vector<float> outline_a, outline_b;
    // Alternated, so that neither always runs with the other's data in the
    // caches; each from the same random state (a learning's k-means++ draws
    // from it), as one sender's outliner would be.
    const uint64 random_state = cv::theRNG().state;
    for (int k = 0; k < 2; ++k) {
      const bool first_a = (frames % 2 == 0) == (k == 0);
      cv::theRNG().state = random_state;
      Stopwatch watch;
      try {
        (first_a ? outline_a : outline_b) = (first_a ? a : b)->Finish(params, fitted, tracker.identity());
      } catch (const std::invalid_argument&) {
      }
      (first_a ? whole_ms : band_ms).Add(watch.ElapsedMs());
    }
    // The learner thread's work on the frames it learns on: HeadMask's
    // learning, and the models alone (its last cut left out).
    if (outlined % whole.refit_every == 0) {
      HeadMaskModels with_mask;
      cv::theRNG().state = random_state;
      Stopwatch watch;
      HeadMask(frame, face.raw, whole, &with_mask);
      learn_with_mask_ms.Add(watch.ElapsedMs());
      cv::theRNG().state = random_state;
      watch.Restart();
      const HeadMaskModels alone = LearnHeadMaskModels(frame, face.raw, whole);
      learn_alone_ms.Add(watch.ElapsedMs());
      ++learnings;
      learnings_equal += cv::norm(with_mask.background, alone.background, cv::NORM_INF) == 0 &&
                         cv::norm(with_mask.foreground, alone.foreground, cv::NORM_INF) == 0;
    }
    if (outline_a.empty() || outline_b.empty()) continue;
    ++outlined;
    for (size_t i = 0; i < outline_a.size(); ++i) {
      if (outline_a[i] == kOutlineUnknown || outline_b[i] == kOutlineUnknown) continue;
      ++bins;
      equal_bins += outline_a[i] == outline_b[i];
      difference_mm.Add(std::abs(outline_a[i] - outline_b[i]));
    }
  }
  nlohmann::json out;
  out["suite"] = "outline";
  out["what"] =
      "the sender's hair outline (FrameOutliner::Finish on the tracking thread: the frame's GrabCut head mask with "
      "colour models learnt every " +
      std::to_string(whole.refit_every) +
      "th frame and carried between, the matte's rules with the fitted head, the outline measured), ms per frame, "
      "cut over the whole head region and only within --outline-band working pixels of the last frame's outline, "
      "side by side on the same tracked frames; and how far the two outlines differ, mm at the head";
  out["video"] = options.video;
  out["avatar"] = options.avatar;
  out["frames"] = frames;
  out["frames_outlined"] = outlined;
  out["band"] = banded.band;
  AddStats(&out, "whole_ms", whole_ms);
  AddStats(&out, "band_ms", band_ms);
  out["whole_ms_total"] = whole_ms.Mean() * whole_ms.count();
  out["band_ms_total"] = band_ms.Mean() * band_ms.count();
  out["learner_what"] =
      "the learner thread's work on every " + std::to_string(whole.refit_every) +
      "th outlined frame: HeadMask's learning (its mask made) and LearnHeadMaskModels (the models alone, the "
      "learning's last cut left out), ms, from the same random state; learnings whose models are equal";
  AddStats(&out, "learn_with_mask_ms", learn_with_mask_ms);
  AddStats(&out, "learn_alone_ms", learn_alone_ms);
  out["learnings"] = learnings;
  out["learnings_equal"] = learnings_equal;
  out["bins_compared"] = bins;
  out["bins_equal_share"] = bins ? static_cast<double>(equal_bins) / bins : 0.0;
  out["difference_mm_mean"] = difference_mm.empty() ? 0.0 : difference_mm.Mean();
  out["difference_mm_p95"] = difference_mm.empty() ? 0.0 : difference_mm.Percentile(95);
  out["difference_mm_max"] = difference_mm.empty() ? 0.0 : difference_mm.Max();
  return out;
}

}  // namespace headcast::bench
