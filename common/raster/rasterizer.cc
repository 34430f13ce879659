// CPU triangle rasteriser. Edge functions over each triangle's bounding box,
// with barycentrics made perspective-correct by interpolating 1/z.
#include "common/raster/rasterizer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/core/options.h"

namespace headcast {

void RasterOptions::Check() const {
  OptionsCheck c("RasterOptions");
  c.Positive("near_plane", near_plane);
  c.ThrowIfErrors();
}

void RasterBuffers::Reset(int w, int h) {
  width = w;
  height = h;
  const size_t n = static_cast<size_t>(w) * h;
  depth.assign(n, std::numeric_limits<float>::infinity());
  face.assign(n, -1);
  bary.resize(3 * n);
}

cv::Mat RasterBuffers::Mask() const {
  cv::Mat m(height, width, CV_8U);
  for (int i = 0; i < width * height; ++i) m.data[i] = face[i] >= 0 ? 255 : 0;
  return m;
}

cv::Mat RasterBuffers::DepthImage() const {
  cv::Mat d(height, width, CV_32F);
  auto* p = d.ptr<float>();
  for (int i = 0; i < width * height; ++i) p[i] = face[i] >= 0 ? depth[i] : 0.f;
  return d;
}

int RasterBuffers::CoveredPixels() const {
  return static_cast<int>(std::count_if(face.begin(), face.end(), [](int32_t f) { return f >= 0; }));
}

void Rasterize(const RasterVertices& v, const RasterFaces& faces, const PinholeCamera& cam,
               const RasterOptions& options, RasterBuffers* out) {
  const int w = cam.width, h = cam.height;
  if (out->width != w || out->height != h || out->depth.size() != static_cast<size_t>(w) * h) {
    out->Reset(w, h);
  } else {
    std::fill(out->depth.begin(), out->depth.end(), std::numeric_limits<float>::infinity());
    std::fill(out->face.begin(), out->face.end(), -1);
  }
  const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
  const float cx = static_cast<float>(cam.cx), cy = static_cast<float>(cam.cy);
  // Project every vertex once.
  thread_local std::vector<Eigen::Vector3f> screen;  // x, y, 1/z
  screen.resize(v.rows());
  for (Eigen::Index i = 0; i < v.rows(); ++i) {
    const float z = v(i, 2);
    const float iz = z > options.near_plane ? 1.f / z : -1.f;
    screen[i] = {fx * v(i, 0) * iz + cx, fy * v(i, 1) * iz + cy, iz};
  }
  float* depth = out->depth.data();
  int32_t* face_id = out->face.data();
  float* bary = out->bary.data();
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3f& a = screen[faces(f, 0)];
    const Eigen::Vector3f& b = screen[faces(f, 1)];
    const Eigen::Vector3f& c = screen[faces(f, 2)];
    if (a.z() <= 0 || b.z() <= 0 || c.z() <= 0) continue;  // behind the near plane
    // Signed area in image coordinates (y down): front faces are negative.
    const float area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
    if (area == 0 || (options.cull_back_faces && area > 0)) continue;
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}))));
    const int x1 = std::min(w - 1, static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(h - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
    if (x0 > x1 || y0 > y1) continue;
    const float inv_area = 1.f / area;
    // Edge functions e_k(p) = signed area of (p, next, next-next) / area: screen barycentrics.
    const float e0x = (b.y() - c.y()) * inv_area, e0y = (c.x() - b.x()) * inv_area;
    const float e1x = (c.y() - a.y()) * inv_area, e1y = (a.x() - c.x()) * inv_area;
    const float e0c = ((b.x() - x0) * (c.y() - y0) - (b.y() - y0) * (c.x() - x0)) * inv_area;
    const float e1c = ((c.x() - x0) * (a.y() - y0) - (c.y() - y0) * (a.x() - x0)) * inv_area;
    for (int y = y0; y <= y1; ++y) {
      float l0 = e0c + e0y * (y - y0);
      float l1 = e1c + e1y * (y - y0);
      for (int x = x0; x <= x1; ++x, l0 += e0x, l1 += e1x) {
        const float l2 = 1.f - l0 - l1;
        if (l0 < 0 || l1 < 0 || l2 < 0) continue;
        const float iz = l0 * a.z() + l1 * b.z() + l2 * c.z();
        const float z = 1.f / iz;
        const size_t p = static_cast<size_t>(y) * w + x;
        if (z >= depth[p]) continue;
        depth[p] = z;
        face_id[p] = static_cast<int32_t>(f);
        bary[3 * p + 0] = l0 * a.z() * z;
        bary[3 * p + 1] = l1 * b.z() * z;
        bary[3 * p + 2] = l2 * c.z() * z;
      }
    }
  }
}

cv::Mat InterpolateVertexAttribute(const RasterBuffers& buf, const RasterFaces& faces, const Eigen::MatrixXf& attr) {
  const int channels = static_cast<int>(attr.cols());
  if (channels < 1 || channels > 4) throw std::invalid_argument("InterpolateVertexAttribute: 1 to 4 channels");
  cv::Mat out(buf.height, buf.width, CV_32FC(channels), cv::Scalar::all(0));
  float* o = out.ptr<float>();
  for (int p = 0; p < buf.width * buf.height; ++p) {
    const int f = buf.face[p];
    if (f < 0) continue;
    for (int ch = 0; ch < channels; ++ch)
      o[p * channels + ch] = buf.bary[3 * p] * attr(faces(f, 0), ch) + buf.bary[3 * p + 1] * attr(faces(f, 1), ch) +
                             buf.bary[3 * p + 2] * attr(faces(f, 2), ch);
  }
  return out;
}

}  // namespace headcast
