#include "common/avatar/shuffle_blur.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace headcast {

namespace {

// Rows [begin, end) of the branches' pixels: their leaky sum, shuffled into
// `shuffled` (2 rows x 2 columns of C per input pixel). kChannels > 0: C known
// at compile time (the loops unrolled and vectorised).
template <int kChannels>
void ShuffleRows(const ChannelsLastView& global, const ChannelsLastView& local, float slope, int64_t channels,
                 int64_t begin, int64_t end, float* shuffled) {
  const int64_t c = kChannels > 0 ? kChannels : channels, c4 = 4 * c, columns = 2 * global.width;
  float fixed[kChannels > 0 ? 4 * kChannels : 1];
  std::vector<float> dynamic(kChannels > 0 ? 0 : c4);
  float* __restrict sum = kChannels > 0 ? fixed : dynamic.data();
  for (int64_t y = begin; y < end; ++y)
    for (int64_t x = 0; x < global.width; ++x) {
      const float* __restrict g = global.data + y * global.row_stride + x * global.pixel_stride;
      const float* __restrict l = local.data + y * local.row_stride + x * local.pixel_stride;
      for (int64_t k = 0; k < c4; ++k) {
        // LeakyReLU as max and min (exactly the same values): vectorised, where the branch was not.
        const float a = g[k], b = l[k];
        sum[k] = (std::max(a, 0.f) + slope * std::min(a, 0.f)) + (std::max(b, 0.f) + slope * std::min(b, 0.f));
      }
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) {
          float* __restrict to = shuffled + ((2 * y + i) * columns + 2 * x + j) * c;
          const float* __restrict from = sum + 2 * i + j;
          for (int64_t k = 0; k < c; ++k) to[k] = from[4 * k];
        }
    }
}

}  // namespace

void ShuffleBlur(const ChannelsLastView& global, const ChannelsLastView& local, float slope, const ShuffleBlurWindow& w,
                 float* out) {
  const int64_t c4 = global.channels, c = c4 / 4;
  if (!global.data || !local.data || !out || c4 < 4 || c4 % 4 || local.channels != c4 ||
      local.height != global.height || local.width != global.width || global.height < 1 || global.width < 1)
    throw std::invalid_argument("ShuffleBlur: the branches' images differ or hold no 4 C channels");
  const int64_t height = w.picture_height, width = w.picture_width;
  if (w.y0 < 0 || w.x0 < 0 || w.y1 > height || w.x1 > width || w.y1 <= w.y0 || w.x1 <= w.x0)
    throw std::invalid_argument("ShuffleBlur: the window is not inside the picture");
  // The shuffled pixels the blur reads, and where the branches' pixels put them.
  const int64_t ry0 = std::max<int64_t>(w.y0 - 1, 0), ry1 = std::min(w.y1 + 1, height);
  const int64_t rx0 = std::max<int64_t>(w.x0 - 1, 0), rx1 = std::min(w.x1 + 1, width);
  const int64_t oy = 2 * w.first_row, ox = 2 * w.first_column;
  const int64_t rows = 2 * global.height, columns = 2 * global.width;
  if (ry0 < oy || rx0 < ox || ry1 > oy + rows || rx1 > ox + columns)
    throw std::invalid_argument("ShuffleBlur: the branches' pixels do not reach the window and the blur around it");

  // The leaky sum, shuffled: one input pixel's 4 C values are side by side,
  // and land on its four output pixels, C each.
  thread_local std::vector<float> shuffled_storage;
  shuffled_storage.resize(static_cast<size_t>(rows * columns * c));
  float* const shuffled = shuffled_storage.data();
  at::parallel_for(0, global.height, 8, [&](int64_t begin, int64_t end) {
    switch (c) {  // the renderer's shipped widths, unrolled
      case 8:
        return ShuffleRows<8>(global, local, slope, c, begin, end, shuffled);
      case 12:
        return ShuffleRows<12>(global, local, slope, c, begin, end, shuffled);
      case 24:
        return ShuffleRows<24>(global, local, slope, c, begin, end, shuffled);
      default:
        return ShuffleRows<0>(global, local, slope, c, begin, end, shuffled);
    }
  });

  // The blur, one output row at a time: the rows above and below summed
  // first (a run of floats), then the columns beside.
  const int64_t span = (rx1 - rx0) * c, out_row = (w.x1 - w.x0) * c;
  at::parallel_for(w.y0, w.y1, 4, [&](int64_t begin, int64_t end) {
    std::vector<float> column_sums(span);
    float* __restrict t = column_sums.data();
    for (int64_t y = begin; y < end; ++y) {
      const auto row = [&](int64_t picture_row) { return shuffled + ((picture_row - oy) * columns + (rx0 - ox)) * c; };
      const float* __restrict above = row(std::max<int64_t>(y - 1, 0));
      const float* __restrict centre = row(y);
      const float* __restrict below = row(std::min(y + 1, height - 1));
      for (int64_t n = 0; n < span; ++n) t[n] = above[n] + 2 * centre[n] + below[n];
      float* __restrict o = out + (y - w.y0) * out_row;
      // Column x of the picture is t[(x - rx0) * c]; beyond the picture's
      // edges the edge column again.
      const auto pixel = [&](int64_t x) {
        const float* left = t + (std::max<int64_t>(x - 1, 0) - rx0) * c;
        const float* mid = t + (x - rx0) * c;
        const float* right = t + (std::min(x + 1, width - 1) - rx0) * c;
        float* to = o + (x - w.x0) * c;
        for (int64_t k = 0; k < c; ++k) to[k] = (left[k] + 2 * mid[k] + right[k]) * (1.f / 16);
      };
      const int64_t inner0 = std::max<int64_t>(w.x0, 1), inner1 = std::min(w.x1, width - 1);
      for (int64_t x = w.x0; x < std::min(inner0, w.x1); ++x) pixel(x);
      if (inner1 > inner0) {
        const float* __restrict mid = t + (inner0 - rx0) * c;
        float* __restrict to = o + (inner0 - w.x0) * c;
        const int64_t n_end = (inner1 - inner0) * c;
        for (int64_t n = 0; n < n_end; ++n) to[n] = (mid[n - c] + 2 * mid[n] + mid[n + c]) * (1.f / 16);
      }
      for (int64_t x = std::max(inner1, inner0); x < w.x1; ++x) pixel(x);
    }
  });
}

}  // namespace headcast
