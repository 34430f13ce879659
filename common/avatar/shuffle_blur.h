// The 2D renderer's upsampling tail for inference, in one pass over
// channels-last images.
#pragma once

#include <cstdint>

namespace headcast {

// A channels-last image of floats: pixel (y, x), channel c at
// data[y * row_stride + x * pixel_stride + c] (a slice of a larger picture is
// fine: the strides are the picture's).
struct ChannelsLastView {
  const float* data = nullptr;
  int64_t height = 0, width = 0, channels = 0;
  int64_t row_stride = 0, pixel_stride = 0;
};

// What the upsampling block does after its two branches: the leaky ReLUs of
// both (`slope`), their sum, PixelShuffle x2 (4 C channels -> C at twice the
// size: channel 4 c + 2 i + j goes to sub-pixel (i, j) of channel c) and the
// 3x3 binomial blur ([1 2 1] x [1 2 1] / 16, the picture's edge pixels
// repeated beyond it).
//
// `global` and `local` hold the branches' outputs at the same input pixels:
// rows from `first_row`, columns from `first_column` of an input picture half
// the output's `picture_height` x `picture_width`. They must reach one
// output pixel beyond the window on each side inside the picture (the blur's
// reach). Writes output pixels [y0, y1) x [x0, x1) to `out`, channels-last and
// contiguous ((y1 - y0) x (x1 - x0) x C). The same values as the layers one
// after the other, up to float rounding. Runs on libtorch's intra-op threads.
struct ShuffleBlurWindow {
  int64_t first_row = 0, first_column = 0;  // of the branches' pixels in the input picture
  int64_t picture_height = 0, picture_width = 0;
  int64_t y0 = 0, y1 = 0, x0 = 0, x1 = 0;  // the output window
};
void ShuffleBlur(const ChannelsLastView& global, const ChannelsLastView& local, float slope,
                 const ShuffleBlurWindow& window, float* out);

}  // namespace headcast
