// The offline tracking pass.
#include "common/tracking/offline_tracker.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/options.h"
#include "common/core/rotation.h"
#include "common/core/timer.h"
#include "common/tracking/appearance_fit.h"
#include "common/tracking/expression_fit.h"

namespace headcast {
bool IsLiveCameraSource(const std::string& input) {
  return input.rfind("/dev/", 0) == 0 || input.find(":/dev/") != std::string::npos;
}

namespace {

// The full frame's camera: calibrated, given, the source's, or from the field of view.
PinholeCamera FirstFrameCamera(const OfflineTrackOptions& o, const std::optional<PinholeCamera>& calibrated,
                               const CapturedFrame& c) {
  PinholeCamera camera = calibrated     ? *calibrated
                         : o.intrinsics ? *o.intrinsics
                         : c.camera     ? *c.camera
                                        : PinholeCamera::FromFovY(c.bgr.cols, c.bgr.rows, o.fov_deg);
  if (o.intrinsics && !calibrated) {
    camera.width = c.bgr.cols;
    camera.height = c.bgr.rows;
  }
  return camera;
}

// Identity calibration (RGB, recorded input): a first pass collects
// landmarks; key frames spread evenly over the sorted yaws (the extremes
// included, at most a quarter of the frames) give shape and focal length.
struct IdentityCalibration {
  Eigen::VectorXd shape;
  PinholeCamera camera;
  nlohmann::json report;
};

// The face in every readable frame of the input (as the main pass counts them),
// unfiltered, then the whole track smoothed forwards and backwards.
std::vector<FaceObservation> ObserveFacesTwoSided(const OfflineTrackOptions& o, const FrameSourceFactory& open) {
  FaceTrackerOptions unfiltered = o.tracker.face;
  unfiltered.filter = false;
  FaceTracker faces(unfiltered);
  auto source = open();
  std::vector<FaceObservation> track;
  std::vector<double> times;
  while (o.max_frames <= 0 || static_cast<int>(track.size()) < o.max_frames) {
    CapturedFrame c;
    std::string why;
    const ReadStatus st = source->Read(&c, &why);
    if (st == ReadStatus::kEnd) break;
    if (st == ReadStatus::kSkipped) continue;
    // Times must increase for the filter; a source without them counts frames.
    const double t = c.capture_time_s > (times.empty() ? -1e300 : times.back())
                         ? c.capture_time_s
                         : (times.empty() ? 0.0 : times.back() + 1.0 / std::max(1.0, source->fps()));
    track.push_back(faces.Track(c.bgr, t));
    times.push_back(t);
  }
  SmoothTrackTwoSided(&track, times, o.tracker.face.filter_min_cutoff, o.tracker.face.filter_beta);
  spdlog::info("faces observed in {} frames, smoothed forwards and backwards", track.size());
  return track;
}

// The observation of readable frame `index` from the first pass; the input must read alike twice.
const FaceObservation& Observed(const std::vector<FaceObservation>& observed, int index, const std::string& input) {
  if (index < 0 || index >= static_cast<int>(observed.size()))
    throw std::runtime_error(input + ": the input gave more frames on a second reading than on the first");
  return observed[static_cast<size_t>(index)];
}

IdentityCalibration CalibrateOverKeyFrames(const HeadModel& model, const OfflineTrackOptions& o,
                                           const FrameSourceFactory& open,
                                           const std::vector<FaceObservation>* observed) {
  auto source = open();
  FrameTracker first(model, o.tracker);
  if (o.identity.size() > 0) first.SetIdentity(o.identity);
  std::vector<std::pair<double, Landmarks2d>> seen;  // (yaw, landmarks)
  std::optional<PinholeCamera> initial;
  for (int n = 0; o.max_frames <= 0 || n < o.max_frames;) {
    CapturedFrame c;
    std::string why;
    const ReadStatus st = source->Read(&c, &why);
    if (st == ReadStatus::kEnd) break;
    if (st == ReadStatus::kSkipped) continue;
    const int index = n++;
    if (!initial) initial = FirstFrameCamera(o, std::nullopt, c);
    FrameParams p;
    const TrackedFrame t =
        observed ? first.TrackObserved(c.bgr, cv::Mat(), Observed(*observed, index, o.input), *initial, &p)
                 : first.Track(c.bgr, cv::Mat(), c.capture_time_s, *initial, &p);
    if (t.fitted)
      seen.emplace_back(ViewRotation(AxisAngleToMatrix(p.cam_rotation.cast<double>())).y(), t.face.landmarks);
  }
  if (seen.size() < 3) throw std::runtime_error(o.input + ": too few frames with a face to calibrate the identity");
  std::sort(seen.begin(), seen.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  const int keys = std::max(3, std::min(o.calibration_frames, static_cast<int>(seen.size()) / 4));
  std::vector<Landmarks2d> key_frames;
  for (int k = 0; k < keys; ++k)
    key_frames.push_back(seen[static_cast<size_t>(std::lround(k * (seen.size() - 1.0) / (keys - 1)))].second);
  HeadFitter fitter(model, o.tracker.fit);
  if (o.identity.size() > 0) fitter.SetIdentity(o.identity);
  const HeadFitter::Calibration cal = fitter.CalibrateIdentity(key_frames, *initial, nullptr, o.intrinsics.has_value());
  if (!cal.ok) throw std::runtime_error(o.input + ": identity calibration failed");
  spdlog::info("identity calibrated over {} key frames: focal {:.1f} px, rms {:.2f} px", cal.frames, cal.camera.fx,
               cal.rms_px);
  return {cal.shape, cal.camera,
          nlohmann::json{{"key_frames", cal.frames},
                         {"yaw_range_deg", {seen.front().first * 180 / M_PI, seen.back().first * 180 / M_PI}},
                         {"focal_px", cal.camera.fx},
                         {"focal_px_from_fov", initial->fx},
                         {"rms_px", cal.rms_px}}};
}

// Landmark error and jitter of the fitted frames. Jitter: the second
// difference of landmark positions over consecutive fitted frames (mean over
// the 68, over the eye distance): what shakes.
class FitQuality {
 public:
  void Add(int frame, const Landmarks2d& fitted, const Landmarks2d& detected) {
    error_iod_.Add(LandmarkErrorIod(fitted, detected));
    if (last_frame_ != frame - 1) {  // a gap: start the history again
      fitted_.clear();
      detected_.clear();
    }
    last_frame_ = frame;
    fitted_.push_back(fitted);
    detected_.push_back(detected);
    if (fitted_.size() > 3) {
      fitted_.erase(fitted_.begin());
      detected_.erase(detected_.begin());
    }
    if (fitted_.size() == 3) {
      jitter_fitted_.Add(LandmarkJitterIod(fitted_[0], fitted_[1], fitted_[2]));
      jitter_detected_.Add(LandmarkJitterIod(detected_[0], detected_[1], detected_[2]));
    }
  }
  void Report(nlohmann::json* r) const {
    (*r)["landmark_error_iod_mean"] = error_iod_.empty() ? -1.0 : error_iod_.Mean();
    (*r)["jitter_iod_median"] = jitter_fitted_.empty() ? -1.0 : jitter_fitted_.Median();
    (*r)["jitter_iod_median_raw_landmarks"] = jitter_detected_.empty() ? -1.0 : jitter_detected_.Median();
  }

 private:
  SampleStats error_iod_, jitter_fitted_, jitter_detected_;
  std::vector<Landmarks2d> fitted_, detected_;
  int last_frame_ = -2;
};

// Detected landmarks and irises filled (orange, red); the model's landmarks and pupils as rings (green, cyan).
void DrawOverlay(const cv::Mat& frame, const TrackedFrame& t, const Landmarks2d* model_landmarks,
                 const std::array<Eigen::Vector2d, 2>* model_pupils, cv::Mat* shown) {
  *shown = frame.clone();
  auto dot = [&](const Eigen::Vector2d& p, const cv::Scalar& colour, int thickness) {
    cv::circle(*shown, cv::Point2d(p.x(), p.y()), 2, colour, thickness, cv::LINE_AA);
  };
  if (model_landmarks) {
    for (int l = 0; l < kNumLandmarks; ++l) {
      dot(t.face.raw[l], cv::Scalar(0, 200, 255), cv::FILLED);
      dot((*model_landmarks)[l], cv::Scalar(80, 255, 80), 1);
    }
  }
  for (const IrisObservation* iris : {&t.face.irises.left, &t.face.irises.right})
    if (iris->found) dot(iris->center, cv::Scalar(0, 0, 255), cv::FILLED);
  if (model_pupils)
    for (const Eigen::Vector2d& p : *model_pupils) dot(p, cv::Scalar(255, 255, 0), 1);
  cv::putText(*shown, std::string(FaceStatusName(t.face.status)) + (t.fitted ? " fitted" : ""), {8, 20},
              cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
}

// RGB-D frames fitted while the identity was still free: written once it is
// frozen, fitted again with it.
struct HeldFrame {
  Landmarks2d landmarks;
  cv::Mat depth;
  FrameParams params;  // sequence and time
};

void RefitHeld(FrameTracker& tracker, const PinholeCamera& camera, std::vector<HeldFrame>* held,
               std::vector<FrameParams>* out) {
  spdlog::info("identity frozen from {} RGB-D frames", held->size());
  RgbdFitResult previous;
  for (const HeldFrame& h : *held) {
    const RgbdFitResult r = tracker.RefitRgbd(h.landmarks, h.depth, camera, &previous);
    if (!r.ok) continue;
    FrameParams f = h.params;
    ApplyRgbdFit(r, &f);
    out->push_back(f);
    previous = r;
  }
  held->clear();
}

// Holds every fitted frame's head placement to its appearance over the clip
// (PhotometricAnchor): per round, the points' reference grey levels from the
// current fits, then each frame aligned to them and fitted again to its
// landmarks with the aligned points holding the pose. Reads the input again
// twice a round. Returns the report's entry; *reference: the last round's references.
nlohmann::json AnchorTrack(const HeadModel& model, const OfflineTrackOptions& o, const FrameSourceFactory& open,
                           const Eigen::VectorXd& identity, const PinholeCamera& camera,
                           const std::map<uint64_t, FaceObservation>& faces,
                           const std::map<uint64_t, std::vector<int>>& mask_tops, std::vector<FrameParams>* frames,
                           std::optional<AnchorReference>* reference) {
  PhotometricAnchor anchor(model, identity, o.anchor);
  std::optional<OutlineHold> outline;
  if (o.outline.enabled()) outline.emplace(model, identity, o.outline);
  auto tops = [&](const FrameParams& f) -> const std::vector<int>* {
    const auto it = mask_tops.find(f.sequence);
    return it == mask_tops.end() ? nullptr : &it->second;
  };
  HeadFitterOptions fit_options = o.tracker.fit;
  fit_options.rigid_flow_weight = o.anchor.weight;
  HeadFitter fitter(model, fit_options);
  fitter.SetIdentity(identity);
  std::map<uint64_t, FrameParams*> by_sequence;
  for (FrameParams& f : *frames)
    if (faces.count(f.sequence)) by_sequence[f.sequence] = &f;
  // Each fitted frame's grey image, read again in order; `use` gets it with its params, landmarks and eye distance.
  auto each_frame = [&](const std::function<void(const cv::Mat&, FrameParams*, const FaceObservation&, double)>& use) {
    std::unique_ptr<FrameSource> source = open();
    int index = 0;
    for (;;) {
      if (o.max_frames > 0 && index >= o.max_frames) break;
      CapturedFrame captured;
      std::string problem;
      const ReadStatus status = source->Read(&captured, &problem);
      if (status == ReadStatus::kEnd) break;
      if (status == ReadStatus::kSkipped) continue;
      const auto it = by_sequence.find(static_cast<uint64_t>(index++));
      if (it == by_sequence.end()) continue;
      const FaceObservation& face = faces.at(it->first);
      const double iod = (face.landmarks[45] - face.landmarks[36]).norm();
      use(AnchorGray(captured.bgr, o.anchor.blur_iod * iod), it->second, face, iod);
    }
  };
  nlohmann::json rounds = nlohmann::json::array();
  for (int round = 0; round < o.anchor.rounds; ++round) {
    each_frame([&](const cv::Mat& gray, FrameParams* f, const FaceObservation&, double) {
      anchor.Observe(gray, *f, camera);
      if (outline && tops(*f)) outline->Observe(*tops(*f), *f, camera);
    });
    const int referenced = anchor.Reference();
    const bool outlined = outline && outline->Reference();
    SampleStats shift, before, after, held_columns;
    int refitted = 0, rejected = 0;
    each_frame([&](const cv::Mat& gray, FrameParams* f, const FaceObservation& face, double iod) {
      AnchorAlignment a;
      RigidObservations held;
      if (outlined && tops(*f)) held = outline->Observations(*tops(*f), *f, camera);
      if (outlined) held_columns.Add(static_cast<double>(held.head.size()));
      const bool again = anchor.Refit(gray, face.landmarks, &face.irises, iod, camera, fitter, f, &a, &held);
      if (a.ok) {
        shift.Add(a.shift_px);
        before.Add(a.rms_before);
        after.Add(a.rms_after);
      }
      ++(again ? refitted : rejected);
    });
    spdlog::info("photometric anchor, round {}: {} points referenced, {} frames fitted again, {} kept, shift {:.2f} px",
                 round + 1, referenced, refitted, rejected, shift.empty() ? 0.0 : shift.Median());
    rounds.push_back({{"points_referenced", referenced},
                      {"frames_refitted", refitted},
                      {"frames_kept", rejected},
                      {"shift_px_median", shift.empty() ? 0.0 : shift.Median()},
                      {"shift_px_p95", shift.empty() ? 0.0 : shift.Percentile(95)},
                      {"grey_rms_before_median", before.empty() ? 0.0 : before.Median()},
                      {"grey_rms_after_median", after.empty() ? 0.0 : after.Median()}});
    if (outline) {
      // Metres to millimetres; NaN (too few frames to tell) as null.
      const auto mm = [](double metres) {
        return std::isnan(metres) ? nlohmann::json(nullptr) : nlohmann::json(1e3 * metres);
      };
      rounds.back()["outline"] = {{"held", outlined},
                                  {"hair_thickness_mm", mm(outline->observed_median())},
                                  {"hair_thickness_spread_mm", mm(outline->observed_spread())},
                                  {"columns_held_mean", held_columns.empty() ? 0.0 : held_columns.Mean()}};
    }
  }
  nlohmann::json exported;  // null: no point referenced
  if (const AnchorReference last = anchor.Exported(); last.referenced() > 0) {
    *reference = last;
    exported = last.ToJson();
  }
  return {{"options", o.anchor.ToJson()},
          {"outline", o.outline.enabled() ? o.outline.ToJson() : nlohmann::json(nullptr)},
          {"points", anchor.num_points()},
          {"rounds", rounds},
          {"reference", exported},
          {"what",
           "the head's placement held to the grey levels of the face above the nose's base (forehead, brows, "
           "nose, temples) over the clip, then every frame fitted again; shift: how far the alignment moved those "
           "points; frames_kept: frames whose alignment failed or moved them beyond max_shift_iod, left as first "
           "fitted"}};
}

}  // namespace

void OfflineTrackOptions::Check() const {
  source.Check();
  mask.Check();
  tracker.Check();
  OptionsCheck c("OfflineTrackOptions");
  c.NotEmpty("input", input).NonNegative("max_frames", max_frames).InRange("fov_deg", fov_deg, 1, 179);
  c.InRange("calibration_frames", calibration_frames, 3, 10000);
  c.That(!(calibrate && IsLiveCameraSource(input)),
         "calibrate needs a recorded input (a live camera cannot be read twice)");
  c.That(!(two_sided_filter && IsLiveCameraSource(input)),
         "two_sided_filter needs a recorded input (a live camera cannot be read twice)");
  c.That(!(calibrate && identity.size() > 0), "calibrate and a given identity exclude each other");
  anchor.Check();
  c.That(!(anchor.enabled() && IsLiveCameraSource(input)),
         "the photometric anchor needs a recorded input (a live camera cannot be read again)");
  c.That(!(anchor.enabled() && anchor_reference), "the clip's own anchor and given references exclude each other");
  c.That(!anchor_reference || identity.size() > 0, "given anchor references need the identity they were made for");
  outline.Check();
  c.That(!outline.enabled() || (anchor.enabled() && masks),
         "holding the hair's outline needs the photometric anchor (its refits) and masks");
  if (intrinsics) c.That(intrinsics->fx > 0 && intrinsics->fy > 0, "intrinsics need positive focal lengths");
  c.That(identity.size() == 0 || identity.allFinite(), "identity must be finite");
  c.ThrowIfErrors();
}

void SetLandmarkFilter(const std::string& mode, OfflineTrackOptions* o) {
  if (std::find(kLandmarkFilterModes.begin(), kLandmarkFilterModes.end(), mode) == kLandmarkFilterModes.end())
    throw std::invalid_argument("landmark filter " + mode + ": causal, off or two-sided");
  o->tracker.face.filter = mode == "causal";
  o->two_sided_filter = mode == "two-sided";
}

OfflineTrack TrackVideo(const HeadModel& model, const OfflineTrackOptions& options,
                        const OfflineFrameObserver& observer) {
  return TrackFrames(
      model, options, [&] { return OpenFrameSource(options.input, options.source); }, observer);
}

OfflineTrack TrackFrames(const HeadModel& model, const OfflineTrackOptions& o, const FrameSourceFactory& open,
                         const OfflineFrameObserver& observer) {
  o.Check();
  if (o.identity.size() > 0 && o.identity.size() != model.num_shape())
    throw std::invalid_argument("the given identity has " + std::to_string(o.identity.size()) +
                                " shape values; the head model has " + std::to_string(model.num_shape()));
  FrameTracker tracker(model, o.tracker);
  tracker.SetIdentity(o.identity.size() > 0 ? o.identity : Eigen::VectorXd::Zero(model.num_shape()),
                      o.identity.size() > 0);
  if (o.anchor_reference) tracker.SetAnchor(*o.anchor_reference);
  std::vector<FaceObservation> observed;
  if (o.two_sided_filter) observed = ObserveFacesTwoSided(o, open);
  std::optional<IdentityCalibration> calibration;
  if (o.calibrate) {
    calibration = CalibrateOverKeyFrames(model, o, open, o.two_sided_filter ? &observed : nullptr);
    tracker.SetIdentity(calibration->shape, false);  // RGB only: RGB-D frames still calibrate their own
  }
  std::unique_ptr<FrameSource> source = open();
  spdlog::info("source: {}", source->Describe());
  OfflineTrack out;
  out.fps = source->fps();
  std::unique_ptr<VideoWriter> overlay;
  if (!o.overlay.empty()) overlay = std::make_unique<VideoWriter>(o.overlay, out.fps);
  PinholeCamera camera;
  std::vector<AppearanceSample> appearance_samples;
  std::vector<HeldFrame> held;
  FitQuality quality;
  SampleStats ms, accuracy_mm;
  int frames = 0, fitted = 0, unreadable = 0, with_depth = 0, contour_rejected = 0, gaze_frames = 0;
  int anchored_frames = 0;  // given references (anchor_reference)
  SampleStats anchor_ms;
  std::map<std::string, int> statuses;
  int recovered = 0;  // frames where the followed box slipped and the detector found the face again
  // Frames whose region's landmarks disagreed with the flow, and were carried by it.
  std::array<int, kNumRepairRegions> disputes{}, repairs{};
  std::map<uint64_t, FaceObservation> faces;       // what the photometric anchor fits again (RGB frames)
  std::map<uint64_t, std::vector<int>> mask_tops;  // with the outline held: each of them's mask's top row per column
  int disputed_frames = 0, repaired_frames = 0;
  Stopwatch watch;
  for (;;) {
    if (o.max_frames > 0 && frames >= o.max_frames) break;
    CapturedFrame captured;
    std::string problem;
    const ReadStatus status = source->Read(&captured, &problem);
    if (status == ReadStatus::kEnd) {
      if (!problem.empty()) spdlog::warn("{}", problem);
      break;
    }
    if (status == ReadStatus::kSkipped) {
      ++unreadable;  // a corrupt frame is a per-frame status; the run goes on
      spdlog::warn("{}", problem);
      continue;
    }
    const cv::Mat& frame = captured.bgr;
    const int index = frames++;
    with_depth += captured.has_depth();
    if (index == 0)
      camera = FirstFrameCamera(o, calibration ? std::optional(calibration->camera) : std::nullopt, captured);
    if (index > 0 && index % 100 == 0) {
      const double elapsed = watch.ElapsedSeconds();
      const int64_t total = o.max_frames > 0 && source->frame_count() > 0
                                ? std::min<int64_t>(o.max_frames, source->frame_count())
                            : o.max_frames > 0 ? o.max_frames
                                               : source->frame_count();
      if (total > index)
        spdlog::info("tracking: {} of {} frames, {} fitted; {}, ETA {}", index, total, fitted, HumanDuration(elapsed),
                     HumanDuration(elapsed * (total - index) / index));
      else
        spdlog::info("tracking: {} frames, {} fitted; {}", index, fitted, HumanDuration(elapsed));
    }
    FrameParams params;
    const TrackedFrame t = o.two_sided_filter
                               ? tracker.TrackObserved(frame, captured.depth_m, Observed(observed, index, o.input),
                                                       camera, &params, captured.depth_on_demand.get())
                               : tracker.Track(frame, captured.depth_m, captured.capture_time_s, camera, &params,
                                               captured.depth_on_demand.get());
    ms.Add(t.landmarks_ms + t.fit_ms);
    if (!t.fitted && !t.problem.empty()) spdlog::debug("frame {}: {}", index, t.problem);
    ++statuses[t.face.status == FaceStatus::kNoFace ? "no_face" : t.fitted ? "fitted" : "fit_failed"];
    recovered += t.face.recovered;
    disputed_frames += t.face.disputed != 0;
    repaired_frames += t.face.repaired != 0;
    for (int r = 0; r < kNumRepairRegions; ++r) {
      disputes[r] += (t.face.disputed >> r) & 1;
      repairs[r] += (t.face.repaired >> r) & 1;
    }
    OfflineFrame seen{index, &frame, t.fitted, cv::Mat()};
    std::array<Eigen::Vector2d, 2> model_pupils;
    bool have_pupils = false;
    if (t.fitted) {
      ++fitted;
      gaze_frames += t.face.irises.left.found || t.face.irises.right.found;
      anchored_frames += t.anchored;
      if (o.anchor_reference && !t.with_depth) anchor_ms.Add(t.anchor_ms);
      params.sequence = static_cast<uint64_t>(index);
      params.capture_time_s = captured.capture_time_s;
      params.confidence = 1.f;
      if (t.with_depth) {
        accuracy_mm.Add(1e3 * t.rgbd_accuracy_m);
        contour_rejected += t.contour_rejected;
      }
      if (t.identity_frame) {
        held.push_back({t.face.landmarks, t.depth_m.clone(), params});
      } else {
        out.frames.push_back(params);
        if (o.anchor.enabled() && !t.with_depth) faces[params.sequence] = t.face;
      }
      if (t.identity_frozen_now) RefitHeld(tracker, camera, &held, &out.frames);
      // Every 15th fitted frame, up to 8, for the texture and light fit.
      const bool sample = o.fit_appearance && fitted % 15 == 1 && appearance_samples.size() < 8;
      if (sample || o.masks) {
        seen.mask = HeadMask(frame, t.face.raw, o.mask);
        if (sample) appearance_samples.push_back({frame.clone(), seen.mask, params, camera});
        if (faces.count(params.sequence) && o.outline.enabled()) mask_tops[params.sequence] = MaskTopRows(seen.mask);
      }
      have_pupils = tracker.fitter().ProjectPupils(params, camera, &model_pupils[0], &model_pupils[1]);
      quality.Add(index, t.model_landmarks, t.face.raw);
    }
    if (observer) observer(seen);
    if (overlay) {
      cv::Mat shown;
      DrawOverlay(frame, t, t.fitted ? &t.model_landmarks : nullptr, t.fitted && have_pupils ? &model_pupils : nullptr,
                  &shown);
      overlay->Write(shown);
    }
  }
  if (tracker.FreezeRgbdIdentity()) RefitHeld(tracker, camera, &held, &out.frames);
  if (frames == 0) throw std::runtime_error(o.input + ": no readable frames (corrupt or empty?)");
  std::sort(out.frames.begin(), out.frames.end(),
            [](const FrameParams& a, const FrameParams& b) { return a.sequence < b.sequence; });
  out.frames_read = frames;
  nlohmann::json anchored;
  if (o.anchor.enabled() && !faces.empty())
    anchored =
        AnchorTrack(model, o, open, tracker.identity(), camera, faces, mask_tops, &out.frames, &out.anchor_reference);
  SubjectParams& subject = out.subject;
  subject.shape = tracker.identity().cast<float>();
  subject.texture = Eigen::VectorXf::Zero(model.num_texture());
  subject.intrinsics = camera;
  AppearanceFit appearance;
  if (!appearance_samples.empty()) {
    appearance = FitAppearance(model, tracker.identity(), appearance_samples);
    if (!appearance.ok) spdlog::warn("texture/light fit: {}", appearance.problem);
  }
  if (appearance.ok) {
    subject.texture.head(appearance.texture.size()) = appearance.texture.cast<float>();
    subject.light = appearance.light;
  }
  nlohmann::json& report = out.report;
  report = {{"input", o.input},
            {"head_model", model.data().name},
            {"frames", frames},
            {"fitted_frames", fitted},
            {"unreadable_frames", unreadable},
            {"statuses", statuses},
            {"tracking_recovered_frames", recovered},
            {"ms_per_frame_median", ms.Median()},
            {"ms_per_frame_p95", ms.Percentile(95)},
            {"frames_with_depth", with_depth},
            {"identity", !o.identity_source.empty() ? o.identity_source
                         : o.identity.size() > 0    ? "given"
                         : o.calibrate              ? "calibrated over key frames (shape, focal)"
                         : with_depth > 0           ? "RGB-D: median shape of the first fitted frames"
                                                    : "neutral (beta = 0)"},
            {"camera", camera.ToString()}};
  quality.Report(&report);
  if (o.tracker.face.repair.enabled) {
    nlohmann::json& r = report["landmark_checks"];
    r["disputed_frames"] = disputed_frames;
    r["repaired_frames"] = repaired_frames;
    for (int i = 0; i < kNumRepairRegions; ++i) {
      const char* name = LandmarkRegionName(static_cast<LandmarkRegion>(i));
      r["disputed"][name] = disputes[i];
      r["repaired"][name] = repairs[i];
    }
    r["what_it_means"] =
        "frames where the shape predictor's points of a region disagreed with the flow from the previous frame "
        "(disputed), and where the carried points were used instead (repaired, with --landmark-repair); "
        "common/tracking/landmark_repair.h";
  }
  if (o.tracker.face.locate_irises)
    report["gaze"] = {{"fitted_frames_with_an_iris", gaze_frames},
                      {"how", "irises located in the landmarks' eye regions; the eye joints fitted to them"}};
  if (!accuracy_mm.empty()) {
    report["rgbd_accuracy_mm_median"] = accuracy_mm.Median();
    report["rgbd_accuracy_mm_p95"] = accuracy_mm.Percentile(95);
    report["rgbd_contour_landmarks_rejected"] = contour_rejected;
    report["what_rgbd_accuracy_means"] = "sqrt of the mean squared point-to-mesh distance after the fit (METHOD §3)";
  }
  if (calibration) report["calibration"] = calibration->report;
  report["expression_fit"] = ExpressionFitSettings::Of(o.tracker.fit).ToJson();
  if (!anchored.is_null()) report["photometric_anchor"] = anchored;
  if (o.anchor_reference)
    report["photometric_anchor"] = {
        {"options", o.anchor_reference->options.ToJson()},
        {"points_referenced", o.anchor_reference->referenced()},
        {"frames_anchored", anchored_frames},
        {"anchor_ms_median", anchor_ms.empty() ? 0.0 : anchor_ms.Median()},
        {"what",
         "each frame's placement held to given references (an avatar's) as it was fitted, as the live sender "
         "does; frames_anchored: fitted again with the aligned points (the others keep their landmark fit)"}};
  if (appearance.ok)
    report["appearance"] = {{"frames", appearance_samples.size()},
                            {"pixels", appearance.pixels},
                            {"rms", appearance.rms},
                            {"what", "texture tau and SH light lambda by the masked photometric fit; rms in 0..1"}};
  return out;
}

}  // namespace headcast
