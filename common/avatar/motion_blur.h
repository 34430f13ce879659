// The camera's exposure smears what moves while the shutter is open: a head
// that turns between two frames is blurred along its image motion in the
// frame the camera writes. The avatar draws a sharp head at one instant; with
// AvatarConfig::motion_blur it draws each frame averaged over the motion the
// head made since the frame before, scaled by the exposure. Trained so, its
// networks are shown the blur they are compared with instead of having to
// learn an average of sharp and smeared pictures; the receiver smears a moving
// head as the person's camera would have, and leaves a still one sharp.
#pragma once

#include <torch/torch.h>

#include <array>
#include <optional>

#include "common/core/camera.h"
#include "common/raster/rasterizer.h"

namespace headcast {

// The head's image motion over one frame interval, an affine field in pixels:
// at pixel (x, y) (centres at integers) the picture moved by
// (a[0] x + a[1] y + a[2], a[3] x + a[4] y + a[5]).
struct ImageMotion {
  std::array<double, 6> a{};
  Eigen::Vector2d At(double x, double y) const { return {a[0] * x + a[1] * y + a[2], a[3] * x + a[4] * y + a[5]}; }
  // The largest displacement at the corners of a width x height picture (an
  // affine field is largest at a corner).
  double Largest(int width, int height) const;
};

// The affine field that best moves the posed vertices of the earlier frame
// onto this frame's, both in the camera frame, through `camera` (least
// squares over every `stride`-th vertex that lies in front of the camera and
// inside the picture in both frames), divided by `frames` between the two.
// None when fewer than 20 vertices qualify or the vertex counts differ.
std::optional<ImageMotion> MeasureImageMotion(const RasterVertices& earlier, const RasterVertices& now,
                                              const PinholeCamera& camera, int frames = 1, int stride = 7);

// (B, C, H, W) -> the mean of the picture sampled along the motion, from
// -exposure / 2 to +exposure / 2 of it, with taps no more than half a pixel
// apart (at most kMaxMotionBlurTaps; edges repeat). Differentiable. Returns
// `image` itself when the exposure's smear is under a quarter of a pixel
// everywhere: a still head costs nothing.
// `exposure` a double, or a 0-dim tensor that may be learnt (the taps' spacing follows its value).
inline constexpr int kMaxMotionBlurTaps = 9;
torch::Tensor BlurAlongMotion(const torch::Tensor& image, const ImageMotion& motion, double exposure);
torch::Tensor BlurAlongMotion(const torch::Tensor& image, const ImageMotion& motion, const torch::Tensor& exposure);

}  // namespace headcast
