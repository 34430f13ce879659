// Benchmark suite "rgbd": the RGB-D fit (METHOD §3) per frame on a rendered
// talking-head sequence with known parameters: time per frame (cold first
// frame, then warm-started), 3D reconstruction accuracy, the head position
// error and the face's vertex error, at two depth-noise levels, for the
// default cloud size and a denser cloud side by side.
#include <opencv2/core.hpp>
#include <random>

#include "bench/bench.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/synthetic_motion.h"
#include "common/tracking/rgbd_fitter.h"
#include "common/tracking/synthetic_scan.h"

namespace headcast::bench {
namespace {

struct RgbdScene {
  explicit RgbdScene(const HeadModel& m) : model(m), albedo(AlbedoTexture(m)) { motion.distance = 0.55; }
  const HeadModel& model;
  PinholeCamera camera = PinholeCamera::FromFovY(640, 480, 45);
  cv::Mat albedo;
  SyntheticMotionOptions motion;
};

// RMS distance over the face's vertices between the fit and the truth (camera frame), mm.
double FaceRmsMm(const HeadModel& model, const RgbdFitResult& fit, const RowMatrixX3f& truth_cam) {
  MeshFitResult placed;
  placed.params = fit.params;
  placed.rotation = fit.rotation;
  placed.translation = fit.translation;
  return FaceRmsAgainstTruthMm(model, placed, truth_cam);
}

nlohmann::json RunSequence(const RgbdScene& s, int frames, int cloud_points, double noise_mm, bool batched) {
  RgbdFitOptions calibrating, frozen;  // the identity from the first frame, as headcast-track calibrates it
  frozen.batched_solve = batched;
  frozen.cloud_points = cloud_points;
  frozen.fit_shape = false;
  RgbdFitter first(s.model, calibrating), fitter(s.model, frozen);
  std::mt19937 rng(3);
  cv::theRNG().state = 3;  // the same depth noise for every configuration
  std::normal_distribution<double> px(0, 1.0);
  SampleStats ms, accuracy_mm, position_mm, face_mm, points;
  double cold_ms = 0;
  RgbdFitResult last;
  for (int i = 0; i < frames; ++i) {
    const FrameParams f = SyntheticTalkingHead(s.model, i, s.motion);
    HeadModelOutput posed;
    s.model.Forward(s.model.MakeIdentity(Eigen::VectorXd::Zero(s.model.num_shape())), f.expression.cast<double>(),
                    f.HeadPose(), &posed);
    const HeadRender r = RenderHead(s.model, posed.vertices, f.CamFromHead(), s.camera, s.albedo);
    cv::Mat depth = r.depth.clone();
    depth.setTo(1.4f, r.mask == 0);
    if (noise_mm > 0) {
      cv::Mat n(depth.size(), CV_32F);
      cv::randn(n, 0, noise_mm * 1e-3);
      depth += n;
    }
    Landmarks2d l;
    for (int k = 0; k < kNumLandmarks; ++k)
      l[k] = s.camera.Project(f.CamFromHead().Apply(posed.landmarks.row(k).cast<double>().transpose())) +
             Eigen::Vector2d(px(rng), px(rng));
    Stopwatch watch;
    const RgbdFitResult fit = i == 0 ? first.Fit(l, depth, s.camera) : fitter.Fit(l, depth, s.camera, &last);
    const double t = watch.ElapsedMs();
    if (!fit.ok) throw std::runtime_error("rgbd: frame " + std::to_string(i) + ": " + fit.problem);
    if (i == 0) {
      cold_ms = t;
      fitter.SetIdentity(fit.params.shape);
    } else {
      ms.Add(t);
    }
    RowMatrixX3f truth_cam(posed.vertices.rows(), 3);
    for (Eigen::Index v = 0; v < truth_cam.rows(); ++v)
      truth_cam.row(v) =
          f.CamFromHead().Apply(posed.vertices.row(v).cast<double>().transpose()).cast<float>().transpose();
    accuracy_mm.Add(1e3 * fit.accuracy_m);
    position_mm.Add(1e3 * (fit.translation - f.CamFromHead().translation).norm());
    face_mm.Add(FaceRmsMm(s.model, fit, truth_cam));
    points.Add(fit.cloud_points);
    last = fit;
  }
  return {{"ms_per_frame_median", ms.Median()},
          {"ms_per_frame_p95", ms.Percentile(95)},
          {"first_frame_ms", cold_ms},
          {"accuracy_mm_median", accuracy_mm.Median()},
          {"head_position_error_mm_median", position_mm.Median()},
          {"face_rms_mm_median", face_mm.Median()},
          {"cloud_points_median", points.Median()}};
}

}  // namespace

nlohmann::json RunRgbdSuite(const BenchOptions& options) {
  const HeadModel model = MakeBuiltinHead();
  const RgbdScene scene(model);
  const int frames = std::max(2, options.repeats);
  nlohmann::json out;
  out["suite"] = "rgbd";
  out["what"] =
      "RgbdFitter::Fit per frame, 640x480, built-in head, landmarks = projected model landmarks + 1 px "
      "noise, wall at 1.4 m; identity frozen after the first frame; ms on this machine; face_rms: the "
      "fitted face's vertices against the truth; *_cloud_3000: a denser cloud; *_per_point_solve: a "
      "Ceres residual block and robust loss per point instead of batched blocks; side by side";
  out["frames"] = frames;
  const int default_points = RgbdFitOptions{}.cloud_points;
  for (const int cloud_points : {default_points, 3000})
    for (const bool batched : {true, false})
      for (const double noise_mm : {0.0, 1.0}) {
        if (cloud_points != default_points && !batched) continue;
        std::string key = "noise_" + std::to_string(static_cast<int>(noise_mm)) + "mm";
        if (cloud_points != default_points) key += "_cloud_" + std::to_string(cloud_points);
        if (!batched) key += "_per_point_solve";
        out[key] = RunSequence(scene, frames, cloud_points, noise_mm, batched);
      }
  return out;
}

}  // namespace headcast::bench
