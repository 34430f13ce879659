// The avatar-backend seam: whatever turns one frame's parameters into the
// person's picture. The avatar file's manifest names its backend ("kind");
// OpenAvatarBackend builds it. The CNeRF + 2D neural renderer
// (AvatarRenderer, kind "cnerf") is the first backend. A new backend
// implements this interface, writes its kind into the files it saves, and
// adds a branch to OpenAvatarBackend; the render loop, the receiver and
// headcast-avatar need nothing else.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/core/options.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"

namespace headcast {

// What every avatar backend shares: the picture it makes and what it is
// conditioned on. A backend's own configuration extends this (the CNeRF
// backend's AvatarConfig); the camera and crop an avatar was trained with are
// its CameraContract.
struct AvatarCommonConfig {
  int output_size = 256;  // output image edge, pixels: 128, 256 or 512
  int num_shape = 12;     // beta components used
  // psi components used: an upper bound that FitConfigToModel lowers to the
  // model's count. Every component the tracker fits and the stream carries must
  // condition the avatar: ICT-FaceKit's blendshapes are not ordered by variance,
  // and its first 13 are brows, cheeks and eyes only — a prefix drops the mouth.
  int num_expression = 64;
  int num_texture = 5;  // tau components used
  // Adds what is wrong to `check` (output size, component counts).
  void CheckCommon(OptionsCheck* check) const;
};

// Milliseconds per stage of one frame (backends fill what applies to them).
struct AvatarTimings {
  double head_model_ms = 0;  // head-model forward pass and transform to the camera
  double sample_ms = 0;      // rasterising at feature resolution and choosing rays/depths
  double surface_ms = 0;     // the output-size raster and matte bound (beside the network when threads > 1)
  double texture_ms = 0;     // the surface texture looked up there (beside the network too)
  double mlp_ms = 0;         // the network over every sample
  double composite_ms = 0;   // volume rendering into the feature map
  double upsample_ms = 0;    // the 2D neural renderer
  double convert_ms = 0;     // tensor to BGR image
  double total_ms = 0;
  int rays = 0;
  int samples = 0;
};

class AvatarBackend {
 public:
  virtual ~AvatarBackend() = default;
  // Renders into `image_bgr` (CV_8UC3, output_size() square). Returns false
  // with `why` for invalid parameters (NaN, out of range) and leaves the image alone.
  virtual bool Render(const FrameParams& params, cv::Mat* image_bgr, AvatarTimings* timings = nullptr,
                      std::string* why = nullptr) = 0;
  virtual const AvatarCommonConfig& common_config() const = 0;
  int output_size() const { return common_config().output_size; }
  virtual std::string kind() const = 0;
  // The person's constants (shape, texture, light) and the camera the avatar renders with.
  virtual const SubjectParams& subject() const = 0;
  // The full frames' camera and crop the avatar was trained with, when known.
  virtual std::optional<CameraContract> camera_contract() const { return std::nullopt; }
};

struct AvatarBackendOptions {
  // libtorch intra-op (OpenMP) threads (OpenBLAS gets one: SetComputeThreads).
  // 1 by default: the receiver's other core decodes, displays and serves the
  // network; two render faster alone (`headcast-bench render` reports both).
  int threads = 1;
  // With threads > 1, the head model's pass in two halves and the output-size
  // raster and matte bound beside the network, on libtorch's threads: the
  // same pixels; off only to measure what it buys.
  bool parallel_stages = true;
  // Convolutions on channels-last images (NeuralRenderer::UseChannelsLast)
  // and the surface texture looked up texel-major (SurfaceTexture::
  // UseChannelsLast): the same pixels; off only to measure what the layout buys.
  bool channels_last = true;
  void Check() const;
};

// The backends this build knows, by kind.
std::vector<std::string> AvatarBackendKinds();

// Opens the avatar file at `path` with the backend its manifest names (files
// without a kind are "cnerf", the first backend). Throws naming the file for an
// unknown kind and for everything the backend refuses (format version, CRCs,
// another head model's fingerprint, mismatched weights).
std::unique_ptr<AvatarBackend> OpenAvatarBackend(const std::string& path, std::shared_ptr<const HeadModel> model,
                                                 const AvatarBackendOptions& options = {});

}  // namespace headcast
