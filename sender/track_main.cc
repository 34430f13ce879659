// headcast-track: the sender's tracking pipeline on a video file or image
// folder — face tracker, landmarks, head-model fit per frame — writing the
// parameter recording, an overlay video and a JSON report.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <optional>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/rotation.h"
#include "common/core/timer.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/appearance_fit.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/head_mask.h"
#include "common/tracking/mesh_fitter.h"
#include "common/tracking/rgbd_fitter.h"
#include "common/tracking/tracked_fit.h"
#include "proto/recording.h"
#include "sender/capture/frame_source.h"

namespace {

// An RGB-D fit as the frame parameters the sender streams.
void ApplyRgbdFit(const headcast::RgbdFitResult& r, headcast::FrameParams* f) {
  f->expression = r.params.expression.cast<float>();
  f->jaw = r.params.pose.segment<3>(3 * headcast::kJawJoint).cast<float>();
  f->SetCamFromHead({r.rotation, r.translation});
}

}  // namespace

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-track: track a face in a video and fit the head model to every frame"};
  std::string input, head_model_spec = "builtin", out, report_path, overlay, log_level, predictor, identity_from;
  int max_frames = 0;
  std::string camera_size = "640x480", intrinsics;
  int calibration_frames = 15;
  bool calibrate = false;
  std::string masks_dir;
  bool fit_appearance = true;
  double fov_deg = 40;
  app.add_option("--input", input,
                 "video file, image folder, RGB-D folder (with associations.txt), /dev/videoN (V4L2 camera), or "
                 "zed:SOURCE (side-by-side stereo from a camera, video or folder)")
      ->required();
  app.add_option("--head-model", head_model_spec, "builtin or a model .npz")->capture_default_str();
  app.add_option("--out", out, "parameter recording to write (.hcrec)")->required();
  app.add_option("--report", report_path, "JSON report to write");
  app.add_option("--overlay", overlay, "MP4 with the fitted landmarks/mesh over the frames");
  app.add_option("--max-frames", max_frames, "stop after this many frames");
  app.add_option("--fov", fov_deg, "vertical field of view of the camera, degrees (until calibration exists)")
      ->capture_default_str();
  app.add_option("--predictor", predictor, "dlib 68-point shape predictor (.dat)");
  SourceOptions source_options;
  app.add_option("--depth-input", source_options.depth_input,
                 "RGB-D: association file (TUM style: t colour.png t depth.png) of 16-bit depth PNGs");
  app.add_option("--depth-units", source_options.depth_units_per_metre,
                 "depth PNG units per metre (1000: millimetres; TUM datasets use 5000)")
      ->capture_default_str();
  app.add_option("--stereo-calibration", source_options.stereo_calibration,
                 "for zed:SOURCE inputs: OpenCV YAML or the camera's factory SN<serial>.conf");
  app.add_option("--stereo-resolution", source_options.stereo_resolution, "section of a ZED .conf: 2K, FHD, HD, VGA")
      ->capture_default_str();
  app.add_flag("--realtime", source_options.realtime, "pace recorded inputs to their frame rate");
  app.add_option("--intrinsics", intrinsics, "camera intrinsics fx,fy,cx,cy in pixels (else --fov, or the stereo calibration)");
  app.add_option("--calibration-frames", calibration_frames,
                 "RGB-D: frames whose fitted shapes give the identity (median); with --calibrate: key frames at most")
      ->capture_default_str();
  app.add_option("--masks", masks_dir, "also write a head mask (face, hair, neck) per fitted frame here, NNNNN.png");
  HeadMaskOptions mask_options;
  app.add_option("--mask-hair-height", mask_options.hair_height,
                 "head masks: hair may reach this far above the brows, in face heights")
      ->capture_default_str();
  app.add_option("--mask-head-width", mask_options.head_width, "head masks: the head's width, in jaw widths")
      ->capture_default_str();
  app.add_flag("!--no-appearance", fit_appearance, "skip the texture/light fit (stored in the recording's header)");
  app.add_flag("--calibrate", calibrate,
               "RGB, recorded input: calibrate identity (shape) and focal length over key frames spread over the "
               "head's yaw in a first pass, then track with them (METHOD §2)");
  app.add_option("--camera-size", camera_size, "cameras: WIDTHxHEIGHT to ask for")->capture_default_str();
  app.add_option("--camera-fps", source_options.fps, "cameras: frame rate to ask for; image folders: their rate")
      ->capture_default_str();
  app.add_option("--pixel-format", source_options.pixel_format, "cameras: auto, yuyv or mjpeg")->capture_default_str();
  app.add_option("--identity-from", identity_from,
                 "take the identity (shape) from a headcast-fit-mesh PARAMS.json instead of neutral");
  app.add_option("--log", log_level, "log level");
  CLI11_PARSE(app, argc, argv);
  try {
    if (std::sscanf(camera_size.c_str(), "%dx%d", &source_options.width, &source_options.height) != 2)
      throw std::invalid_argument("--camera-size wants WIDTHxHEIGHT, e.g. 1280x720");
    mask_options.Check();
    InitLogging(log_level);
    const HeadModel model = LoadHeadModelSpec(head_model_spec);
    FaceTrackerOptions tracker_options;
    if (!predictor.empty()) tracker_options.predictor_path = predictor;
    FaceTracker tracker(tracker_options);
    HeadFitter fitter(model);
    Eigen::VectorXd identity = Eigen::VectorXd::Zero(model.num_shape());
    if (!identity_from.empty()) identity = ReadIdentityFromMeshFit(identity_from, model);
    fitter.SetIdentity(identity);
    // Identity calibration (RGB, recorded input): a first pass collects landmarks,
    // key frames spread over the head's yaw give shape and focal length.
    std::optional<PinholeCamera> calibrated_camera;
    nlohmann::json calibration_report;
    if (calibrate) {
      if (input.rfind("/dev/", 0) == 0 || input.find(":/dev/") != std::string::npos)
        throw std::invalid_argument("--calibrate needs a recorded input (a live camera cannot be read twice)");
      auto pass = OpenFrameSource(input, source_options);
      FaceTracker first_tracker(tracker_options);
      HeadFitter first_fitter(model);
      first_fitter.SetIdentity(identity);
      FrameParams p;
      p.cam_translation.setZero();
      std::vector<std::pair<double, Landmarks2d>> seen;  // (yaw, landmarks)
      PinholeCamera initial;
      bool have_initial = false;
      for (int n = 0; max_frames <= 0 || n < max_frames; ++n) {
        CapturedFrame c;
        std::string why;
        const ReadStatus st = pass->Read(&c, &why);
        if (st == ReadStatus::kEnd) break;
        if (st == ReadStatus::kSkipped) continue;
        if (!have_initial) {
          initial = c.camera ? *c.camera : PinholeCamera::FromFovY(c.bgr.cols, c.bgr.rows, fov_deg);
          have_initial = true;
        }
        const FaceObservation obs = first_tracker.Track(c.bgr, c.capture_time_s);
        if (!FitTrackedFace(first_fitter, obs, initial, &p).ok) continue;
        seen.emplace_back(ViewRotation(AxisAngleToMatrix(p.cam_rotation.cast<double>())).y(), obs.landmarks);
      }
      if (seen.size() < 3) throw std::runtime_error(input + ": too few frames with a face to calibrate the identity");
      std::sort(seen.begin(), seen.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      // Key frames: evenly spaced over the sorted yaws (the extremes included), at most a quarter of the frames.
      const int keys = std::max(3, std::min(calibration_frames, static_cast<int>(seen.size()) / 4));
      std::vector<Landmarks2d> key_frames;
      for (int k = 0; k < keys; ++k)
        key_frames.push_back(seen[static_cast<size_t>(std::lround(k * (seen.size() - 1.0) / (keys - 1)))].second);
      const HeadFitter::Calibration cal = fitter.CalibrateIdentity(key_frames, initial);
      if (!cal.ok) throw std::runtime_error(input + ": identity calibration failed");
      identity = cal.shape;
      calibrated_camera = cal.camera;
      calibration_report = {{"key_frames", cal.frames},
                            {"yaw_range_deg", {seen.front().first * 180 / M_PI, seen.back().first * 180 / M_PI}},
                            {"focal_px", cal.camera.fx},
                            {"focal_px_from_fov", initial.fx},
                            {"rms_px", cal.rms_px}};
      spdlog::info("identity calibrated over {} key frames: focal {:.1f} px, rms {:.2f} px", cal.frames, cal.camera.fx,
                   cal.rms_px);
    }
    // Frames from a camera, a video, an image or RGB-D folder, or side-by-side stereo.
    std::unique_ptr<FrameSource> source = OpenFrameSource(input, source_options);
    if (!masks_dir.empty()) std::filesystem::create_directories(masks_dir);
    spdlog::info("source: {}", source->Describe());
    const double fps = source->fps();
    // Frames are kept and written at the end, when the subject's constants
    // (identity, camera, texture, light) that head the recording are known.
    std::vector<FrameParams> recorded;
    std::unique_ptr<VideoWriter> overlay_writer;
    if (!overlay.empty()) overlay_writer = std::make_unique<VideoWriter>(overlay, fps);
    PinholeCamera camera;
    AppearanceFit appearance;
    std::vector<AppearanceSample> appearance_samples;
    auto MakeInfo = [&] {
      RecordingInfo info;
      info.head_model_name = model.data().name;
      info.head_model_fingerprint = model.fingerprint();
      info.num_expression = model.num_expression();
      info.fps = fps;
      info.subject.shape = identity.cast<float>();
      info.subject.texture = Eigen::VectorXf::Zero(model.num_texture());
      if (appearance.ok) {
        info.subject.texture.head(appearance.texture.size()) = appearance.texture.cast<float>();
        info.subject.light = appearance.light;
      }
      info.subject.intrinsics = camera;
      info.source = "headcast-track " + input;
      return info;
    };
    // RGB-D: one fitter that also fits the shape (calibration), one with it frozen.
    RgbdFitOptions calibrating_options, frozen_options;
    frozen_options.fit_shape = false;
    RgbdFitter rgbd_calibrating(model, calibrating_options), rgbd(model, frozen_options);
    rgbd.SetIdentity(identity);
    bool identity_frozen = !identity_from.empty();
    struct Pending {
      Landmarks2d landmarks;
      cv::Mat depth;
      uint64_t sequence;
      double time;
    };
    std::vector<Pending> pending;
    std::vector<Eigen::VectorXd> calibration_shapes;
    RgbdFitResult last_rgbd;
    SampleStats accuracy_mm;
    int contour_rejected = 0;
    // The identity: per-component median of the calibration frames' shapes;
    // those frames are fitted again with it and written.
    auto freeze = [&] {
      for (int k = 0; k < model.num_shape(); ++k) {
        std::vector<double> v;
        for (const auto& shape : calibration_shapes) v.push_back(shape[k]);
        std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
        identity[k] = v[v.size() / 2];
      }
      rgbd.SetIdentity(identity);
      fitter.SetIdentity(identity);
      identity_frozen = true;
      spdlog::info("identity frozen from {} RGB-D frames", calibration_shapes.size());
      RgbdFitResult previous;
      for (const Pending& p : pending) {
        const RgbdFitResult r = rgbd.Fit(p.landmarks, p.depth, camera, previous.ok ? &previous : nullptr);
        if (!r.ok) continue;
        FrameParams f;
        ApplyRgbdFit(r, &f);
        f.sequence = p.sequence;
        f.capture_time_s = p.time;
        f.confidence = 1.f;
        recorded.push_back(f);
        previous = r;
      }
      pending.clear();
      last_rgbd = previous.ok ? previous : last_rgbd;
    };
    SampleStats ms, error_iod;
    // Jitter: the second difference of landmark positions over consecutive
    // fitted frames (mean over the 68, over the eye distance): what shakes.
    SampleStats jitter_fitted, jitter_detected;
    std::vector<Landmarks2d> last_fitted, last_detected;
    int64_t last_fitted_frame = -2;
    auto second_difference = [](const std::vector<Landmarks2d>& h) {
      double sum = 0;
      for (int l = 0; l < kNumLandmarks; ++l) sum += (h[2][l] - 2 * h[1][l] + h[0][l]).norm();
      return sum / kNumLandmarks / std::max(1e-9, (h[1][36] - h[1][45]).norm());
    };
    int frames = 0, fitted = 0, unreadable = 0, with_depth = 0;
    std::map<std::string, int> statuses;
    FrameParams params;
    params.cam_translation.setZero();  // cold start
    for (;;) {
      if (max_frames > 0 && frames >= max_frames) break;
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
      with_depth += !captured.depth_m.empty();
      ++frames;
      if (frames == 1) {
        // Calibrated intrinsics when the source has them (stereo) or were given, else the field of view.
        camera = calibrated_camera ? *calibrated_camera
                 : captured.camera ? *captured.camera
                                   : PinholeCamera::FromFovY(frame.cols, frame.rows, fov_deg);
        if (!intrinsics.empty()) {
          if (std::sscanf(intrinsics.c_str(), "%lf,%lf,%lf,%lf", &camera.fx, &camera.fy, &camera.cx, &camera.cy) != 4)
            throw std::invalid_argument("--intrinsics wants fx,fy,cx,cy in pixels");
          camera.Check();
        }
      }
      const double t = captured.capture_time_s;
      Stopwatch watch;
      const FaceObservation obs = tracker.Track(frame, t);
      FitResult fit;
      bool hold = false;  // RGB-D identity calibration: written once the identity is frozen
      if (obs.status != FaceStatus::kNoFace && !captured.depth_m.empty()) {
        // RGB-D (METHOD §3): shape fitted on the first frames, then frozen at their median.
        const RgbdFitResult r = identity_frozen ? rgbd.Fit(obs.landmarks, captured.depth_m, camera,
                                                           last_rgbd.ok ? &last_rgbd : nullptr)
                                                : rgbd_calibrating.Fit(obs.landmarks, captured.depth_m, camera);
        if (r.ok) {
          ApplyRgbdFit(r, &params);
          fit.ok = true;
          accuracy_mm.Add(1e3 * r.accuracy_m);
          contour_rejected += r.contour_rejected;
          if (!identity_frozen) {
            calibration_shapes.push_back(r.params.shape);
            pending.push_back({obs.landmarks, captured.depth_m.clone(), static_cast<uint64_t>(frames - 1), t});
            hold = true;
          }
        } else {
          spdlog::debug("frame {}: RGB-D fit: {}", frames - 1, r.problem);
        }
        last_rgbd = r;
      } else {
        fit = FitTrackedFace(fitter, obs, camera, &params);
      }
      ms.Add(watch.ElapsedMs());
      ++statuses[obs.status == FaceStatus::kNoFace ? "no_face" : fit.ok ? "fitted" : "fit_failed"];
      cv::Mat shown = frame.clone();
      if (fit.ok) {
        ++fitted;
        params.sequence = static_cast<uint64_t>(frames - 1);
        params.capture_time_s = t;
        params.confidence = 1.f;
        if (!hold) recorded.push_back(params);
        if (!identity_frozen && static_cast<int>(calibration_shapes.size()) >= calibration_frames) freeze();
        // Every 15th fitted frame, up to 8, for the texture and light fit.
        const bool sample = fit_appearance && fitted % 15 == 1 && appearance_samples.size() < 8;
        if (sample || !masks_dir.empty()) {
          const cv::Mat mask = HeadMask(frame, obs.raw, mask_options);
          if (sample) appearance_samples.push_back({frame.clone(), mask, params, camera});
          if (!masks_dir.empty()) {
            char name[32];
            std::snprintf(name, sizeof(name), "/%05d.png", frames - 1);
            WriteImage(masks_dir + name, mask);
          }
        }
        const Landmarks2d model_landmarks = fitter.Project(params, camera);
        error_iod.Add(LandmarkErrorIod(model_landmarks, obs.raw));
        if (last_fitted_frame != frames - 2) {  // a gap: start the history again
          last_fitted.clear();
          last_detected.clear();
        }
        last_fitted_frame = frames - 1;
        last_fitted.push_back(model_landmarks);
        last_detected.push_back(obs.raw);
        if (last_fitted.size() > 3) {
          last_fitted.erase(last_fitted.begin());
          last_detected.erase(last_detected.begin());
        }
        if (last_fitted.size() == 3) {
          jitter_fitted.Add(second_difference(last_fitted));
          jitter_detected.Add(second_difference(last_detected));
        }
        for (int l = 0; l < kNumLandmarks; ++l) {
          cv::circle(shown, cv::Point2d(obs.raw[l].x(), obs.raw[l].y()), 2, cv::Scalar(0, 200, 255), cv::FILLED,
                     cv::LINE_AA);
          cv::circle(shown, cv::Point2d(model_landmarks[l].x(), model_landmarks[l].y()), 2, cv::Scalar(80, 255, 80), 1,
                     cv::LINE_AA);
        }
      } else {
        params.cam_translation.setZero();  // lost, or the RGB-D fit failed: the next face starts cold
      }
      cv::putText(shown, std::string(FaceStatusName(obs.status)) + (fit.ok ? " fitted" : ""), {8, 20},
                  cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
      if (overlay_writer) overlay_writer->Write(shown);
    }
    if (!identity_frozen && !calibration_shapes.empty()) freeze();
    if (frames == 0) throw std::runtime_error(input + ": no readable frames (corrupt or empty?)");
    if (!appearance_samples.empty()) {
      appearance = FitAppearance(model, identity, appearance_samples);
      if (!appearance.ok) spdlog::warn("texture/light fit: {}", appearance.problem);
    }
    {
      RecordingWriter writer(out, MakeInfo());
      for (const FrameParams& f : recorded) writer.Write(f);
    }
    nlohmann::json report = {{"input", input},
                             {"head_model", model.data().name},
                             {"frames", frames},
                             {"fitted_frames", fitted},
                             {"unreadable_frames", unreadable},
                             {"statuses", statuses},
                             {"landmark_error_iod_mean", error_iod.empty() ? -1.0 : error_iod.Mean()},
                             {"jitter_iod_median", jitter_fitted.empty() ? -1.0 : jitter_fitted.Median()},
                             {"jitter_iod_median_raw_landmarks", jitter_detected.empty() ? -1.0 : jitter_detected.Median()},
                             {"ms_per_frame_median", ms.Median()},
                             {"ms_per_frame_p95", ms.Percentile(95)},
                             {"frames_with_depth", with_depth},
                             {"identity", !identity_from.empty() ? identity_from
                                          : calibrate          ? "calibrated over key frames (shape, focal)"
                                          : with_depth > 0     ? "RGB-D: median shape of the first fitted frames"
                                                               : "neutral (beta = 0)"},
                             {"camera", camera.ToString()}};
    if (!accuracy_mm.empty()) {
      report["rgbd_accuracy_mm_median"] = accuracy_mm.Median();
      report["rgbd_accuracy_mm_p95"] = accuracy_mm.Percentile(95);
      report["rgbd_contour_landmarks_rejected"] = contour_rejected;
      report["what_rgbd_accuracy_means"] = "sqrt of the mean squared point-to-mesh distance after the fit (METHOD §3)";
    }
    if (calibrate) report["calibration"] = calibration_report;
    if (appearance.ok)
      report["appearance"] = {{"frames", appearance_samples.size()},
                              {"pixels", appearance.pixels},
                              {"rms", appearance.rms},
                              {"what", "texture tau and SH light lambda by the masked photometric fit; rms in 0..1"}};
    std::cout << report.dump(2) << "\n";
    if (!report_path.empty()) std::ofstream(report_path) << report.dump(2) << "\n";
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
