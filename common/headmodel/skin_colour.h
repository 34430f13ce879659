// The colour of a face's skin as a picture shows it: what the sender measures
// on the camera's frame and the receiver on its avatar's picture, so that the
// avatar follows the camera's exposure, white balance and the light on the
// face (a network conditioned on expression and pose cannot know them).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <optional>

#include "common/headmodel/head_model.h"

namespace headcast {

// The pixels of a picture of `size` inside the cheeks (between the jaw line,
// the lower lids, the nose's wings and the mouth's corners), the nose and the
// chin, as dlib's 68 `landmarks` (pixels) lay them out: skin in every
// expression, away from the eyes, brows, lips and hair. CV_8U, 255 inside.
cv::Mat SkinRegion(const Landmarks2d& landmarks, cv::Size size);

// The median R, G and B (0..1) of `image_bgr`'s (CV_8UC3) skin region; none
// when fewer than `min_pixels` of it lie in the picture or a landmark is not finite.
std::optional<Eigen::Vector3f> SkinColour(const cv::Mat& image_bgr, const Landmarks2d& landmarks, int min_pixels = 50);

}  // namespace headcast
