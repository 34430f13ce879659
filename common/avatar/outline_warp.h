// The receiver's half of the outline (common/headmodel/head_outline.h): the
// avatar's picture moved so that the top of its outline lies where the
// sender measured the person's. Each arc's difference between the avatar's
// coverage and the measured outline moves the picture radially about the
// head point, fully beyond the measured outline and fading to nothing a ramp
// inside it, so the face stays where the mesh put it and only the hair's edge
// moves. Not learnt: it needs no training and works on any avatar with a matte.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "common/headmodel/head_outline.h"

namespace headcast {

// AvatarConfig::outline_ramp's receiver moves an arc by at most this share of the picture's height.
inline constexpr double kOutlineMaxShift = 0.04;

struct OutlineWarpOptions {
  double ramp_px = 20;       // the move fades to nothing this far inside the measured outline
  double max_shift_px = 10;  // an arc moves by at most this much (a measurement gone wrong cannot tear the picture)
  void Check() const;        // throws std::invalid_argument naming what is out of range
};

// The source radius offset (pixels; the picture at radius r is drawn from
// r + shift) at `angle` (radians as OutlineBinCentre's) and radius r, for arc
// differences `shift_px` (avatar's outline minus the target's, per bin) and
// the target outline `target_px` (per bin, kOutlineUnknown where unknown).
double OutlineShiftAt(const std::vector<float>& shift_px, const std::vector<float>& target_px,
                      const OutlineOptions& outline, const OutlineWarpOptions& warp, double angle, double r);

// Moves `image` (1, C, H, W) and `coverage` (1, 1, H, W; its outline is the
// avatar's) so that the coverage's outline meets `target_mm` (one value per
// bin of `outline`, mm; MeasureOutline's). Bins unknown on either side stay.
// Returns false, changing nothing, when nothing would move.
bool WarpToOutline(const std::vector<float>& target_mm, const OutlineFrame& frame, const OutlineOptions& outline,
                   const OutlineWarpOptions& warp, torch::Tensor* image, torch::Tensor* coverage);

}  // namespace headcast
