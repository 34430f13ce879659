// The top of a head's outline (hair against the background) in a few numbers.
// The fitted head places the face, but the hair's edge moves against it from
// frame to frame (the fit slides up and down with expressions; hair moves);
// an avatar can only draw an average edge there. A sender has the frame: it
// measures where the edge is, in millimetres about a point of the head, and a
// receiver moves its avatar's edge there (common/avatar/outline_warp.h).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "common/core/camera.h"
#include "common/core/rigid_transform.h"

namespace headcast {

// The most arcs an outline may have (a value read from a peer or a file is checked against it).
inline constexpr int kMaxOutlineBins = 64;

// How the outline is described; sender and receiver must agree.
struct OutlineOptions {
  int bins = 12;             // arcs over the upper half of the picture (right, over the top, to the left)
  int rays_per_bin = 16;     // each arc's value is the median of this many rays
  double centre_y_m = 0.04;  // the rays start at this point of the head frame (0, y, 0), metres: above the eyes
  void Check() const;        // throws std::invalid_argument naming what is out of range
};

// Where the rays start in a picture and its scale there.
struct OutlineFrame {
  Eigen::Vector2d centre_px;  // the head point projected
  double px_per_mm = 0;       // at the head point's depth
  static OutlineFrame Of(const PinholeCamera& camera, const RigidTransform& cam_from_head,
                         const OutlineOptions& options);
};

// A bin's value when too few of its rays meet the head: unknown, not moved.
inline constexpr float kOutlineUnknown = 0.f;
// The largest outline radius a value may carry (a head is far smaller), mm.
inline constexpr float kMaxOutlineMm = 400.f;

// The angles (radians, counter-clockwise from the picture's right, up
// positive) of bin k's centre and its width.
double OutlineBinCentre(const OutlineOptions& options, int k);
double OutlineBinWidth(const OutlineOptions& options);

// Per bin, the median over its rays of the outermost radius at which `mask`
// (CV_8U: inside >= 128; CV_32F: inside >= 0.5, a soft coverage) is inside,
// in pixels (sub-pixel: the crossing is interpolated). kOutlineUnknown where
// fewer than half of a bin's rays meet the head. Throws std::invalid_argument
// on an empty mask or another type.
std::vector<float> MeasureOutlinePx(const cv::Mat& mask, const OutlineFrame& frame, const OutlineOptions& options);
// The same in millimetres at the head's depth: what travels.
std::vector<float> MeasureOutline(const cv::Mat& mask, const OutlineFrame& frame, const OutlineOptions& options);

// Whether `outline` can be a measured outline: finite, 0 (unknown) or within
// 0..kMaxOutlineMm. `why` names the first problem.
bool OutlineIsValid(const std::vector<float>& outline, std::string* why);

}  // namespace headcast
