// The head's pitch held to the top of its hair's outline (offline tracks).
//
// Landmarks pin the face's plane, not how far the head is tipped about the
// eyes: a few degrees of pitch move the eyes, nose and mouth by a pixel and
// the crown by several, so a fit to landmarks (and to the face's grey levels,
// PhotometricAnchor) leaves the skull sliding up and down against the hair
// with the expression. Short hair sits on the skull: the distance from the
// skull's silhouette top to the top of the head mask (GrabCut's, made from the
// detected face, not the fit) is the hair's thickness, the same in every
// frame. Its median over the clip's fits is the reference; each frame is then
// fitted again with its skull's top points held that far below the mask's top
// in their columns.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "common/core/camera.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

struct OutlineHoldOptions {
  // Each held column's weight against a landmark when the frame is fitted
  // again (beside the photometric anchor's points); 0: off.
  double weight = 0;
  int columns = 12;   // columns held, spread over the middle of the skull's projected width
  double span = 0.4;  // that middle's share of the width
  // A column whose outline lies further than this from the reference (metres)
  // is not held: hair that moved, a hand, a mask that took the wall.
  double max_offset = 0.008;
  void Check() const;
  bool enabled() const { return weight > 0; }
  nlohmann::json ToJson() const;
};

// Per column of `mask` (CV_8U, non-zero: head) its first non-zero row; -1
// where the column has none.
std::vector<int> MaskTopRows(const cv::Mat& mask);

class OutlineHold {
 public:
  // The skull's points: vertices of the head shaped by `shape` above the
  // brows that no expression, the jaw or an eye moves.
  OutlineHold(const HeadModel& model, const Eigen::VectorXd& shape, const OutlineHoldOptions& options);

  // How far above the skull's silhouette top the mask's top lies in the held
  // columns at `frame`'s pose (median, metres at the skull's depth), kept for
  // Reference(); false when no column has both.
  bool Observe(const std::vector<int>& mask_top, const FrameParams& frame, const PinholeCamera& camera);
  // The median of the observations (the hair's thickness), which then clears
  // them; false, and no reference, with fewer than `min_frames` or a mask top
  // more than kLowestThickness below the skull's (the mask's region cut the
  // head there, so its top is not the hair's).
  bool Reference(int min_frames = 10);
  static constexpr double kLowestThickness = -0.005;
  void SetReference(double offset) { reference_ = offset; }
  double reference() const { return reference_; }              // NaN: none
  double observed_median() const { return observed_median_; }  // the last Reference()'s median; NaN: none
  // The last Reference()'s median absolute deviation of the frames' thickness
  // about that median (metres; NaN: none): how far the outline moves on the
  // skull over the clip (long hair that swings, a mask that takes the wall).
  double observed_spread() const { return observed_spread_; }

  // The skull's top point of each held column at `frame`'s pose, observed in
  // its own column at the row the reference puts it below the mask's top;
  // each weighted options.weight. Empty without a reference.
  RigidObservations Observations(const std::vector<int>& mask_top, const FrameParams& frame,
                                 const PinholeCamera& camera) const;

  const OutlineHoldOptions& options() const { return options_; }
  int num_points() const { return static_cast<int>(skull_.size()); }

 private:
  struct Column {
    Eigen::Vector3d head;   // the skull's top point in this column
    Eigen::Vector2d pixel;  // where the pose projects it
    double metres_per_px = 0;
    int mask_top = -1;  // the mask's first row at pixel.x(); -1: none
  };
  std::vector<Column> TopColumns(const std::vector<int>& mask_top, const FrameParams& frame,
                                 const PinholeCamera& camera) const;
  OutlineHoldOptions options_;
  std::vector<Eigen::Vector3d> skull_;
  std::vector<double> seen_;
  double reference_, observed_median_, observed_spread_;
};

}  // namespace headcast
