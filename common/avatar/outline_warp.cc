#include "common/avatar/outline_warp.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "common/core/options.h"

namespace headcast {

void OutlineWarpOptions::Check() const {
  OptionsCheck c("OutlineWarpOptions");
  c.InRange("ramp_px", ramp_px, 0.5, 1000.0).InRange("max_shift_px", max_shift_px, 0.0, 1000.0);
  c.ThrowIfErrors();
}

namespace {

// Piecewise linear through the bin centres; beyond the end centres
// `beyond` (nothing: the end values held) is reached one bin width further.
double OverBins(const std::vector<float>& values, const OutlineOptions& o, double angle, std::optional<double> beyond) {
  const int n = static_cast<int>(values.size());
  const double width = OutlineBinWidth(o);
  const double u = angle / width - 0.5;  // bin centres at u = 0 .. n - 1
  if (u <= 0) return beyond ? (u <= -1 ? *beyond : *beyond + (values[0] - *beyond) * (u + 1)) : values[0];
  if (u >= n - 1) {
    const double past = u - (n - 1);
    return beyond ? (past >= 1 ? *beyond : values[n - 1] + (*beyond - values[n - 1]) * past) : values[n - 1];
  }
  const int k = static_cast<int>(u);
  const double f = u - k;
  return values[k] * (1 - f) + values[k + 1] * f;
}

}  // namespace

double OutlineShiftAt(const std::vector<float>& shift_px, const std::vector<float>& edge_px, const OutlineOptions& o,
                      const OutlineWarpOptions& warp, double angle, double r) {
  const double shift = OverBins(shift_px, o, angle, 0.0);
  if (shift == 0) return 0;
  const double edge = OverBins(edge_px, o, angle, std::nullopt);
  return shift * std::clamp((r - (edge - warp.ramp_px)) / warp.ramp_px, 0.0, 1.0);
}

bool WarpToOutline(const std::vector<float>& target_mm, const OutlineFrame& frame, const OutlineOptions& o,
                   const OutlineWarpOptions& warp, torch::Tensor* image, torch::Tensor* coverage) {
  warp.Check();
  if (static_cast<int>(target_mm.size()) != o.bins)
    throw std::invalid_argument("WarpToOutline: " + std::to_string(target_mm.size()) + " outline values for " +
                                std::to_string(o.bins) + " bins");
  if (!(frame.px_per_mm > 0) || !frame.centre_px.allFinite()) return false;
  const torch::Tensor cov = coverage->detach().to(torch::kFloat32).contiguous();
  const int64_t height = cov.size(2), width = cov.size(3);
  const cv::Mat cov_mat(static_cast<int>(height), static_cast<int>(width), CV_32F, cov.data_ptr<float>());
  const std::vector<float> drawn = MeasureOutlinePx(cov_mat, frame, o);
  // Per bin: how far out the avatar's edge lies beyond the measured one, and
  // where the edge is (the measured one; the avatar's where it is unknown).
  std::vector<float> shift(o.bins, 0.f), edge(o.bins, 0.f);
  bool moves = false;
  for (int k = 0; k < o.bins; ++k) {
    const bool known = target_mm[k] != kOutlineUnknown && drawn[k] != kOutlineUnknown;
    edge[k] = known ? static_cast<float>(target_mm[k] * frame.px_per_mm) : drawn[k];
    if (!known) continue;
    shift[k] =
        std::clamp(drawn[k] - edge[k], static_cast<float>(-warp.max_shift_px), static_cast<float>(warp.max_shift_px));
    moves = moves || std::abs(shift[k]) > 0.05f;
  }
  if (!moves) return false;
  // The sampling grid, normalised as grid_sample's (align_corners false),
  // over the rows that may move: above the head point, and below it only the
  // end arcs' fade, within one arc's angle of the horizontal.
  const double cx = frame.centre_px.x(), cy = frame.centre_px.y();
  const double reach = std::hypot(static_cast<double>(width), static_cast<double>(height));
  const int64_t rows =
      std::clamp<int64_t>(static_cast<int64_t>(std::floor(cy + reach * std::sin(OutlineBinWidth(o)))) + 2, 0, height);
  if (rows == 0) return false;
  std::vector<float> grid(static_cast<size_t>(rows * width * 2));
  for (int64_t y = 0; y < rows; ++y)
    for (int64_t x = 0; x < width; ++x) {
      const double dx = x - cx, up = cy - y, r = std::hypot(dx, up);
      double angle = std::atan2(up, dx);
      if (angle < -M_PI / 2) angle += 2 * M_PI;  // the arcs run 0..pi: below the centre is either side's beyond
      const double s = r > 1e-9 ? OutlineShiftAt(shift, edge, o, warp, angle, r) / r : 0;
      float* g = &grid[static_cast<size_t>((y * width + x) * 2)];
      g[0] = static_cast<float>((2 * (x + dx * s) + 1) / width - 1);
      g[1] = static_cast<float>((2 * (y - up * s) + 1) / height - 1);
    }
  const torch::Tensor grid_t = torch::from_blob(grid.data(), {1, rows, width, 2}, torch::kFloat32);
  const int64_t channels = image->size(1);
  namespace F = torch::nn::functional;
  const torch::Tensor both = torch::cat({*image, *coverage}, 1);
  torch::Tensor moved = F::grid_sample(
      both, grid_t.to(image->dtype()),
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
  if (rows < height) moved = torch::cat({moved, both.narrow(2, rows, height - rows)}, 2);
  *image = moved.narrow(1, 0, channels);
  *coverage = moved.narrow(1, channels, 1);
  return true;
}

}  // namespace headcast
