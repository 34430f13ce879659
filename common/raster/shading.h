// Shading of rasterised meshes: albedo textures and 2nd-order spherical-harmonic light.
#pragma once

#include <array>
#include <opencv2/core.hpp>

#include "common/raster/rasterizer.h"

namespace headcast {

// 9 coefficients per colour channel (R, G, B), 27 numbers: lambda in METHOD.
// Irradiance = sum_k coeff[c][k] * Y_k(n) with the real SH basis Y_0..Y_8
// evaluated at the unit normal n in the camera frame.
using ShLighting = std::array<float, 27>;

// Soft light from the camera's side and a little above, white.
ShLighting DefaultLighting();
// The 9 real SH basis values at unit normal n.
std::array<float, 9> ShBasis(const Eigen::Vector3f& n);

using RasterUvs = Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor>;

// Bilinear lookup of an RGB float texture (H x W x 3, v down) at each pixel's
// interpolated UV. Returns CV_32FC3 RGB, 0 outside the silhouette.
cv::Mat SampleTexture(const RasterBuffers& buffers, const RasterFaces& uv_faces, const RasterUvs& uvs,
                      const cv::Mat& texture_rgb);

// albedo (CV_32FC3 RGB) times SH irradiance at the interpolated normals
// (CV_32FC3, unit length expected). Pixels outside the silhouette get `background`.
cv::Mat ShadeSphericalHarmonics(const RasterBuffers& buffers, const cv::Mat& albedo_rgb, const cv::Mat& normals,
                                const ShLighting& light, const cv::Vec3f& background_rgb = {0, 0, 0});

}  // namespace headcast
