// Texture tau and spherical-harmonic light lambda of a subject (METHOD §2 and
// §3, the photometric term): with the geometry fitted, every head pixel is
// albedo(tau) * irradiance(lambda, normal), linear in tau for fixed light and
// linear in lambda for fixed albedo, so the two are solved in turn by linear
// least squares over the pixels of a few frames, through the rasteriser.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "common/core/camera.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/raster/shading.h"

namespace headcast {

struct AppearanceSample {
  cv::Mat bgr;         // the frame, 8-bit BGR
  cv::Mat mask;        // optional CV_8U head mask: only pixels inside count (empty: the model's silhouette)
  FrameParams params;  // fitted expression, jaw, cam_from_head
  PinholeCamera camera;
};

struct AppearanceFitOptions {
  int alternations = 300;            // light, texture, light, ... at most (stops when the error settles)
  double texture_prior = 1e-3;       // weight of |tau|^2 against mean squared pixel error (0..1 intensities)
  int max_pixels_per_frame = 20000;  // pixels used per frame at most (evenly subsampled)
  int border_px = 2;                 // silhouette pixels left out (they mix head and background)
  void Check() const;
};

struct AppearanceFit {
  bool ok = false;
  std::string problem;
  Eigen::VectorXd texture;  // tau (empty when the model has no texture model)
  ShLighting light{};       // lambda
  double rms = 0;           // RGB error over the pixels used, 0..1 intensities
  int pixels = 0;
};

AppearanceFit FitAppearance(const HeadModel& model, const Eigen::VectorXd& shape,
                            const std::vector<AppearanceSample>& samples, const AppearanceFitOptions& options = {});

}  // namespace headcast
