// Two-sided smoothing of a fitted track's head placement, for offline
// tracks (prep): every frame is fitted before any is smoothed.
#pragma once

#include <vector>

#include "common/headmodel/params.h"

namespace headcast {

// Each frame's cam_from_head becomes the Gaussian-weighted mean of its
// neighbours' (sigma in frames, by sequence number, out to 3 sigma): the
// translations averaged, the rotations averaged about the frame's own. The
// fit moves the whole head with the landmarks' frame-to-frame noise, and with
// it the outline the masks are cut with and the avatar is drawn at, against
// hair that did not move. Expression, jaw and eyes are left as fitted (blinks
// and lips are fast). sigma_frames 0 leaves the track as it is.
void SmoothHeadPlacement(double sigma_frames, std::vector<FrameParams>* frames);

}  // namespace headcast
