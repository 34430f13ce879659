// The head's placement held to its own appearance (offline tracks): points on
// the face above the mouth (forehead, brows, nose, temples, crown), their grey
// levels learnt over the whole clip at the first pass's fits, and each
// frame's cam_from_head aligned to them photometrically.
//
// Landmarks alone trade the head's position for expression: a smile or an
// open jaw moves the fitted head up and down against the hair, and the
// avatar's outline with it. A reference taken from one frame carries that
// frame's error into every later one (optical flow from a reference frame,
// `rigid_flow_weight`); the median over the whole clip's fits does not,
// because those errors come and go with the expression.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "common/core/camera.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/tracking/anchor_reference.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

// One frame's grey image for the anchor: float, 0..1, blurred by `blur_px`.
cv::Mat AnchorGray(const cv::Mat& bgr, double blur_px);

struct AnchorAlignment {
  bool ok = false;
  int points = 0;         // visible points with a reference
  double shift_px = 0;    // mean movement of those points' projections
  double rms_before = 0;  // grey-level rms over them (after the gain and bias fit)
  double rms_after = 0;
};

class PhotometricAnchor {
 public:
  // Points on the head shaped by `shape`, spread evenly by area over the
  // triangles facing forward at rest above the nose's base; none the jaw or
  // an eye joint carries. They move with the frame's expression.
  PhotometricAnchor(const HeadModel& model, const Eigen::VectorXd& shape, const PhotometricAnchorOptions& options);

  // Collects the grey levels `gray` (AnchorGray) shows at `frame`'s fit for
  // the points facing the camera; Reference() then takes their medians.
  void Observe(const cv::Mat& gray, const FrameParams& frame, const PinholeCamera& camera);
  // Per point the median of its observations, when it was seen in at least
  // `min_share` of the observed frames; clears the observations. Returns the
  // points with a reference.
  int Reference(double min_share = 0.2);
  // The references learnt elsewhere (an avatar's, made with these options and
  // this person's shape); throws std::invalid_argument when their count is
  // not this anchor's.
  void SetReference(const std::vector<double>& grey);
  AnchorReference Exported() const { return {options_, reference_}; }

  // Moves frame->cam_from_head so that the points' grey levels in `gray`
  // match their reference (a gain and bias per frame absorb the light).
  AnchorAlignment Align(const cv::Mat& gray, const PinholeCamera& camera, FrameParams* frame) const;
  // One frame anchored, the step the offline pass and the live tracker share:
  // the pose aligned (Align), then the frame fitted again by `fitter` (its
  // rigid_flow_weight the anchor's weight) to `landmarks` and `irises` with
  // fit_points aligned points holding the pose. *frame is left as it was when
  // the alignment fails or moves the points more than max_shift_iod eye
  // distances (`iod`, pixels; then *alignment is not ok) or the fit fails.
  // `more` holds the pose beside the aligned points (their own weights: the
  // hair's outline, OutlineHold). Returns whether the frame was fitted again.
  bool Refit(const cv::Mat& gray, const Landmarks2d& landmarks, const EyeIrises* irises, double iod,
             const PinholeCamera& camera, const HeadFitter& fitter, FrameParams* frame, AnchorAlignment* alignment,
             const RigidObservations* more = nullptr) const;
  // Up to `count` referenced points visible at `frame`'s pose, spread over
  // them, at its expression, with where that pose projects them: what
  // HeadFitter::Fit holds the pose to.
  RigidObservations Observations(const FrameParams& frame, const PinholeCamera& camera, int count) const;

  const PhotometricAnchorOptions& options() const { return options_; }
  int num_points() const { return static_cast<int>(points_.size()); }
  const std::vector<Eigen::Vector3d>& points() const { return points_; }
  const std::vector<double>& reference() const { return reference_; }  // NaN: none

 private:
  // Point i in the head frame at `frame`'s expression.
  Eigen::Vector3d At(int i, const FrameParams& frame) const;
  // Indices of the points facing a camera with this pose.
  std::vector<int> Visible(const FrameParams& frame, const PinholeCamera& camera) const;
  PhotometricAnchorOptions options_;
  std::vector<Eigen::Vector3d> points_, normals_;  // head frame, neutral expression
  std::vector<Eigen::MatrixXd> dirs_;              // per point: 3 x E, its motion per expression coefficient
  std::vector<double> reference_;
  std::vector<std::vector<float>> seen_;  // per point, its observations so far
  int observed_frames_ = 0;
};

}  // namespace headcast
