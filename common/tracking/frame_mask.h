// A live frame's head mask cut as prep cuts a training target's: the
// tracker's GrabCut mask on the whole frame, cropped to the square the
// avatar's training frames were cut from, then the matte's rules with the
// fitted head. What the sender measures the hair's outline on
// (common/headmodel/head_outline.h) is then the mask the avatar was taught
// and is scored against.
#pragma once

#include <opencv2/core.hpp>
#include <optional>

#include "common/avatar/matte.h"
#include "common/core/camera.h"
#include "common/headmodel/params.h"
#include "common/tracking/head_fitter.h"
#include "common/tracking/head_mask.h"

namespace headcast {

// A square of a frame and the camera of its crop.
struct FrameCrop {
  double x0 = 0, y0 = 0, side = 0;  // the frame's pixels
  int resolution = 0;               // the crop's edge, pixels
  PinholeCamera camera;             // of the crop (CropIntrinsics)
};

// The avatar's square (its camera contract's) in `camera`'s frames; nothing
// when their aspect is not the contract's (that frame shows another view).
std::optional<FrameCrop> ContractCrop(const CameraContract& contract, const PinholeCamera& camera, int resolution);

// The tracker's GrabCut head mask made on the whole frame (seeded by
// `face_landmarks`, pixels of the frame) and cut to `crop`: CV_8U,
// crop.resolution², 0 or 255. Throws std::invalid_argument on an empty frame
// or non-finite landmarks. `wanted_above_y` (pixels of the crop): only the
// mask above that row is wanted (HeadMask's).
cv::Mat CropGrabCutMask(const cv::Mat& bgr, const Landmarks2d& face_landmarks, const FrameCrop& crop,
                        const HeadMaskOptions& mask = {}, HeadMaskModels* carried = nullptr,
                        double wanted_above_y = HUGE_VAL);

// A training target's mask from a crop's GrabCut mask: the matte's rules with
// the fitted head (`posed` by `params`) seen through `crop_camera`, and its
// landmarks projected there (HeadFitter::Project).
cv::Mat CutCropMask(const cv::Mat& grabcut, const HeadModel& model, const HeadModelOutput& posed,
                    const Landmarks2d& fitted_landmarks, const FrameParams& params, const PinholeCamera& crop_camera,
                    const MatteRules& rules);

}  // namespace headcast
