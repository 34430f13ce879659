// Renders a posed head model through the CPU rasteriser (previews, synthetic data, overlays).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/core/camera.h"
#include "common/core/rigid_transform.h"
#include "common/headmodel/head_model.h"
#include "common/raster/rasterizer.h"
#include "common/raster/shading.h"

namespace headcast {

// A camera `distance` metres in front of the face looking at `target` (head
// frame), the head turned by `yaw_deg` (positive: toward the subject's left)
// and pitched by `pitch_deg` (positive: chin down).
RigidTransform FrontalCamFromHead(double distance, double yaw_deg = 0, double pitch_deg = 0,
                                  const Eigen::Vector3d& target = Eigen::Vector3d(0, -0.01, 0.02));

// Vertices (head frame) to the camera frame; `out` is reused across frames.
void TransformToCamera(const RowMatrixX3f& vertices, const RigidTransform& cam_from_head, RasterVertices* out);

// The flat skin colour (linear RGB) a model without an albedo is rendered in.
inline Eigen::Vector3f FlatSkinAlbedo() { return {0.80f, 0.62f, 0.52f}; }

// Albedo texture (CV_32FC3, RGB) for texture coefficients tau; flat skin if the model has none.
cv::Mat AlbedoTexture(const HeadModel& model, const Eigen::VectorXd& tau = {});

struct HeadRenderOptions {
  ShLighting light = DefaultLighting();
  cv::Vec3f background_rgb = {0.16f, 0.17f, 0.20f};
  RasterOptions raster;
  void Check() const;
};

struct HeadRender {
  cv::Mat image_bgr;  // CV_8UC3
  cv::Mat mask;       // CV_8U, 255 on the head
  cv::Mat depth;      // CV_32F metres, 0 off the head
};

// Renders vertices (head frame) seen through `camera` at `cam_from_head`.
HeadRender RenderHead(const HeadModel& model, const RowMatrixX3f& vertices, const RigidTransform& cam_from_head,
                      const PinholeCamera& camera, const cv::Mat& albedo_rgb, const HeadRenderOptions& options = {},
                      RasterBuffers* buffers = nullptr);

// Draws 2D points (e.g. projected landmarks) onto an image.
void DrawPoints(cv::Mat* image_bgr, const std::vector<Eigen::Vector2d>& points, const cv::Scalar& color,
                int radius = 2);

}  // namespace headcast
