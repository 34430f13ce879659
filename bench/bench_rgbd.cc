// Benchmark suite "rgbd": the RGB-D fit (METHOD §3) per frame on a rendered
// talking-head sequence with known parameters: time per frame (cold first
// frame, then warm-started), 3D reconstruction accuracy and the head position
// error, at several depth-noise levels.
#include <opencv2/core.hpp>
#include <random>

#include "bench/bench.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/synthetic_motion.h"
#include "common/tracking/rgbd_fitter.h"

namespace headcast::bench {

nlohmann::json RunRgbdSuite(const BenchOptions& options) {
  const HeadModel model = MakeBuiltinHead();
  const int frames = std::max(2, options.repeats);
  const PinholeCamera camera = PinholeCamera::FromFovY(640, 480, 45);
  const cv::Mat albedo = AlbedoTexture(model);
  SyntheticMotionOptions motion;
  motion.distance = 0.55;
  nlohmann::json out;
  out["suite"] = "rgbd";
  out["what"] = "RgbdFitter::Fit per frame, 640x480, built-in head, landmarks = projected model landmarks + 1 px "
                "noise, wall at 1.4 m; identity frozen after the first frame; ms on this machine";
  out["frames"] = frames;
  for (double noise_mm : {0.0, 1.0}) {
    RgbdFitOptions calibrating, frozen;
    frozen.fit_shape = false;
    RgbdFitter first(model, calibrating), fitter(model, frozen);
    std::mt19937 rng(3);
    std::normal_distribution<double> px(0, 1.0);
    SampleStats ms, accuracy_mm, position_mm;
    double cold_ms = 0;
    RgbdFitResult last;
    for (int i = 0; i < frames; ++i) {
      const FrameParams f = SyntheticTalkingHead(model, i, motion);
      HeadModelOutput posed;
      model.Forward(model.MakeIdentity(Eigen::VectorXd::Zero(model.num_shape())), f.expression.cast<double>(),
                    f.HeadPose(), &posed);
      const HeadRender r = RenderHead(model, posed.vertices, f.CamFromHead(), camera, albedo);
      cv::Mat depth = r.depth.clone();
      depth.setTo(1.4f, r.mask == 0);
      if (noise_mm > 0) {
        cv::Mat n(depth.size(), CV_32F);
        cv::randn(n, 0, noise_mm * 1e-3);
        depth += n;
      }
      Landmarks2d l;
      for (int k = 0; k < kNumLandmarks; ++k)
        l[k] = camera.Project(f.CamFromHead().Apply(posed.landmarks.row(k).cast<double>().transpose())) +
               Eigen::Vector2d(px(rng), px(rng));
      Stopwatch watch;
      const RgbdFitResult fit = i == 0 ? first.Fit(l, depth, camera) : fitter.Fit(l, depth, camera, &last);
      const double t = watch.ElapsedMs();
      if (!fit.ok) throw std::runtime_error("rgbd: frame " + std::to_string(i) + ": " + fit.problem);
      if (i == 0) {
        cold_ms = t;
        fitter.SetIdentity(fit.params.shape);
      } else {
        ms.Add(t);
      }
      accuracy_mm.Add(1e3 * fit.accuracy_m);
      position_mm.Add(1e3 * (fit.translation - f.CamFromHead().translation).norm());
      last = fit;
    }
    const std::string key = "noise_" + std::to_string(static_cast<int>(noise_mm)) + "mm";
    out[key] = {{"ms_per_frame_median", ms.Median()},
                {"ms_per_frame_p95", ms.Percentile(95)},
                {"first_frame_ms", cold_ms},
                {"accuracy_mm_median", accuracy_mm.Median()},
                {"head_position_error_mm_median", position_mm.Median()}};
  }
  return out;
}

}  // namespace headcast::bench
