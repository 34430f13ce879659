#include "common/tracking/frame_mask.h"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "common/core/crop.h"
#include "common/headmodel/head_render.h"
#include "common/raster/rasterizer.h"

namespace headcast {

std::optional<FrameCrop> ContractCrop(const CameraContract& contract, const PinholeCamera& camera, int resolution) {
  if (!ContractCameraFor(contract, camera.width, camera.height)) return std::nullopt;
  const double s = static_cast<double>(camera.width) / contract.source.width;
  FrameCrop crop{s * contract.crop_x0, s * contract.crop_y0, s * contract.crop_side, resolution, {}};
  crop.camera = CropIntrinsics(camera, crop.x0, crop.y0, crop.side, resolution);
  return crop;
}

cv::Mat CropGrabCutMask(const cv::Mat& bgr, const Landmarks2d& face_landmarks, const FrameCrop& crop,
                        const HeadMaskOptions& mask_options, HeadMaskModels* carried, double wanted_above_y) {
  const double wanted_in_frame = crop.y0 + wanted_above_y * crop.side / crop.resolution;
  cv::Mat grabcut = CropSquare(HeadMask(bgr, face_landmarks, mask_options, carried, wanted_in_frame), crop.x0, crop.y0,
                               crop.side, crop.resolution, cv::INTER_LINEAR);
  cv::threshold(grabcut, grabcut, 127, 255, cv::THRESH_BINARY);
  return grabcut;
}

cv::Mat CutCropMask(const cv::Mat& grabcut, const HeadModel& model, const HeadModelOutput& posed,
                    const Landmarks2d& fitted_landmarks, const FrameParams& params, const PinholeCamera& crop_camera,
                    const MatteRules& rules) {
  RasterVertices in_camera;
  TransformToCamera(posed.vertices, params.CamFromHead(), &in_camera);
  RasterBuffers silhouette;
  Rasterize(in_camera, model.data().faces, crop_camera, RasterOptions{}, &silhouette);
  return CutTrainingMask(grabcut, silhouette.Mask(), fitted_landmarks, rules);
}

}  // namespace headcast
