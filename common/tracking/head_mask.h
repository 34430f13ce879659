// A head mask (face, hair, ears, neck) for training losses: GrabCut seeded by
// the 68 landmarks — the face hull is certain foreground, a head-shaped region
// around it (hair above, neck below) probable foreground, a ring around that
// probable background, the rest background.
#pragma once

#include <cmath>
#include <opencv2/core.hpp>

#include "common/tracking/head_fitter.h"

namespace headcast {

struct HeadMaskOptions {
  int iterations = 3;                         // GrabCut iterations
  int working_size = 200;                     // the head region is segmented at about this many pixels across (speed)
  double hair_height = 0.75;                  // probable hair above the brows, in face heights (brow to chin)
  double head_width = 1.35;                   // probable head width, in jaw widths
  double neck_height = 0.45;                  // probable neck below the chin, in face heights
  double turn_shift = 1.0, turn_widen = 1.5;  // how far the region follows the back of a turned head
  // A face seen from above or below looks shorter than it is: its height is
  // taken as at least this many jaw widths (about a frontal face's ratio).
  double min_face_height = 0.9;
  // Beyond the probable head, a ring this wide (in face heights) is probable
  // background rather than certain: hair the region misses can still join the
  // head instead of teaching GrabCut that hair is background.
  double background_ring = 0.3;
  // With colour models carried from frame to frame (HeadMaskModels): a frame
  // learns its own models (`iterations` of GrabCut) only every this many
  // frames; the others cut once with the last ones, unchanged. A head and
  // what is behind it keep their colours over a few frames, and the models
  // are what GrabCut's iterations spend most of their time refining.
  int refit_every = 1;
  // A frame cut with carried models of which only the rows above a given one
  // are wanted (HeadMask's `wanted_above_y`) is segmented down to that row
  // and this much of the region's height further (the cut there still feels
  // the rows beneath it); most of GrabCut's time scales with the pixels.
  double wanted_margin = 0.1;
  // A frame cut with carried models right after another one (HeadMaskModels'
  // last mask) is segmented only within this many working pixels of that
  // mask's outline, moved with the face: further inside it is head, further
  // out background. A head's outline moves a few pixels between frames, and
  // the minimum cut's time scales with the pixels it may move. 0: the whole
  // region, every frame.
  int band = 0;
  void Check() const;
};

// GrabCut's colour models of the head and of what is around it, learnt on one
// frame and used on the next ones (HeadMaskOptions::refit_every).
struct HeadMaskModels {
  cv::Mat background, foreground;  // cv::grabCut's
  int frames_since_fit = 0;
  // The last mask cut with them (the frame's size; empty: none yet) and the
  // centre of the landmarks it was seeded by: where the next frame's outline
  // is looked for (HeadMaskOptions::band).
  cv::Mat last_mask;
  cv::Point2f last_centre;
};

// CV_8U, 255 on the head. Throws std::invalid_argument on an empty image or
// non-finite landmarks. With `carried`, the colour models are learnt or
// reused as HeadMaskOptions::refit_every says (a sequence of frames: a live
// sender); without, every mask learns its own. `wanted_above_y` (pixels of
// `bgr`): only the mask above that row is wanted; a frame cut with carried
// models is then segmented only there (HeadMaskOptions::wanted_margin), and
// below it the mask is the seeds' probable head. A frame that learns its
// models segments the whole region: they must know the face and the neck.
// A mask cut with carried models is kept in `carried` (its last_mask): the
// next frame cut with them looks for its outline near it
// (HeadMaskOptions::band). A learning leaves none: the first cut with new
// models is whole.
cv::Mat HeadMask(const cv::Mat& bgr, const Landmarks2d& landmarks, const HeadMaskOptions& options = {},
                 HeadMaskModels* carried = nullptr, double wanted_above_y = HUGE_VAL);

// The colour models HeadMask would learn on this frame (and carry), without
// its mask: the learning's last cut, which changes only the mask, is left
// out. Throws std::invalid_argument as HeadMask, or when the head's region is
// too small to learn on (where HeadMask gives an empty mask).
HeadMaskModels LearnHeadMaskModels(const cv::Mat& bgr, const Landmarks2d& landmarks,
                                   const HeadMaskOptions& options = {});

// Intersection over union of two binary masks (non-zero = inside).
double MaskIou(const cv::Mat& a, const cv::Mat& b);

}  // namespace headcast
