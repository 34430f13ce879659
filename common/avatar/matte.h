// The geometry of a training mask: where the picture may show the head, as a
// function of the fitted head alone (its silhouette and landmarks). The
// dataset cuts its masks with these rules, and an avatar with a bounded matte
// keeps its coverage inside the same region, so the outline the receiver
// draws below the jaw and beside the cheeks is the one it was trained on
// rather than a blur the networks must learn.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "common/headmodel/head_model.h"

namespace headcast {

// The rules a dataset's masks were cut with (PrepOptions holds the same four).
struct MatteRules {
  // Above the eye line the mask may reach this fraction of the image edge
  // beyond the model's silhouette (hair); below it, `side_margin` (cheeks, ears).
  double hair_margin = 0.08;
  double side_margin = 0.02;
  bool keep_neck = false;  // false: nothing below the jaw line (landmarks 0..16)
  // The fitted skull above the brows is head (FillSkull). Rules read from a
  // file without the key were not (masks cut before it existed).
  bool fill_skull = true;
  void Check() const;
  nlohmann::json ToJson() const;
  static MatteRules FromJson(const nlohmann::json& j);  // checks
  bool operator==(const MatteRules& o) const {
    return hair_margin == o.hair_margin && side_margin == o.side_margin && keep_neck == o.keep_neck &&
           fill_skull == o.fill_skull;
  }
};

// Clears `mask` (CV_8U) below the jaw line given by landmarks 0..16 (pixels):
// under the chin and between the jaw's ends, along the face's downward
// direction (chin minus brows) to beyond the image. GrabCut takes the neck in
// some frames and not in others; a target that comes and goes with the
// shirt's colour cannot be learnt, one that stops at the jaw can.
void ClearBelowJawLine(const Landmarks2d& landmarks, cv::Mat* mask);

// Keeps the connected piece of `mask` (CV_8U, 0 or 255; 8-connected) that
// holds the nose tip (landmark 30) and clears the rest; leaves a mask without
// it alone. The jaw line's cut leaves the model's shoulders beyond the jaw's
// ends apart from the head: GrabCut takes the skin there in some frames, and an
// avatar trained on such masks drew skin-coloured fragments below its ears.
inline constexpr int kNoseTipLandmark = 30;
void KeepHeadPiece(const Landmarks2d& landmarks, cv::Mat* mask);

// `mask` (CV_8U, 0 or 255) dilated by the elliptical structuring element of
// radius `radius` (cv::getStructuringElement(MORPH_ELLIPSE, 2r+1 square)):
// the same pixels as cv::dilate, which walks every point of the element for
// every pixel (the hair margin's element has over a thousand); here each
// element row is a run, so a row's distance to its nearest set pixel answers
// it with one comparison per element row.
// Radii up to this one go to cv::dilate (the rows' distances cost more than a
// small element's walk).
inline constexpr int kDilateEllipseOwnRadius = 8;
cv::Mat DilateEllipse(const cv::Mat& mask, int radius);

// The head mask of frame `centre` steadied over time: each mask of the frames
// within `radius` frame numbers of it is moved onto it by the affine map that
// carries that frame's head points onto this frame's, the moved masks are
// averaged with weights falling linearly with the distance in frames
// (radius + 1 - |d|), and the average is cut at half. GrabCut draws the
// outline anew on every frame, a pixel or so either way where hair meets a
// wall of its highlights' colour; an avatar can learn where the head's
// outline is, not where one frame's segmentation happened to draw it.
// masks: CV_8U (0 or 255), one size; points[i]: 2 x P, the same P points
// that move with the skull, projected into frame i; frame_numbers ascending.
// radius 0, or no neighbour, returns the mask itself. Throws on mismatched sizes.
cv::Mat SteadyMask(const std::vector<cv::Mat>& masks, const std::vector<Eigen::Matrix2Xd>& points,
                   const std::vector<int64_t>& frame_numbers, size_t centre, int radius);

// Where a training mask may reach: `silhouette` (CV_8U, the fitted model
// rasterised) grown by `hair_px` above the eye line (landmarks 36..47; the
// face's up direction is brows minus chin) and by `side_px` below it.
cv::Mat MaskReach(const cv::Mat& silhouette, const Landmarks2d& landmarks, int hair_px, int side_px);

// Fills the notches GrabCut cuts into the top of the hair where a highlight
// matches the wall's colour: above the brow line (landmarks 17..26) the mask
// (CV_8U) becomes its convex hull there. The top of a head is convex; below
// the brows the ears make it not so, and the mask is left alone.
void FillHairNotches(const Landmarks2d& landmarks, cv::Mat* mask);

// Adds to `mask` (CV_8U) the silhouette above the brow line (landmarks
// 17..26), shrunk by kSkullInset face heights (brows to chin): whatever
// covers the skull (hair, skin, a hat) is head, never background. GrabCut
// may take dark hair before a dark wall for the wall; its mask then stops at
// the hairline, and an avatar trained on it is drawn bald. The inset keeps a
// fit a little wider than a short-haired head from adding the wall beside
// its temples.
inline constexpr double kSkullInset = 0.04;
void FillSkull(const cv::Mat& silhouette, const Landmarks2d& landmarks, cv::Mat* mask);

// A training target's mask (the dataset's and `headcast-train compare`'s):
// the tracker's GrabCut mask (CV_8U, square, 0 or 255) with its hair notches
// filled, the skull added (rules.fill_skull), within MatteBound.
cv::Mat CutTrainingMask(const cv::Mat& grabcut, const cv::Mat& silhouette, const Landmarks2d& landmarks,
                        const MatteRules& rules);

// The region (CV_8U, 255 inside) a mask cut by `rules` may cover for a head
// with this silhouette (CV_8U, square) and these landmarks: MaskReach with the
// margins scaled to the image, minus what lies below the jaw line, then only
// the head's piece (KeepHeadPiece).
cv::Mat MatteBound(const cv::Mat& silhouette, const Landmarks2d& landmarks, const MatteRules& rules);

// What is always covered: `silhouette` eroded by `erosion` times its edge, within `bound` (CV_8U each).
cv::Mat MatteCore(const cv::Mat& silhouette, const cv::Mat& bound, double erosion);

}  // namespace headcast
