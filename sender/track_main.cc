// headcast-track: the sender's tracking pipeline on a video file or image
// folder — face tracker, landmarks, head-model fit per frame — writing the
// parameter recording, an overlay video and a JSON report.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/timer.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/mesh_fitter.h"
#include "proto/recording.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-track: track a face in a video and fit the head model to every frame"};
  std::string input, head_model_spec = "builtin", out, report_path, overlay, log_level, predictor, identity_from;
  int max_frames = 0;
  double fov_deg = 40;
  app.add_option("--input", input, "video file or folder of images")->required();
  app.add_option("--head-model", head_model_spec, "builtin or a model .npz")->capture_default_str();
  app.add_option("--out", out, "parameter recording to write (.hcrec)")->required();
  app.add_option("--report", report_path, "JSON report to write");
  app.add_option("--overlay", overlay, "MP4 with the fitted landmarks/mesh over the frames");
  app.add_option("--max-frames", max_frames, "stop after this many frames");
  app.add_option("--fov", fov_deg, "vertical field of view of the camera, degrees (until calibration exists)")
      ->capture_default_str();
  app.add_option("--predictor", predictor, "dlib 68-point shape predictor (.dat)");
  app.add_option("--identity-from", identity_from,
                 "take the identity (shape) from a headcast-fit-mesh PARAMS.json instead of neutral");
  app.add_option("--log", log_level, "log level");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    const HeadModel model = LoadHeadModelSpec(head_model_spec);
    FaceTrackerOptions tracker_options;
    if (!predictor.empty()) tracker_options.predictor_path = predictor;
    FaceTracker tracker(tracker_options);
    HeadFitter fitter(model);
    Eigen::VectorXd identity = Eigen::VectorXd::Zero(model.num_shape());
    if (!identity_from.empty()) identity = ReadIdentityFromMeshFit(identity_from, model);
    fitter.SetIdentity(identity);
    // Frames from a video or a sorted folder of images.
    std::unique_ptr<VideoReader> video;
    std::vector<fs::path> images;
    double fps = 30;
    if (fs::is_directory(input)) {
      for (const auto& e : fs::directory_iterator(input)) {
        const std::string ext = e.path().extension().string();
        if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".ppm")
          images.push_back(e.path());
      }
      std::sort(images.begin(), images.end());
      if (images.empty()) throw std::runtime_error(input + ": no images in this folder");
    } else {
      video = std::make_unique<VideoReader>(input);
      if (video->fps() > 0) fps = video->fps();
    }
    std::unique_ptr<RecordingWriter> writer;
    std::unique_ptr<VideoWriter> overlay_writer;
    if (!overlay.empty()) overlay_writer = std::make_unique<VideoWriter>(overlay, fps);
    SampleStats ms, error_iod;
    int frames = 0, fitted = 0, unreadable = 0;
    std::map<std::string, int> statuses;
    FrameParams params;
    params.cam_translation.setZero();  // cold start
    PinholeCamera camera;
    for (size_t index = 0;; ++index) {
      if (max_frames > 0 && frames >= max_frames) break;
      cv::Mat frame;
      if (video) {
        if (!video->Read(&frame)) break;
      } else {
        if (index >= images.size()) break;
        try {
          frame = ReadImage(images[index].string());
        } catch (const std::exception& e) {
          ++unreadable;  // a corrupt file is a per-frame status; the run goes on
          spdlog::warn("{}", e.what());
          continue;
        }
      }
      ++frames;
      if (!writer) {
        camera = PinholeCamera::FromFovY(frame.cols, frame.rows, fov_deg);
        RecordingInfo info;
        info.head_model_name = model.data().name;
        info.head_model_fingerprint = model.fingerprint();
        info.num_expression = model.num_expression();
        info.fps = fps;
        info.subject.shape = identity.cast<float>();
        info.subject.texture = Eigen::VectorXf::Zero(model.num_texture());
        info.subject.intrinsics = camera;
        info.source = "headcast-track " + input;
        writer = std::make_unique<RecordingWriter>(out, info);
      }
      const double t = (frames - 1) / fps;
      Stopwatch watch;
      const FaceObservation obs = tracker.Track(frame, t);
      FitResult fit;
      if (obs.status != FaceStatus::kNoFace) {
        if (obs.status == FaceStatus::kDetected && !(params.cam_translation.z() > 0)) params.expression.resize(0);
        fit = fitter.Fit(obs.landmarks, camera, &params);
      }
      ms.Add(watch.ElapsedMs());
      ++statuses[obs.status == FaceStatus::kNoFace ? "no_face" : fit.ok ? "fitted" : "fit_failed"];
      cv::Mat shown = frame.clone();
      if (fit.ok) {
        ++fitted;
        params.sequence = static_cast<uint64_t>(frames - 1);
        params.capture_time_s = t;
        params.confidence = 1.f;
        writer->Write(params);
        const Landmarks2d model_landmarks = fitter.Project(params, camera);
        error_iod.Add(LandmarkErrorIod(model_landmarks, obs.raw));
        for (int l = 0; l < kNumLandmarks; ++l) {
          cv::circle(shown, cv::Point2d(obs.raw[l].x(), obs.raw[l].y()), 2, cv::Scalar(0, 200, 255), cv::FILLED,
                     cv::LINE_AA);
          cv::circle(shown, cv::Point2d(model_landmarks[l].x(), model_landmarks[l].y()), 2, cv::Scalar(80, 255, 80), 1,
                     cv::LINE_AA);
        }
      } else {
        params.cam_translation.setZero();  // lost: the next face starts cold
      }
      cv::putText(shown, std::string(FaceStatusName(obs.status)) + (fit.ok ? " fitted" : ""), {8, 20},
                  cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
      if (overlay_writer) overlay_writer->Write(shown);
    }
    if (frames == 0) throw std::runtime_error(input + ": no readable frames (corrupt or empty?)");
    nlohmann::json report = {{"input", input},
                             {"head_model", model.data().name},
                             {"frames", frames},
                             {"fitted_frames", fitted},
                             {"unreadable_frames", unreadable},
                             {"statuses", statuses},
                             {"landmark_error_iod_mean", error_iod.empty() ? -1.0 : error_iod.Mean()},
                             {"ms_per_frame_median", ms.Median()},
                             {"ms_per_frame_p95", ms.Percentile(95)},
                             {"identity", identity_from.empty() ? "neutral (beta = 0)" : identity_from},
                             {"note", "identity is not calibrated from the video yet; focal from --fov"}};
    std::cout << report.dump(2) << "\n";
    if (!report_path.empty()) std::ofstream(report_path) << report.dump(2) << "\n";
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
