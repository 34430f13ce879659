// GrabCut (Rother et al. 2004), the head masks' segmentation (HeadMask): a
// minimum cut of the energy cv::grabCut minimises (a pixel pays the negative
// log-likelihood of its colour under the side's colour mixture; neighbours of
// like colour pay to be split) with given colour models — a live sender's,
// carried from the frames that learn them (HeadMaskOptions::refit_every) —
// and the models' learning.
//
// cv::grabCut builds a graph vertex for every pixel — the certain background
// and head too, which can never change side. Here only the undecided pixels
// are vertices (a certain neighbour's link is folded into the pixel's own
// terminal weight): the same cut for a fraction of the work. Learning is
// cv::grabCut's, with these cuts; its masks come out as cv::grabCut's.
#pragma once

#include <opencv2/core.hpp>

namespace headcast {

// `labels`: CV_8U of cv::GC_BGD / GC_FGD / GC_PR_BGD / GC_PR_FGD, the size of
// `bgr` (CV_8UC3). Every probable pixel is set to the side the cut puts it on;
// the certain ones stay. `background` / `foreground`: colour models in
// cv::grabCut's layout (1×65 CV_64F: five weights, five means, five 3×3
// covariances), as a learning cv::grabCut leaves them. Throws
// std::invalid_argument on images, labels or models of another type or size,
// a model whose weights are not a distribution or whose covariances are
// singular.
void CutWithColourModels(const cv::Mat& bgr, cv::Mat& labels, const cv::Mat& background, const cv::Mat& foreground);

// Colour models learnt as cv::grabCut(GC_INIT_WITH_MASK) learns them: each
// side's pixels (certain and probable) clustered by k-means into five
// components, then `iterations` rounds of giving each pixel its side's
// likeliest component, refitting both mixtures and cutting with them (as
// CutWithColourModels). `labels` leaves with the last cut, `background` and
// `foreground` with the models (cv::grabCut's layout). Throws
// std::invalid_argument as CutWithColourModels, or when either side has
// fewer pixels than a mixture has components. `cut_last` false: the last
// round's cut, which changes only `labels`, is left out (a learner that
// keeps only the models); `labels` then leaves with the round before's.
void LearnColourModels(const cv::Mat& bgr, cv::Mat& labels, int iterations, cv::Mat* background, cv::Mat* foreground,
                       bool cut_last = true);

}  // namespace headcast
