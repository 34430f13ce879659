// AvatarRenderer, the CNeRF avatar backend: FrameParams in, the avatar's picture out, on the CPU.
// Per frame: head model (Eigen) -> ray sampling -> CNeRF -> volume rendering ->
// 2D neural renderer -> BGR image. Buffers are reused across frames.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "common/avatar/avatar.h"
#include "common/avatar/avatar_backend.h"
#include "common/headmodel/params.h"

namespace headcast {

// The CNeRF backend's options are the backends' shared ones.
using AvatarRendererOptions = AvatarBackendOptions;

class AvatarRenderer : public AvatarBackend {
 public:
  static constexpr const char* kKind = "cnerf";
  // `model` must be the head model the avatar was made for (fingerprint checked).
  AvatarRenderer(std::shared_ptr<const HeadModel> model, Avatar avatar, const AvatarRendererOptions& options = {});
  ~AvatarRenderer();

  // Renders into `image_bgr` (CV_8UC3, output_size x output_size). Returns false
  // with `why` for invalid parameters (NaN, out of range) and leaves the image alone.
  bool Render(const FrameParams& params, cv::Mat* image_bgr, AvatarTimings* timings = nullptr,
              std::string* why = nullptr) override;
  const AvatarCommonConfig& common_config() const override;
  std::string kind() const override { return kKind; }
  const SubjectParams& subject() const override;
  std::optional<CameraContract> camera_contract() const override;

  const Avatar& avatar() const;
  const HeadModel& head_model() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
