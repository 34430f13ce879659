// Ray and depth sampling.
#include "common/avatar/ray_sampler.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace headcast {

RaySampler::RaySampler(const AvatarConfig& config) : config_(config) { config.Check(); }

void RaySampler::AddRay(const PinholeCamera& cam, int x, int y, float z_near, float z_far, int face, std::mt19937* rng,
                        RayBatch* out) const {
  out->pixel.push_back(y * cam.width + x);
  out->face.push_back(face);
  out->directions.push_back(static_cast<float>((x - cam.cx) / cam.fx));
  out->directions.push_back(static_cast<float>((y - cam.cy) / cam.fy));
  out->directions.push_back(1.f);
  const int s = config_.samples_per_ray;
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (int k = 0; k < s; ++k) {
    const float offset = rng ? u(*rng) : 0.5f;  // stratified: one sample per stratum
    out->depths.push_back(z_near + (z_far - z_near) * (k + offset) / s);
  }
}

void RaySampler::Sample(const RasterVertices& vertices_in_cam, const RasterFaces& faces, const PinholeCamera& cam,
                        const RigidTransform& cam_from_head, std::mt19937* rng, RayBatch* out) {
  out->width = cam.width;
  out->height = cam.height;
  out->samples_per_ray = config_.samples_per_ray;
  out->pixel.clear();
  out->directions.clear();
  out->depths.clear();
  out->face.clear();
  if (config_.sampling == SamplingMode::kUniform) {
    const float centre = static_cast<float>(cam_from_head.translation.z());
    const float z_near = std::max(0.01f, centre - static_cast<float>(config_.uniform_near));
    const float z_far = centre + static_cast<float>(config_.uniform_far);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) AddRay(cam, x, y, z_near, z_far, -1, rng, out);
    return;
  }
  RasterOptions raster;
  raster.cull_back_faces = true;
  Rasterize(vertices_in_cam, faces, cam, raster, &buffers_);
  // Depth for rays near the silhouette (hair, ears, a margin for the fit's
  // error): the nearest surface depth within hair_margin_px.
  const int w = cam.width, h = cam.height, m = config_.hair_margin_px;
  const float inf = std::numeric_limits<float>::infinity();
  surface_depth_.assign(static_cast<size_t>(w) * h, inf);
  surface_face_.assign(static_cast<size_t>(w) * h, -1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      if (buffers_.face[p] >= 0) {
        surface_depth_[p] = buffers_.depth[p];
        surface_face_[p] = buffers_.face[p];
        continue;
      }
      for (int dy = -m; dy <= m; ++dy)
        for (int dx = -m; dx <= m; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const size_t q = static_cast<size_t>(yy) * w + xx;
          if (buffers_.face[q] >= 0 && buffers_.depth[q] < surface_depth_[p]) {
            surface_depth_[p] = buffers_.depth[q];
            surface_face_[p] = buffers_.face[q];
          }
        }
    }
  const float front = static_cast<float>(config_.shell_front), back = static_cast<float>(config_.shell_back);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      const float d = surface_depth_[p];
      if (d == inf) continue;  // misses the head: background, no samples
      const bool margin = buffers_.face[p] < 0;
      AddRay(cam, x, y, std::max(0.01f, d - front), d + back, margin && config_.rigid_margin ? -1 : surface_face_[p],
             rng, out);
    }
}

namespace {

// The canonical mesh must be the posed one's (x y z per vertex).
void CheckCanonicalVertices(const char* who, const Eigen::VectorXf& canonical, Eigen::Index vertices) {
  if (canonical.size() != 3 * vertices)
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(canonical.size() / 3) +
                                " canonical vertices for a mesh of " + std::to_string(vertices));
}

// The point under pixel `p` of `b` on a mesh of the same faces (`vertices`:
// x y z per vertex, canonical or posed): the same triangle and barycentrics,
// each vertex moved by `offset` along its normal (none when `normals` is null).
void PointUnderPixel(const RasterBuffers& b, int p, const RasterFaces& faces, const float* vertices,
                     const RowMatrixX3f* normals, float offset, float point[3]) {
  point[0] = point[1] = point[2] = 0;
  const int f = b.face[p];
  for (int corner = 0; corner < 3; ++corner) {
    const float w = b.bary[3 * p + corner];
    const int v = faces(f, corner);
    for (int k = 0; k < 3; ++k) point[k] += w * (vertices[3 * v + k] + (normals ? offset * (*normals)(v, k) : 0.f));
  }
}

}  // namespace

std::vector<uint8_t> CoveredFaces(const Eigen::VectorXf& canonical, const RasterFaces& faces, float depth) {
  if (canonical.size() % 3 != 0 || canonical.size() == 0)
    throw std::invalid_argument("CoveredFaces: the canonical mesh needs x y z per vertex");
  if (!(depth > 0)) throw std::invalid_argument("CoveredFaces: depth must be positive");
  const Eigen::Index n = canonical.size() / 3;
  const Eigen::Map<const RowMatrixX3f> v(canonical.data(), n, 3);
  const Eigen::RowVector3f low = v.colwise().minCoeff(), high = v.colwise().maxCoeff();
  // Seen from the front and far away (nearly orthographic), about 0.3 mm a
  // pixel for a head: finer than the mouth's and eyes' triangles, so each
  // face's centre falls on a pixel of its own or of what covers it.
  constexpr int kSize = 1024;
  constexpr float kDistance = 10.f;
  const float span = 1.02f * std::max(high.x() - low.x(), high.y() - low.y());
  if (!(span > 0)) throw std::invalid_argument("CoveredFaces: the mesh has no extent");
  PinholeCamera cam;
  cam.width = cam.height = kSize;
  cam.fx = cam.fy = kSize * kDistance / span;
  cam.cx = cam.cy = 0.5 * kSize - 0.5;
  // Camera frame: x right, y down, z into the scene; the camera on the face's side.
  const Eigen::RowVector3f middle = 0.5f * (low + high);
  const auto to_cam = [&](const Eigen::RowVector3f& p) {
    return Eigen::RowVector3f(p.x() - middle.x(), middle.y() - p.y(), high.z() + kDistance - p.z());
  };
  RasterVertices in_cam(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) in_cam.row(i) = to_cam(v.row(i));
  RasterBuffers b;
  RasterOptions raster;
  raster.cull_back_faces = true;
  Rasterize(in_cam, faces, cam, raster, &b);
  // A face that wins a pixel is seen; one too small or too steep to win any
  // lies behind its neighbours' pixels by about its slope times a pixel
  // (the crown's, seen edge on, by several millimetres), while the lids and
  // lips lie further in front of what they cover.
  constexpr float kTolerance = 2e-3f;
  const float pixel_metres = span / kSize;
  std::vector<uint8_t> seen(static_cast<size_t>(faces.rows()), 0);
  for (const int32_t f : b.face)
    if (f >= 0) seen[f] = 1;
  std::vector<uint8_t> covered(static_cast<size_t>(faces.rows()), 0);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    if (seen[f]) continue;
    const Eigen::RowVector3f a = v.row(faces(f, 0)), e1 = v.row(faces(f, 1)) - a, e2 = v.row(faces(f, 2)) - a;
    const Eigen::RowVector3f normal = e1.cross(e2);
    if (!(normal.z() > 0)) continue;  // looks away from the front
    const float slope = normal.head<2>().norm() / normal.z();
    const Eigen::RowVector3f centre = to_cam((3 * a + e1 + e2) / 3);
    const Eigen::Vector2d pixel = cam.Project(centre.transpose().cast<double>());
    const int x = static_cast<int>(std::lround(pixel.x())), y = static_cast<int>(std::lround(pixel.y()));
    if (x < 0 || y < 0 || x >= kSize || y >= kSize) continue;
    const size_t p = static_cast<size_t>(y) * kSize + x;
    const float gap = centre.z() - b.depth[p];
    covered[f] = b.face[p] >= 0 && b.face[p] != f && gap > kTolerance + slope * pixel_metres && gap < depth;
  }
  return covered;
}

namespace {

void MoveApart(float p[3]) {
  for (int k = 0; k < 3; ++k) p[k] = kCoveredApartTo[k] + kCoveredApartScale * (p[k] - kCoveredApartFrom[k]);
}

}  // namespace

int MoveCoveredPointsApart(const std::vector<uint8_t>& covered, SurfaceBatch* surface) {
  if (surface->face.size() != static_cast<size_t>(surface->num_pixels()))
    throw std::invalid_argument("MoveCoveredPointsApart: the surface's pixels come without their triangles");
  int moved = 0;
  for (int i = 0; i < surface->num_pixels(); ++i) {
    const int f = surface->face[i];
    if (f < 0 || static_cast<size_t>(f) >= covered.size())
      throw std::invalid_argument("MoveCoveredPointsApart: a pixel's triangle is not the covered table's mesh's");
    if (!covered[f]) continue;
    MoveApart(&surface->canonical[3 * static_cast<size_t>(i)]);
    ++moved;
  }
  return moved;
}

std::vector<uint8_t> HairFaces(const HeadModel& model, float reach) {
  const HeadModelData& d = model.data();
  const int n = model.num_vertices();
  std::vector<uint8_t> still(n, 0);
  for (int i = 0; i < n; ++i) {
    float largest = 0;
    for (int e = 0; e < model.num_expression(); ++e)
      largest = std::max(largest, d.expressiondirs.block(3 * i, e, 3, 1).norm());
    const float joints = d.weights(i, kJawJoint) + d.weights(i, kLeftEyeJoint) + d.weights(i, kRightEyeJoint);
    still[i] = largest < reach && joints <= 0.01f;
  }
  std::vector<uint8_t> hair(d.faces.rows());
  for (int f = 0; f < d.faces.rows(); ++f)
    hair[f] = still[d.faces(f, 0)] && still[d.faces(f, 1)] && still[d.faces(f, 2)];
  return hair;
}

void HairRays(const RayBatch& rays, const std::vector<uint8_t>& hair_faces, std::vector<float>* out) {
  out->resize(rays.num_rays());
  for (int r = 0; r < rays.num_rays(); ++r) {
    const int f = rays.face[r];
    if (f >= static_cast<int>(hair_faces.size()))
      throw std::invalid_argument("HairRays: a ray's triangle is not the hair table's mesh's");
    (*out)[r] = f < 0 || hair_faces[f] ? 1.f : 0.f;
  }
}

const std::vector<uint8_t>& RaySampler::Hair(const HeadModel& model) {
  if (hair_of_ != model.data().expressiondirs.data() || hair_.size() != static_cast<size_t>(model.num_faces())) {
    hair_ = HairFaces(model, static_cast<float>(config_.hair_reach));
    hair_of_ = model.data().expressiondirs.data();
  }
  return hair_;
}

const std::vector<uint8_t>& RaySampler::Covered(const Eigen::VectorXf& canonical, const RasterFaces& faces) {
  if (covered_of_.size() != canonical.size() || covered_of_ != canonical ||
      covered_.size() != static_cast<size_t>(faces.rows())) {
    covered_ = CoveredFaces(canonical, faces, static_cast<float>(config_.shell_front + config_.shell_back));
    covered_of_ = canonical;
  }
  return covered_;
}

int FoldEyeballPoints(const HeadModel& model, const HeadIdentity& identity, SurfaceBatch* surface) {
  if (surface->face.size() != static_cast<size_t>(surface->num_pixels()))
    throw std::invalid_argument("FoldEyeballPoints: the surface's pixels come without their triangles");
  const HeadModelData& d = model.data();
  auto eye_of = [&](int f) {
    for (int joint : {kLeftEyeJoint, kRightEyeJoint}) {
      bool all = true;
      for (int k = 0; k < 3; ++k) all = all && d.weights(d.faces(f, k), joint) > 0.5f;
      if (all) return joint;
    }
    return -1;
  };
  int moved = 0;
  for (int i = 0; i < surface->mesh_pixels; ++i) {
    const int eye = eye_of(surface->face[i]);
    if (eye < 0) continue;
    float* p = &surface->canonical[3 * static_cast<size_t>(i)];
    const float cx = identity.joints(eye, 0), cy = identity.joints(eye, 1);
    p[0] = cx + std::hypot(p[0] - cx, p[1] - cy);
    p[1] = cy;
    ++moved;
  }
  return moved;
}

void RaySampler::SampleSurface(const RasterVertices& vertices_in_cam, const RasterFaces& faces,
                               const Eigen::VectorXf& canonical_vertices, const PinholeCamera& cam, SurfaceBatch* out,
                               const RowMatrixX3f* posed_vertices) {
  CheckCanonicalVertices("SampleSurface", canonical_vertices, vertices_in_cam.rows());
  if (posed_vertices && posed_vertices->rows() != vertices_in_cam.rows())
    throw std::invalid_argument("SampleSurface: " + std::to_string(posed_vertices->rows()) +
                                " posed vertices for a mesh of " + std::to_string(vertices_in_cam.rows()));
  RasterOptions raster;
  raster.cull_back_faces = true;
  Rasterize(vertices_in_cam, faces, cam, raster, &surface_buffers_);
  out->width = cam.width;
  out->height = cam.height;
  out->pixel.clear();
  out->canonical.clear();
  out->posed.clear();
  out->face.clear();
  const RasterBuffers& b = surface_buffers_;
  for (int p = 0; p < cam.width * cam.height; ++p) {
    if (b.face[p] < 0) continue;
    out->pixel.push_back(p);
    out->face.push_back(b.face[p]);
    float point[3];
    PointUnderPixel(b, p, faces, canonical_vertices.data(), nullptr, 0.f, point);
    out->canonical.insert(out->canonical.end(), point, point + 3);
    if (posed_vertices) {
      PointUnderPixel(b, p, faces, posed_vertices->data(), nullptr, 0.f, point);
      out->posed.insert(out->posed.end(), point, point + 3);
    }
  }
  out->mesh_pixels = out->num_pixels();
  if (config_.surface_shell > 0)
    AppendShell(vertices_in_cam, faces, canonical_vertices, cam, static_cast<float>(config_.surface_shell), out);
}

void RaySampler::AppendShell(const RasterVertices& vertices_in_cam, const RasterFaces& faces,
                             const Eigen::VectorXf& canonical_vertices, const PinholeCamera& cam, float shell,
                             SurfaceBatch* out) {
  // Inflated along the vertex normals, posed and canonical alike, so that a
  // shell point keeps its place relative to the surface under it.
  inflated_ = vertices_in_cam + shell * VertexNormals(vertices_in_cam, faces);
  if (normals_of_.size() != canonical_vertices.size() || normals_of_ != canonical_vertices) {
    const RowMatrixX3f canonical =
        Eigen::Map<const RowMatrixX3f>(canonical_vertices.data(), canonical_vertices.size() / 3, 3);
    canonical_normals_ = VertexNormals(canonical, faces);
    normals_of_ = canonical_vertices;
  }
  RasterOptions raster;
  raster.cull_back_faces = true;
  Rasterize(inflated_, faces, cam, raster, &shell_buffers_);
  const RasterBuffers& mesh = surface_buffers_;
  const RasterBuffers& b = shell_buffers_;
  for (int p = 0; p < cam.width * cam.height; ++p) {
    if (b.face[p] < 0 || mesh.face[p] >= 0) continue;
    out->pixel.push_back(p);
    out->face.push_back(b.face[p]);
    float point[3];
    PointUnderPixel(b, p, faces, canonical_vertices.data(), &canonical_normals_, shell, point);
    out->canonical.insert(out->canonical.end(), point, point + 3);
  }
}

namespace {

// Columns: the triangle's two edges and its unit normal; false when degenerate.
bool LocalFrame(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c, Eigen::Matrix3f* frame) {
  const Eigen::Vector3f e1 = b - a, e2 = c - a, n = e1.cross(e2);
  const float area2 = n.norm();
  if (!(area2 > 1e-12f)) return false;
  frame->col(0) = e1;
  frame->col(1) = e2;
  frame->col(2) = n / area2;
  return true;
}

}  // namespace

void CanonicalTransforms(const RayBatch& rays, const RowMatrixX3f& posed, const RasterFaces& faces,
                         const Eigen::VectorXf& canonical, std::vector<float>* out,
                         const std::vector<uint8_t>* covered) {
  CheckCanonicalVertices("CanonicalTransforms", canonical, posed.rows());
  if (covered && covered->size() != static_cast<size_t>(faces.rows()))
    throw std::invalid_argument("CanonicalTransforms: " + std::to_string(covered->size()) +
                                " covered flags for a mesh of " + std::to_string(faces.rows()) + " faces");
  out->assign(12 * rays.face.size(), 0.f);
  for (size_t r = 0; r < rays.face.size(); ++r) {
    float* t = out->data() + 12 * r;
    t[0] = t[4] = t[8] = 1.f;  // identity unless the ray has a usable triangle
    const int f = rays.face[r];
    if (f < 0 || f >= faces.rows()) continue;
    Eigen::Matrix3f from, to;
    const auto corner = [&](int k) { return Eigen::Vector3f(canonical.segment<3>(3 * faces(f, k))); };
    if (!LocalFrame(posed.row(faces(f, 0)), posed.row(faces(f, 1)), posed.row(faces(f, 2)), &from) ||
        !LocalFrame(corner(0), corner(1), corner(2), &to))
      continue;
    Eigen::Matrix3f a = to * from.inverse();
    Eigen::Vector3f o = corner(0) - a * posed.row(faces(f, 0)).transpose();
    if (covered && (*covered)[f]) {  // p -> To + s (A p + o - From)
      a *= kCoveredApartScale;
      o = kCoveredApartTo + kCoveredApartScale * (o - kCoveredApartFrom);
    }
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) t[3 * i + j] = a(i, j);
      t[9 + i] = o[i];
    }
  }
}

}  // namespace headcast
