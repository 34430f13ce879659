// Dataset preparation and loading.
#include "training/dataset.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "common/avatar/matte.h"
#include "common/core/check.h"
#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/options.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/raster/rasterizer.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/offline_tracker.h"
#include "common/tracking/pose_smoothing.h"
#include "proto/recording.h"
#include "training/interpolation.h"
#include "training/run_report.h"

namespace headcast {
namespace fs = std::filesystem;

void PrepOptions::Check() const {
  OptionsCheck c("PrepOptions");
  c.That(!input.empty(), "input is required").That(!out_dir.empty(), "out_dir is required");
  c.That(!resolutions.empty(), "at least one resolution");
  for (int r : resolutions) c.That(r == 128 || r == 256 || r == 512, "resolutions are 128, 256 or 512");
  c.InRange("test_frames", test_frames, 0, 1000000).NonNegative("max_frames", max_frames);
  c.InRange("test_share", test_share, 0.0, 0.9);
  c.InRange("interpolate", interpolate, 0, 8)
      .InRange("crop_scale", crop_scale, 1.0, 6.0)
      .InRange("mask_margin", mask_margin, 0.0, 0.5)
      .InRange("side_margin", side_margin, 0.0, mask_margin)
      .InRange("mask_working_size", mask_working_size, 32, 2048)
      .InRange("steady_masks", steady_masks, 0, kMaxSteadyMasks)
      .NonNegative("shape_prior", shape_prior)
      .NonNegative("calibration_mean_expression", calibration_mean_expression)
      .NonNegative("rigid_flow_weight", rigid_flow_weight)
      .InRange("predictor_views", predictor_views, 1, kMaxPredictorViews)
      .That(std::find(kPredictorViewsPoints.begin(), kPredictorViewsPoints.end(), predictor_views_points) !=
                kPredictorViewsPoints.end(),
            "predictor_views_points is all, no-eyes or outline")
      .Positive("landmark_filter_hz", landmark_filter_hz)
      .NonNegative("landmark_filter_beta", landmark_filter_beta)
      .InRange("pose_smoothing", pose_smoothing, 0.0, 100.0)
      .InRange("photometric_anchor", photometric_anchor, 0.0, 100.0)
      .InRange("outline_hold", outline_hold, 0.0, 100.0)
      .That(std::find(kLandmarkFilterModes.begin(), kLandmarkFilterModes.end(), landmark_filter) !=
                kLandmarkFilterModes.end(),
            "landmark_filter is causal, off or two-sided");
  expression_fit.CheckInto(&c);
  c.That(!(calibrate && !identity_from.empty()), "calibrate and identity_from exclude each other");
  c.That(outline_hold == 0 || photometric_anchor > 0, "outline_hold needs the photometric anchor (its refits)");
  c.ThrowIfErrors();
}

namespace {

double Percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(std::clamp(q, 0.0, 1.0) * (v.size() - 1))];
}

// Points that move with the skull (SteadyMask's), in the camera frame: every
// few vertices of the subject's head under the frame's placement and neck,
// without expression, jaw or eyes.
RasterVertices SkullPoints(const HeadModel& model, const HeadIdentity& identity, const FrameParams& params) {
  constexpr int kPoints = 400;
  PoseVector pose = params.HeadPose();
  pose.tail(kNumPoseParams - 3 * kJawJoint).setZero();  // the jaw and the eyes
  HeadModelOutput rigid;
  model.Forward(identity, Eigen::VectorXd::Zero(model.num_expression()), pose, &rigid);
  RasterVertices in_camera;
  TransformToCamera(rigid.vertices, params.CamFromHead(), &in_camera);
  const int stride = std::max(1, static_cast<int>(in_camera.rows()) / kPoints);
  RasterVertices every(static_cast<int>((in_camera.rows() + stride - 1) / stride), 3);
  for (int i = 0, k = 0; i < in_camera.rows(); i += stride, ++k) every.row(k) = in_camera.row(i);
  return every;
}

// `points` (camera frame) in `camera`'s pixels, 2 x P.
Eigen::Matrix2Xd ProjectPoints(const RasterVertices& points, const PinholeCamera& camera) {
  Eigen::Matrix2Xd pixels(2, points.rows());
  for (int i = 0; i < points.rows(); ++i) pixels.col(i) = camera.Project(points.row(i).transpose().cast<double>());
  return pixels;
}

}  // namespace

namespace {

// 1. The offline tracking pass, in-process: every fitted frame and its head
// mask are kept as lossless PNGs (full_frames/, full_masks/) for the crops,
// whose box is known only once every frame is fitted; params.hcrec and
// track_report.json (written last: a finished pass) beside them.
struct TrackedInput {
  std::vector<FrameParams> fitted;
  RecordingInfo info;
  nlohmann::json report;
};

TrackedInput TrackInput(const PrepOptions& o, const HeadModel& model) {
  const fs::path dir = o.out_dir;
  const fs::path frames_dir = dir / "full_frames", masks_dir = dir / "full_masks";
  TrackedInput t;
  if (o.resume && fs::exists(dir / "track_report.json") && fs::exists(frames_dir) && fs::exists(masks_dir)) {
    spdlog::info("prep: reusing the finished tracking pass in {}", o.out_dir);
    t.fitted = ReadRecording((dir / "params.hcrec").string(), &t.info);
    try {
      t.report = nlohmann::json::parse(std::ifstream(dir / "track_report.json"));
    } catch (const std::exception& e) {
      throw std::runtime_error((dir / "track_report.json").string() + ": " + e.what() + " (remove it to track again)");
    }
    return t;
  }
  fs::remove(dir / "track_report.json");
  fs::remove_all(frames_dir);
  fs::remove_all(masks_dir);
  fs::create_directories(frames_dir);
  fs::create_directories(masks_dir);
  OfflineTrackOptions track;
  track.input = o.input;
  track.source = o.source;
  track.max_frames = o.max_frames;
  track.calibrate = o.calibrate;
  track.tracker.fit.shape_prior = o.shape_prior;
  track.tracker.fit.calibration_mean_expression = o.calibration_mean_expression;
  track.tracker.fit.rigid_flow_weight = o.rigid_flow_weight;
  o.expression_fit.ApplyTo(&track.tracker.fit);
  track.tracker.face.locate_irises = o.gaze;
  track.tracker.face.repair.repair = o.landmark_repair;
  track.tracker.face.predictor_views = o.predictor_views;
  track.tracker.face.predictor_views_points = o.predictor_views_points;
  track.tracker.face.filter_min_cutoff = o.landmark_filter_hz;
  track.tracker.face.filter_beta = o.landmark_filter_beta;
  SetLandmarkFilter(o.landmark_filter, &track);
  if (!o.intrinsics.empty()) track.intrinsics = ParseIntrinsics(o.intrinsics, "intrinsics");
  if (!o.identity_from.empty()) {
    track.identity = ReadTrackingIdentity(o.identity_from, model);
    track.identity_source = o.identity_from;
  }
  track.anchor.weight = o.photometric_anchor;
  track.outline.weight = o.outline_hold;
  if (IsLiveCameraSource(o.input) && o.photometric_anchor > 0) {
    spdlog::info("prep: no photometric anchor on a live camera (it cannot be read again)");
    track.anchor.weight = 0;
    track.outline.weight = 0;
  }
  track.masks = true;
  track.mask.working_size = o.mask_working_size;
  track.overlay = (dir / "preview.mp4").string();
  spdlog::info("prep: tracking {}", o.input);
  const OfflineTrack tracked = TrackVideo(model, track, [&](const OfflineFrame& f) {
    if (!f.fitted) return;
    WriteImage((frames_dir / FrameFileName(f.index)).string(), *f.bgr);
    WriteImage((masks_dir / FrameFileName(f.index)).string(), f.mask);
  });
  t.fitted = tracked.frames;
  SmoothHeadPlacement(o.pose_smoothing, &t.fitted);
  t.info = MakeRecordingInfo(model, tracked.fps, tracked.subject, "headcast-train prep " + o.input);
  t.report = tracked.report;
  WriteRecording((dir / "params.hcrec").string(), t.info, t.fitted);
  std::ofstream(dir / "track_report.json") << t.report.dump(2) << "\n";
  return t;
}

}  // namespace

nlohmann::json PrepareDataset(const PrepOptions& o) {
  o.Check();
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  fs::create_directories(o.out_dir);
  const fs::path dir = o.out_dir;
  const fs::path full_frames = dir / "full_frames", full_masks = dir / "full_masks";
  const TrackedInput tracked = TrackInput(o, model);
  const std::vector<FrameParams>& fitted = tracked.fitted;
  const RecordingInfo& info = tracked.info;
  const nlohmann::json& track_report = tracked.report;
  if (fitted.empty()) throw std::runtime_error(o.input + ": no face was found and fitted in any frame");
  const int min_train = 8;
  // A short video keeps most of its frames for training (test_share).
  const int test_frames =
      o.test_share > 0 ? std::min(o.test_frames, static_cast<int>(fitted.size() * o.test_share)) : o.test_frames;
  if (static_cast<int>(fitted.size()) < test_frames + min_train)
    throw std::runtime_error(o.input + ": " + std::to_string(fitted.size()) + " fitted frames; the split needs " +
                             std::to_string(test_frames) + " test frames and at least " + std::to_string(min_train) +
                             " training frames (lower --test-frames?)");

  // 2. One crop box for the whole video, so the camera stays one pinhole:
  //    the landmarks' median centre (raised toward the hair by 0.3 of the extent) and their 95th
  //    percentile extent, times crop_scale.
  HeadFitter fitter(model);
  fitter.SetIdentity(info.subject.shape.cast<double>());
  const HeadIdentity identity = model.MakeIdentity(info.subject.shape.cast<double>());
  const PinholeCamera& camera = info.subject.intrinsics;
  std::vector<double> cx, cy, extent;
  for (const FrameParams& f : fitted) {
    const Landmarks2d l = fitter.Project(f, camera);
    Eigen::Vector2d lo = l[0], hi = l[0];
    for (const auto& p : l) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    cx.push_back(0.5 * (lo.x() + hi.x()));
    cy.push_back(0.5 * (lo.y() + hi.y()));
    extent.push_back(std::max(hi.x() - lo.x(), hi.y() - lo.y()));
  }
  const double size = Percentile(extent, 0.95);
  // Close-ups: no bigger than the frame, and inside it (no black borders to learn).
  const double side = std::min({o.crop_scale * size, 1.0 * camera.width, 1.0 * camera.height});
  const double x0 = std::clamp(Percentile(cx, 0.5) - side / 2, 0.0, camera.width - side);
  const double y0 = std::clamp(Percentile(cy, 0.5) - 0.3 * size - side / 2, 0.0, camera.height - side);

  // 3. Crops and masks at each resolution, named by source frame number: the
  //    images written as they are cut, GrabCut's masks kept with the head's
  //    place in each crop, then steadied over time (SteadyMask) and cut by the
  //    fit's rules.
  for (int r : o.resolutions) {
    fs::create_directories(dir / std::to_string(r) / "images");
    fs::create_directories(dir / std::to_string(r) / "masks");
  }
  std::vector<int64_t> numbers;
  std::map<int, std::vector<cv::Mat>> grabcut;               // per resolution, per fitted frame
  std::map<int, std::vector<Eigen::Matrix2Xd>> head_points;  // the same
  ProgressLine progress(0, static_cast<int>(fitted.size()), 30, "frame");
  for (size_t next = 0; next < fitted.size(); ++next) {
    if (next % 20 == 0 || next + 1 == fitted.size()) progress.Show(static_cast<int>(next), "cropping");
    const FrameParams& params = fitted[next];
    const int n = static_cast<int>(params.sequence);
    numbers.push_back(static_cast<int64_t>(params.sequence));
    const cv::Mat frame = ReadImage((full_frames / FrameFileName(n)).string());
    const cv::Mat mask = ReadImage((full_masks / FrameFileName(n)).string(), cv::IMREAD_GRAYSCALE);
    if (mask.size() != frame.size())
      throw std::runtime_error(o.input + ": frame " + std::to_string(n) + " and its mask differ in size");
    const RasterVertices skull = o.steady_masks > 0 ? SkullPoints(model, identity, params) : RasterVertices();
    for (int r : o.resolutions) {
      const fs::path rd = dir / std::to_string(r);
      WriteImage((rd / "images" / FrameFileName(n)).string(), CropSquare(frame, x0, y0, side, r, cv::INTER_AREA));
      cv::Mat m = CropSquare(mask, x0, y0, side, r, cv::INTER_LINEAR);
      cv::threshold(m, m, 127, 255, cv::THRESH_BINARY);
      grabcut[r].push_back(m);
      head_points[r].push_back(ProjectPoints(skull, CropIntrinsics(camera, x0, y0, side, r)));
    }
  }
  progress.Finish();
  ProgressLine cutting(0, static_cast<int>(fitted.size()), 30, "frame");
  for (size_t next = 0; next < fitted.size(); ++next) {
    if (next % 20 == 0 || next + 1 == fitted.size()) cutting.Show(static_cast<int>(next), "masks");
    const FrameParams& params = fitted[next];
    HeadModelOutput posed;
    model.Forward(identity, params.expression.cast<double>(), params.HeadPose(), &posed);
    RasterVertices in_camera;
    TransformToCamera(posed.vertices, params.CamFromHead(), &in_camera);
    for (int r : o.resolutions) {
      const PinholeCamera crop_camera = CropIntrinsics(camera, x0, y0, side, r);
      RasterBuffers silhouette;
      Rasterize(in_camera, model.data().faces, crop_camera, RasterOptions{}, &silhouette);
      const cv::Mat steady = SteadyMask(grabcut[r], head_points[r], numbers, next, o.steady_masks);
      WriteImage((dir / std::to_string(r) / "masks" / FrameFileName(static_cast<int>(params.sequence))).string(),
                 CutTrainingMask(steady, silhouette.Mask(), fitter.Project(params, crop_camera), o.matte_rules()));
    }
  }
  cutting.Finish();
  grabcut.clear();

  const int n = static_cast<int>(fitted.size());
  // 4. Short videos: frames between consecutive training frames.
  int interpolated = 0;
  if (o.interpolate > 0) {
    RecordingWriter writer((dir / "params_interp.hcrec").string(), info);
    for (int r : o.resolutions) {
      fs::create_directories(dir / std::to_string(r) / "interp" / "images");
      fs::create_directories(dir / std::to_string(r) / "interp" / "masks");
    }
    for (int i = 0; i + 1 < n - test_frames; ++i) {
      const FrameParams &a = fitted[static_cast<size_t>(i)], &b = fitted[static_cast<size_t>(i + 1)];
      if (b.sequence != a.sequence + 1) continue;  // a gap (lost face): nothing to interpolate
      for (int r : o.resolutions) {
        const fs::path rd = dir / std::to_string(r);
        auto read = [&](const char* kind, uint64_t frame, int flags) {
          return ReadImage((rd / kind / FrameFileName(static_cast<int>(frame))).string(), flags);
        };
        const cv::Mat ia = read("images", a.sequence, cv::IMREAD_COLOR),
                      ib = read("images", b.sequence, cv::IMREAD_COLOR);
        const cv::Mat ma = read("masks", a.sequence, cv::IMREAD_GRAYSCALE),
                      mb = read("masks", b.sequence, cv::IMREAD_GRAYSCALE);
        const FlowPair flow = DenseFlow(ia, ib);
        for (int k = 1; k <= o.interpolate; ++k) {
          const double t = static_cast<double>(k) / (o.interpolate + 1);
          const int id = interpolated + k - 1;
          WriteImage((rd / "interp" / "images" / FrameFileName(id)).string(), InterpolateImage(ia, ib, flow, t));
          cv::Mat m = InterpolateImage(ma, mb, flow, t);
          cv::threshold(m, m, 127, 255, cv::THRESH_BINARY);
          WriteImage((rd / "interp" / "masks" / FrameFileName(id)).string(), m);
        }
      }
      for (int k = 1; k <= o.interpolate; ++k) {
        FrameParams f = InterpolateParams(a, b, static_cast<double>(k) / (o.interpolate + 1));
        f.sequence = static_cast<uint64_t>(interpolated++);
        writer.Write(f);
      }
    }
  }

  // 5. The manifest: split, subject, intrinsics per resolution.
  nlohmann::json intrinsics = nlohmann::json::object();
  for (int r : o.resolutions) {
    const PinholeCamera k = CropIntrinsics(camera, x0, y0, side, r);
    intrinsics[std::to_string(r)] = {k.fx, k.fy, k.cx, k.cy};
  }
  std::vector<int> frame_numbers;
  for (const FrameParams& f : fitted) frame_numbers.push_back(static_cast<int>(f.sequence));
  const std::vector<float> shape(info.subject.shape.data(), info.subject.shape.data() + info.subject.shape.size());
  const std::vector<float> texture(info.subject.texture.data(),
                                   info.subject.texture.data() + info.subject.texture.size());
  nlohmann::json manifest = {
      {"format", "headcast-dataset"},
      {"format_version", kDatasetFormatVersion},
      {"source", o.input},
      {"head_model", {{"name", model.data().name}, {"fingerprint", model.fingerprint()}}},
      {"frames_read", track_report.value("frames", 0)},
      {"frames_fitted", n},
      {"frame_numbers", frame_numbers},
      {"split", {{"train", n - test_frames}, {"test", test_frames}, {"rule", "test = the last N fitted frames"}}},
      {"interpolated",
       {{"per_pair", o.interpolate},
        {"frames", interpolated},
        {"how", "Farneback optical flow both ways, neighbours warped and blended; parameters interpolated"}}},
      {"crop",
       {{"x0", x0},
        {"y0", y0},
        {"side", side},
        {"source_camera", {camera.fx, camera.fy, camera.cx, camera.cy}},
        {"source_size", {camera.width, camera.height}}}},
      {"resolutions", o.resolutions},
      {"intrinsics", intrinsics},
      {"subject", {{"shape", shape}, {"texture", texture}, {"light", info.subject.light}}},
      {"identity", track_report.value("identity", std::string("?"))},
      {"masks", "the tracker's head mask (GrabCut), convex above the brows" +
                    std::string(o.fill_skull ? ", the fitted skull above the brows added" : "") +
                    ", within the fitted model's silhouette "
                    "dilated by " +
                    std::to_string(o.mask_margin) + " of the crop edge above the eye line, " +
                    std::to_string(o.side_margin) + " below it" +
                    (o.keep_neck ? std::string() : ", nothing below the fitted jaw line") +
                    (o.steady_masks > 0 ? ", GrabCut's masks steadied over " + std::to_string(o.steady_masks) +
                                              " frames either side (moved with the head, averaged, cut at half)"
                                        : std::string())},
      {"mask_rules", o.matte_rules().ToJson()},
      {"tracking",
       {{"fitted_frames", track_report.value("fitted_frames", 0)},
        {"frames", track_report.value("frames", 0)},
        {"landmark_error_iod_mean", track_report.value("landmark_error_iod_mean", -1.0)},
        {"jitter_iod_median", track_report.value("jitter_iod_median", -1.0)},
        {"jitter_iod_median_raw_landmarks", track_report.value("jitter_iod_median_raw_landmarks", -1.0)},
        {"predictor_views", o.predictor_views},
        {"predictor_views_points", o.predictor_views_points},
        {"gaze", o.gaze},
        {"eye_look_prior", o.expression_fit.eye_look_prior},
        {"eye_look_prior_shapes", o.expression_fit.eye_look_prior_shapes},
        {"mask_working_size", o.mask_working_size},
        {"steady_masks", o.steady_masks},
        {"landmark_filter", o.landmark_filter},
        {"pose_smoothing", o.pose_smoothing},
        {"photometric_anchor", o.photometric_anchor},
        {"outline_hold", o.outline_hold}}}};
  // The references the frames were fitted to, for the avatar to carry to the sender.
  const nlohmann::json anchor = track_report.value("photometric_anchor", nlohmann::json::object());
  if (anchor.is_object() && anchor.contains("reference") && !anchor.at("reference").is_null())
    manifest["tracking_anchor"] = anchor.at("reference");
  manifest["tracking_fit"] = o.expression_fit.ToJson();
  std::ofstream(dir / "dataset.json") << manifest.dump(2) << "\n";
  return manifest;
}

PreparedDataset PreparedDataset::Load(const std::string& dir, const HeadModel& model, int resolution,
                                      bool interpolated) {
  const fs::path manifest_path = fs::path(dir) / "dataset.json";
  PreparedDataset d;
  d.dir_ = dir;
  d.resolution_ = resolution;
  try {
    std::ifstream in(manifest_path);
    if (!in) throw std::runtime_error("missing (not a prepared dataset? run headcast-train prep)");
    d.manifest_ = nlohmann::json::parse(in);
    const auto& m = d.manifest_;
    if (m.value("format", "") != "headcast-dataset") throw std::runtime_error("not a headcast dataset");
    if (m.at("format_version").get<int>() != kDatasetFormatVersion)
      throw std::runtime_error("format version " + std::to_string(m.at("format_version").get<int>()) +
                               ", this build reads " + std::to_string(kDatasetFormatVersion));
    const std::string fingerprint = m.at("head_model").at("fingerprint");
    if (fingerprint != model.fingerprint())
      throw std::runtime_error("prepared for head model " + m.at("head_model").at("name").get<std::string>() + " (" +
                               fingerprint + "), not " + model.data().name + " (" + model.fingerprint() + ")");
    const auto& k = m.at("intrinsics");
    if (!k.contains(std::to_string(resolution)))
      throw std::runtime_error("no " + std::to_string(resolution) + " crops (prepared: " + m.at("resolutions").dump() +
                               ")");
    const std::vector<double> kk = k.at(std::to_string(resolution));
    d.subject_.intrinsics = PinholeCamera{kk.at(0), kk.at(1), kk.at(2), kk.at(3), resolution, resolution};
    const std::vector<float> shape = m.at("subject").at("shape"), texture = m.at("subject").at("texture");
    d.subject_.shape = Eigen::Map<const Eigen::VectorXf>(shape.data(), static_cast<Eigen::Index>(shape.size()));
    d.subject_.texture = Eigen::Map<const Eigen::VectorXf>(texture.data(), static_cast<Eigen::Index>(texture.size()));
    d.subject_.light = m.at("subject").at("light").get<std::array<float, 27>>();
    d.frames_ = ReadRecording((fs::path(dir) / "params.hcrec").string());
    const int n = static_cast<int>(d.frames_.size());
    const int train = m.at("split").at("train").get<int>();
    if (n != m.at("frames_fitted").get<int>() || train < 1 || train > n)
      throw std::runtime_error("the split does not match params.hcrec");
    for (int i = 0; i < n; ++i) (i < train ? d.train_ : d.test_).push_back(i);
    d.first_interpolated_ = n;
    const int extra = m.contains("interpolated") ? m.at("interpolated").at("frames").get<int>() : 0;
    if (interpolated && extra > 0) {
      const std::vector<FrameParams> more = ReadRecording((fs::path(dir) / "params_interp.hcrec").string());
      if (static_cast<int>(more.size()) != extra) throw std::runtime_error("params_interp.hcrec does not match");
      for (const FrameParams& f : more) {
        d.train_.push_back(static_cast<int>(d.frames_.size()));
        d.frames_.push_back(f);
      }
    }
  } catch (const std::exception& e) {
    throw std::runtime_error(manifest_path.string() + ": " + e.what());
  }
  return d;
}

MatteRules PreparedDataset::matte_rules() const {
  if (!manifest_.contains("mask_rules")) return MatteRules{};
  try {
    return MatteRules::FromJson(manifest_.at("mask_rules"));
  } catch (const std::exception& e) {
    throw std::runtime_error(dir_ + "/dataset.json: " + e.what());
  }
}

std::optional<CameraContract> PreparedDataset::camera_contract() const {
  const nlohmann::json& crop = manifest_.at("crop");
  if (!crop.contains("source_size")) return std::nullopt;
  const std::vector<double> k = crop.at("source_camera");
  const std::vector<int> size = crop.at("source_size");
  if (k.size() != 4 || size.size() != 2) throw std::runtime_error(dir_ + "/dataset.json: a malformed crop");
  CameraContract c;
  c.source = PinholeCamera{k[0], k[1], k[2], k[3], size[0], size[1]};
  c.crop_x0 = crop.at("x0");
  c.crop_y0 = crop.at("y0");
  c.crop_side = crop.at("side");
  c.Check();
  return c;
}

std::optional<AnchorReference> PreparedDataset::anchor_reference() const {
  if (!manifest_.contains("tracking_anchor")) return std::nullopt;
  try {
    return AnchorReference::FromJson(manifest_.at("tracking_anchor"));
  } catch (const std::exception& e) {
    throw std::runtime_error(dir_ + "/dataset.json: tracking_anchor: " + e.what());
  }
}

ExpressionFitSettings PreparedDataset::expression_fit() const {
  try {
    if (manifest_.contains("tracking_fit")) return ExpressionFitSettings::FromJson(manifest_.at("tracking_fit"));
    ExpressionFitSettings legacy = ExpressionFitSettings::Legacy();
    const nlohmann::json tracking = manifest_.value("tracking", nlohmann::json::object());
    legacy.eye_look_prior = tracking.value("eye_look_prior", legacy.eye_look_prior);
    legacy.eye_look_prior_shapes = tracking.value("eye_look_prior_shapes", legacy.eye_look_prior_shapes);
    return ExpressionFitSettings::FromJson(legacy.ToJson());  // checks what the record held
  } catch (const std::exception& e) {
    throw std::runtime_error(dir_ + "/dataset.json: " + e.what());
  }
}

const FrameParams& PreparedDataset::params(int i) const {
  HEADCAST_CHECK(i >= 0 && i < size()) << "PreparedDataset::params(" << i << ") of " << size() << " frames";
  return frames_[static_cast<size_t>(i)];
}

const RealSample& PreparedDataset::At(int i) const {
  HEADCAST_CHECK(i >= 0 && i < size()) << "PreparedDataset::At(" << i << ") of " << size() << " frames";
  auto it = cache_.find(i);
  if (it != cache_.end()) return it->second;
  RealSample s;
  s.params = frames_[static_cast<size_t>(i)];
  s.frame = static_cast<int>(s.params.sequence);
  const fs::path rd = fs::path(dir_) / std::to_string(resolution_) / (i >= first_interpolated_ ? "interp" : "");
  s.image_bgr = ReadImage((rd / "images" / FrameFileName(s.frame)).string());
  s.mask = ReadImage((rd / "masks" / FrameFileName(s.frame)).string(), cv::IMREAD_GRAYSCALE);
  if (s.image_bgr.rows != resolution_ || s.image_bgr.cols != resolution_ || s.mask.size() != s.image_bgr.size())
    throw std::runtime_error(rd.string() + ": frame " + std::to_string(s.frame) + " is not " +
                             std::to_string(resolution_) + " pixels square");
  return cache_.emplace(i, std::move(s)).first->second;
}

}  // namespace headcast
