#include "common/tracking/outline_hold.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/core/median.h"
#include "common/core/options.h"
#include "common/tracking/rigid_vertex.h"

namespace headcast {

void OutlineHoldOptions::Check() const {
  OptionsCheck c("OutlineHoldOptions");
  c.InRange("weight", weight, 0.0, 100.0).InRange("columns", columns, 1, 256).InRange("span", span, 0.05, 1.0);
  c.InRange("max_offset", max_offset, 0.0005, 0.05);
  c.ThrowIfErrors();
}

nlohmann::json OutlineHoldOptions::ToJson() const {
  return {{"weight", weight}, {"columns", columns}, {"span", span}, {"max_offset", max_offset}};
}

std::vector<int> MaskTopRows(const cv::Mat& mask) {
  CV_Assert(mask.type() == CV_8U);
  std::vector<int> top(static_cast<size_t>(mask.cols), -1);
  int unset = mask.cols;
  for (int y = 0; y < mask.rows && unset > 0; ++y) {
    const uint8_t* row = mask.ptr<uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x)
      if (row[x] && top[x] < 0) {
        top[x] = y;
        --unset;
      }
  }
  return top;
}

OutlineHold::OutlineHold(const HeadModel& model, const Eigen::VectorXd& shape, const OutlineHoldOptions& options)
    : options_(options),
      reference_(std::numeric_limits<double>::quiet_NaN()),
      observed_median_(std::numeric_limits<double>::quiet_NaN()),
      observed_spread_(std::numeric_limits<double>::quiet_NaN()) {
  options.Check();
  const HeadIdentity identity = model.MakeIdentity(shape);
  // Above the brows at rest (the brows' highest landmark plus a centimetre):
  // the skull's top, never the face.
  const HeadModelOutput rest = model.Forward(HeadModelParams{});
  const double brow_y = rest.landmarks.middleRows(17, 10).col(1).maxCoeff() + 0.01;
  for (int v = 0; v < model.num_vertices(); ++v) {
    const Eigen::Vector3d p = identity.v_shaped.segment<3>(3 * v).cast<double>();
    if (p.y() >= brow_y && MovesOnlyWithTheSkull(model, v)) skull_.push_back(p);
  }
}

std::vector<OutlineHold::Column> OutlineHold::TopColumns(const std::vector<int>& mask_top, const FrameParams& frame,
                                                         const PinholeCamera& camera) const {
  std::vector<Column> columns;
  if (skull_.empty()) return columns;
  const RigidTransform cam_from_head = frame.CamFromHead();
  std::vector<Eigen::Vector2d> px(skull_.size());
  std::vector<double> depth(skull_.size());
  double u_min = std::numeric_limits<double>::infinity(), u_max = -u_min;
  for (size_t i = 0; i < skull_.size(); ++i) {
    const Eigen::Vector3d x = cam_from_head.Apply(skull_[i]);
    if (!(x.z() > 1e-3)) return columns;
    depth[i] = x.z();
    px[i] = camera.Project(x);
    u_min = std::min(u_min, px[i].x());
    u_max = std::max(u_max, px[i].x());
  }
  // The middle of the skull's projected width, cut into equal columns; in
  // each the skull's highest point is its silhouette there.
  const double mid = 0.5 * (u_min + u_max), half = 0.5 * options_.span * (u_max - u_min);
  const double width = 2 * half / options_.columns;
  if (!(width > 0)) return columns;
  std::vector<int> best(static_cast<size_t>(options_.columns), -1);
  for (size_t i = 0; i < skull_.size(); ++i) {
    const int c = static_cast<int>(std::floor((px[i].x() - (mid - half)) / width));
    if (c < 0 || c >= options_.columns) continue;
    if (best[c] < 0 || px[i].y() < px[best[c]].y()) best[c] = static_cast<int>(i);
  }
  for (int i : best) {
    if (i < 0) continue;
    Column col;
    col.head = skull_[i];
    col.pixel = px[i];
    col.metres_per_px = depth[i] / camera.fy;
    const long x = std::lround(px[i].x());
    if (x >= 0 && x < static_cast<long>(mask_top.size())) col.mask_top = mask_top[x];
    // A mask that reaches the picture's top row does not show where the hair ends.
    if (col.mask_top <= 0) col.mask_top = -1;
    columns.push_back(col);
  }
  return columns;
}

bool OutlineHold::Observe(const std::vector<int>& mask_top, const FrameParams& frame, const PinholeCamera& camera) {
  std::vector<double> offsets;
  for (const Column& c : TopColumns(mask_top, frame, camera))
    if (c.mask_top >= 0) offsets.push_back((c.pixel.y() - c.mask_top) * c.metres_per_px);
  if (offsets.empty()) return false;
  seen_.push_back(MedianInPlace(offsets));
  return true;
}

bool OutlineHold::Reference(int min_frames) {
  const double none = std::numeric_limits<double>::quiet_NaN();
  const bool enough = static_cast<int>(seen_.size()) >= std::max(min_frames, 1);
  observed_median_ = enough ? Median(seen_) : none;
  observed_spread_ = none;
  if (enough) {
    for (double& v : seen_) v = std::abs(v - observed_median_);
    observed_spread_ = Median(seen_);
  }
  seen_.clear();
  const bool usable = enough && observed_median_ >= kLowestThickness;
  reference_ = usable ? observed_median_ : none;
  return usable;
}

RigidObservations OutlineHold::Observations(const std::vector<int>& mask_top, const FrameParams& frame,
                                            const PinholeCamera& camera) const {
  RigidObservations o;
  if (std::isnan(reference_)) return o;
  for (const Column& c : TopColumns(mask_top, frame, camera)) {
    if (c.mask_top < 0) continue;
    const double offset = (c.pixel.y() - c.mask_top) * c.metres_per_px;
    if (std::abs(offset - reference_) > options_.max_offset) continue;
    // Held in its row only: the column's top point may slide along the
    // silhouette, so its x is where the pose puts it.
    o.head.push_back(c.head);
    o.observed.emplace_back(c.pixel.x(), c.mask_top + reference_ / c.metres_per_px);
    o.weight.push_back(options_.weight);
  }
  return o;
}

}  // namespace headcast
