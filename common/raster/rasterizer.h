// CPU triangle rasteriser: z-buffer, triangle ids and perspective-correct barycentrics.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "common/core/camera.h"

namespace headcast {

using RasterVertices = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RasterFaces = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct RasterOptions {
  float near_plane = 0.01f;     // metres; triangles with a vertex nearer are dropped
  bool cull_back_faces = true;  // faces are counter-clockwise seen from outside
  void Check() const;
};

// Per-pixel results; pixel (x, y) is sampled at its centre, integer coordinates.
struct RasterBuffers {
  int width = 0, height = 0;
  std::vector<float> depth;   // camera z (metres), +inf where nothing was drawn
  std::vector<int32_t> face;  // triangle index, -1 for background
  std::vector<float> bary;    // 3 per pixel, perspective-correct, sum to 1

  void Reset(int w, int h);
  bool Covered(int x, int y) const { return face[static_cast<size_t>(y) * width + x] >= 0; }
  cv::Mat Mask() const;        // CV_8U, 255 where covered (the silhouette)
  cv::Mat DepthImage() const;  // CV_32F metres, 0 where not covered
  int CoveredPixels() const;
};

// Rasterises triangles whose vertices are given in the camera frame. Buffers
// are reused across calls (no per-frame allocation after the first).
void Rasterize(const RasterVertices& vertices_in_cam, const RasterFaces& faces, const PinholeCamera& camera,
               const RasterOptions& options, RasterBuffers* out);

// Interpolates per-vertex attributes (N x C, C <= 4) into a CV_32FC(C) image; 0 outside.
cv::Mat InterpolateVertexAttribute(const RasterBuffers& buffers, const RasterFaces& faces,
                                   const Eigen::MatrixXf& attribute);

}  // namespace headcast
