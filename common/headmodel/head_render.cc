// Head-model rendering through the CPU rasteriser.
#include "common/headmodel/head_render.h"

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/options.h"
#include "common/core/rotation.h"

namespace headcast {

RigidTransform FrontalCamFromHead(double distance, double yaw_deg, double pitch_deg, const Eigen::Vector3d& target) {
  // Head frame: y up, z out of the face. Camera: y down, z forward. Looking at
  // the face from the front is a half turn about x.
  const Eigen::Matrix3d flip = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d turn = (Eigen::AngleAxisd(pitch_deg * M_PI / 180, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitY()))
                                   .toRotationMatrix();
  RigidTransform t;
  t.rotation = flip * turn;
  t.translation = Eigen::Vector3d(0, 0, distance) - t.rotation * target;
  return t;
}

void TransformToCamera(const RowMatrixX3f& vertices, const RigidTransform& cam_from_head, RasterVertices* out) {
  const Eigen::Matrix3f R = cam_from_head.rotation.cast<float>();
  out->noalias() = vertices * R.transpose();
  out->rowwise() += cam_from_head.translation.cast<float>().transpose();
}

cv::Mat AlbedoTexture(const HeadModel& model, const Eigen::VectorXd& tau) {
  const auto& d = model.data();
  if (!model.has_texture()) {
    const Eigen::Vector3f skin = FlatSkinAlbedo();
    return cv::Mat(4, 4, CV_32FC3, cv::Scalar(skin.x(), skin.y(), skin.z()));
  }
  cv::Mat tex(d.texture_height, d.texture_width, CV_32FC3);
  Eigen::Map<Eigen::VectorXf> out(tex.ptr<float>(), static_cast<Eigen::Index>(d.texture_mean.size()));
  out = Eigen::Map<const Eigen::VectorXf>(d.texture_mean.data(), static_cast<Eigen::Index>(d.texture_mean.size()));
  const int k = std::min<int>(static_cast<int>(tau.size()), model.num_texture());
  if (k > 0) out.noalias() += d.texture_basis.leftCols(k) * tau.head(k).cast<float>();
  cv::max(tex, 0.0, tex);
  cv::min(tex, 1.0, tex);
  return tex;
}

void HeadRenderOptions::Check() const {
  raster.Check();
  OptionsCheck c("HeadRenderOptions");
  for (float v : light) c.Finite("light", v);
  c.ThrowIfErrors();
}

HeadRender RenderHead(const HeadModel& model, const RowMatrixX3f& vertices, const RigidTransform& cam_from_head,
                      const PinholeCamera& camera, const cv::Mat& albedo, const HeadRenderOptions& options,
                      RasterBuffers* buffers) {
  RasterBuffers local;
  RasterBuffers& buf = buffers ? *buffers : local;
  RasterVertices v_cam;
  TransformToCamera(vertices, cam_from_head, &v_cam);
  Rasterize(v_cam, model.data().faces, camera, options.raster, &buf);
  const RowMatrixX3f normals = model.VertexNormals(v_cam);
  const cv::Mat normal_image = InterpolateVertexAttribute(buf, model.data().faces, normals);
  cv::Mat albedo_image;
  if (model.has_texture()) {
    albedo_image = SampleTexture(buf, model.data().uv_faces, model.data().uvs, albedo);
  } else {
    albedo_image = cv::Mat(camera.height, camera.width, CV_32FC3, albedo.at<cv::Vec3f>(0, 0));
  }
  const cv::Mat rgb = ShadeSphericalHarmonics(buf, albedo_image, normal_image, options.light, options.background_rgb);
  HeadRender out;
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  out.image_bgr = ToUint8(bgr);
  out.mask = buf.Mask();
  out.depth = buf.DepthImage();
  return out;
}

void DrawPoints(cv::Mat* image, const std::vector<Eigen::Vector2d>& points, const cv::Scalar& color, int radius) {
  for (const auto& p : points) cv::circle(*image, cv::Point2d(p.x(), p.y()), radius, color, cv::FILLED, cv::LINE_AA);
}

}  // namespace headcast
