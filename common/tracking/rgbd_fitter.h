// RgbdFitter: the head model fitted to one RGB-D frame (METHOD §3, the
// thesis's contribution). 2D landmarks + aligned metric depth give 3D
// landmarks and a face point cloud; then
//   block 1: pose (and jaw) from the 3D landmarks,
//   block 2: 3D landmarks + point-to-mesh distances (closest points on
//            the model, exact) over shape, expression, jaw and pose,
//   block 3: the point-to-mesh term alone over shape.
// The 3D reconstruction accuracy is sqrt of the final mean squared
// point-to-mesh distance, metres.
//
// Stereo depth at the face border often lies on the background, so contour
// landmarks (0..16) get background depth: they are left out of block 1, and
// afterwards kept only when their depth agrees with the posed model; cloud
// points are limited to the landmarks' span and depth range and paired only
// within a distance gate, with surfaces facing the same way.
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "common/core/camera.h"
#include "common/headmodel/head_model.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

struct RgbdFitOptions {
  int num_expression = 0;  // expression components fitted (0: all the model has)
  bool fit_shape = true;   // false once the identity is calibrated (SetIdentity)
  // w1 (3D landmark term) and w2 (point-to-mesh term). Landmark depth is read
  // where the surface may turn (lips, eyelids), so the cloud leads.
  double landmark_weight = 0.1, point_weight = 1.0;
  double max_point_distance_m = 0.01;  // cloud points farther from the model are not paired
  double robust_scale_m = 0.002;       // Huber: quadratic below this, linear above
  int block2_rounds = 6, block3_rounds = 3;
  int warm_rounds = 2;  // block 2 rounds when warm-started from the previous frame
  // About this many depth points on the face: the pixel stride follows the
  // face's size in the image, so a closer face or a 2K camera costs no more.
  // Tracking (identity frozen) takes fewer: much faster for slightly more face
  // error. The identity is fitted once, over a few frames: it takes more
  // (bench/DEFAULTS.md).
  int cloud_points = 1200;
  int shape_cloud_points = 3000;       // when fit_shape
  double cloud_margin_m = 0.015;       // around the landmarks' image span
  double head_depth_m = 0.15;          // points this far behind the nearest landmark at most
  double contour_tolerance_m = 0.005;  // contour landmark depth against the posed model after block 1
  double contour_weight = 0.25;        // of a contour landmark against an inner one
  bool reject_background_contour = true;
  double shape_prior = 1e-9,
         expression_prior = 1e-8;  // m^2 per unit^2 per point: keeps unobserved components at zero
  // Tracking (the identity frozen): points solved in a few residual blocks,
  // the robust loss as weights fixed at each solve's start
  // (SolveSettings::batched). The rounds of closest points reweight anyway,
  // and a solve costs a fraction. The identity's fit keeps a block and a loss
  // per point: batched, its head position came out worse (bench rgbd).
  bool batched_solve = true;
  // The accuracy is measured on every n-th cloud point (an RMS over some
  // hundreds of points estimates it as well as over all, for less).
  int accuracy_every = 2;
  // Ceres threads of the identity's solves (tracking solves on one). 2: the
  // synchronous identity frames may take both cores; 1 when the identity is
  // fitted beside tracking (BackgroundIdentity), which keeps the other core.
  int shape_solve_threads = 2;
  int max_iterations = 30;      // per solve
  int warm_max_iterations = 8;  // per solve when warm-started
  void Check() const;
};

struct RgbdFitResult {
  bool ok = false;
  std::string problem;     // why not, when !ok
  HeadModelParams params;  // shape, expression, jaw (root zero: the placement is the rotation/translation below)
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // cam_from_head
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double accuracy_m = 0;       // sqrt(mean squared point-to-mesh distance) after the last block (sampled)
  double landmark_rmse_m = 0;  // 3D landmarks used, after the fit
  int cloud_points = 0, paired_points = 0 /* in the last round */, landmarks_3d = 0, contour_rejected = 0;
};

class RgbdFitter {
 public:
  RgbdFitter(const HeadModel& model, const RgbdFitOptions& options = {});
  ~RgbdFitter();
  // Identity used from now on (and frozen when fit_shape is false).
  void SetIdentity(const Eigen::VectorXd& shape);
  // `depth_m`: CV_32F metres aligned to the image the landmarks are in, 0 unknown.
  // `previous`: warm start from the last frame's result (skips the landmark pose initialisation).
  RgbdFitResult Fit(const Landmarks2d& landmarks, const cv::Mat& depth_m, const PinholeCamera& camera,
                    const RgbdFitResult* previous = nullptr);
  const RgbdFitOptions& options() const { return options_; }

 private:
  struct Impl;
  const HeadModel& model_;
  RgbdFitOptions options_;
  std::unique_ptr<Impl> impl_;
};

// The depth at a pixel: median of the valid values in a (2r+1)^2 window, 0 if none.
float DepthAt(const cv::Mat& depth_m, const Eigen::Vector2d& pixel, int radius = 2);

}  // namespace headcast
