// Texture sampling and spherical-harmonic shading.
#include "common/raster/shading.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace headcast {

std::array<float, 9> ShBasis(const Eigen::Vector3f& n) {
  const float x = n.x(), y = n.y(), z = n.z();
  // Real spherical harmonics, bands 0..2 (standard normalisation).
  return {0.282095f,
          0.488603f * y,
          0.488603f * z,
          0.488603f * x,
          1.092548f * x * y,
          1.092548f * y * z,
          0.315392f * (3 * z * z - 1),
          1.092548f * x * z,
          0.546274f * (x * x - y * y)};
}

ShLighting DefaultLighting() {
  // Camera frame: y down, z forward, so a surface facing the camera has n_z < 0
  // and one facing up has n_y < 0.
  ShLighting l{};
  for (int c = 0; c < 3; ++c) {
    l[9 * c + 0] = 2.9f;    // ambient: 2.9 * 0.282 = 0.82
    l[9 * c + 1] = -0.30f;  // brighter facing up
    l[9 * c + 2] = -0.55f;  // brighter facing the camera
    l[9 * c + 3] = 0.12f;   // a little from the image's right
    l[9 * c + 6] = -0.10f;
  }
  return l;
}

cv::Mat SampleTexture(const RasterBuffers& buf, const RasterFaces& uv_faces, const RasterUvs& uvs, const cv::Mat& tex) {
  if (tex.type() != CV_32FC3) throw std::invalid_argument("SampleTexture: texture must be CV_32FC3");
  cv::Mat out(buf.height, buf.width, CV_32FC3, cv::Scalar::all(0));
  const int tw = tex.cols, th = tex.rows;
  for (int p = 0; p < buf.width * buf.height; ++p) {
    const int f = buf.face[p];
    if (f < 0) continue;
    const float* b = &buf.bary[3 * p];
    const float u = b[0] * uvs(uv_faces(f, 0), 0) + b[1] * uvs(uv_faces(f, 1), 0) + b[2] * uvs(uv_faces(f, 2), 0);
    const float v = b[0] * uvs(uv_faces(f, 0), 1) + b[1] * uvs(uv_faces(f, 1), 1) + b[2] * uvs(uv_faces(f, 2), 1);
    const float tx = std::clamp(u * tw - 0.5f, 0.f, tw - 1.f), ty = std::clamp(v * th - 0.5f, 0.f, th - 1.f);
    const int x0 = static_cast<int>(tx), y0 = static_cast<int>(ty);
    const int x1 = std::min(x0 + 1, tw - 1), y1 = std::min(y0 + 1, th - 1);
    const float ax = tx - x0, ay = ty - y0;
    const cv::Vec3f c = (1 - ay) * ((1 - ax) * tex.at<cv::Vec3f>(y0, x0) + ax * tex.at<cv::Vec3f>(y0, x1)) +
                        ay * ((1 - ax) * tex.at<cv::Vec3f>(y1, x0) + ax * tex.at<cv::Vec3f>(y1, x1));
    out.at<cv::Vec3f>(p / buf.width, p % buf.width) = c;
  }
  return out;
}

cv::Mat ShadeSphericalHarmonics(const RasterBuffers& buf, const cv::Mat& albedo, const cv::Mat& normals,
                                const ShLighting& light, const cv::Vec3f& background) {
  if (albedo.type() != CV_32FC3 || normals.type() != CV_32FC3 || albedo.size() != normals.size() ||
      albedo.cols != buf.width || albedo.rows != buf.height)
    throw std::invalid_argument("ShadeSphericalHarmonics: albedo and normals must be CV_32FC3 of the raster size");
  cv::Mat out(buf.height, buf.width, CV_32FC3);
  for (int p = 0; p < buf.width * buf.height; ++p) {
    const int y = p / buf.width, x = p % buf.width;
    if (buf.face[p] < 0) {
      out.at<cv::Vec3f>(y, x) = background;
      continue;
    }
    const cv::Vec3f nn = normals.at<cv::Vec3f>(y, x);
    Eigen::Vector3f n(nn[0], nn[1], nn[2]);
    const float len = n.norm();
    if (len > 0) n /= len;
    const auto basis = ShBasis(n);
    const cv::Vec3f a = albedo.at<cv::Vec3f>(y, x);
    cv::Vec3f c;
    for (int ch = 0; ch < 3; ++ch) {
      float irradiance = 0;
      for (int k = 0; k < 9; ++k) irradiance += light[9 * ch + k] * basis[k];
      c[ch] = a[ch] * std::max(irradiance, 0.f);
    }
    out.at<cv::Vec3f>(y, x) = c;
  }
  return out;
}

}  // namespace headcast
