// AvatarRenderer: FrameParams in, the avatar's picture out, on the CPU.
// Per frame: head model (Eigen) -> ray sampling -> CNeRF -> volume rendering ->
// 2D neural renderer -> BGR image. Buffers are reused across frames.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "common/avatar/avatar.h"
#include "common/headmodel/params.h"

namespace headcast {

// Milliseconds per stage of one frame.
struct AvatarTimings {
  double head_model_ms = 0;  // head-model forward pass and transform to the camera
  double sample_ms = 0;      // rasterising at feature resolution and choosing rays/depths
  double mlp_ms = 0;         // CNeRF over every sample
  double composite_ms = 0;   // volume rendering into the feature map
  double upsample_ms = 0;    // the 2D neural renderer
  double convert_ms = 0;     // tensor to BGR image
  double total_ms = 0;
  int rays = 0;
  int samples = 0;
};

struct AvatarRendererOptions {
  // libtorch intra-op (OpenMP) threads. 1 by default: measured on the 2-core
  // machine, OpenBLAS already threads the MLP's matrix products, and a second
  // OpenMP thread competing with it (and with the display) made frames slower
  // (`headcast-bench render` reports both).
  int threads = 1;
  void Check() const;
};

class AvatarRenderer {
 public:
  // `model` must be the head model the avatar was made for (fingerprint checked).
  AvatarRenderer(std::shared_ptr<const HeadModel> model, Avatar avatar, const AvatarRendererOptions& options = {});
  ~AvatarRenderer();

  // Renders into `image_bgr` (CV_8UC3, output_size x output_size). Returns false
  // with `why` for invalid parameters (NaN, out of range) and leaves the image alone.
  bool Render(const FrameParams& params, cv::Mat* image_bgr, AvatarTimings* timings = nullptr,
              std::string* why = nullptr);

  const Avatar& avatar() const;
  const HeadModel& head_model() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
