// The CPU rasteriser: coverage, perspective-correct interpolation, z-buffer, culling, shading.
#include "common/raster/rasterizer.h"

#include <gtest/gtest.h>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/raster/shading.h"

namespace headcast {
namespace {

PinholeCamera Camera() { return PinholeCamera::FromFovY(64, 64, 60); }

// A slanted triangle facing the camera (counter-clockwise seen from the camera side, y down).
RasterVertices Slanted() {
  RasterVertices v(3, 3);
  v << -0.4f, -0.3f, 1.0f,  //
      0.0f, 0.4f, 2.0f,     //
      0.5f, -0.3f, 1.5f;
  return v;
}

TEST(Rasterizer, PerspectiveCorrectDepthAndAttributes) {
  const PinholeCamera cam = Camera();
  RasterFaces f(1, 3);
  f << 0, 1, 2;
  RasterBuffers buf;
  RasterOptions o;
  o.cull_back_faces = false;
  const RasterVertices v = Slanted();
  Rasterize(v, f, cam, o, &buf);
  ASSERT_GT(buf.CoveredPixels(), 100);
  // An attribute linear in 3D (here x + 2y + 3z) must interpolate exactly at
  // the ray-plane intersection; depth must be the plane's depth.
  Eigen::MatrixXf attr(3, 1);
  for (int i = 0; i < 3; ++i) attr(i, 0) = v(i, 0) + 2 * v(i, 1) + 3 * v(i, 2);
  const cv::Mat interp = InterpolateVertexAttribute(buf, f, attr);
  const Eigen::Vector3f n = (v.row(1) - v.row(0)).cross(v.row(2) - v.row(0)).transpose();
  int checked = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      if (!buf.Covered(x, y)) continue;
      const Eigen::Vector3f ray((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1);
      const float t = n.dot(v.row(0).transpose()) / n.dot(ray);
      const Eigen::Vector3f p = t * ray;
      EXPECT_NEAR(buf.depth[y * cam.width + x], p.z(), 1e-4);
      EXPECT_NEAR(interp.at<float>(y, x), p.x() + 2 * p.y() + 3 * p.z(), 1e-3);
      const float* b = &buf.bary[3 * (y * cam.width + x)];
      EXPECT_NEAR(b[0] + b[1] + b[2], 1, 1e-5);
      ++checked;
    }
  EXPECT_EQ(checked, buf.CoveredPixels());
}

TEST(Rasterizer, CullsBackFacesAndKeepsTheNearest) {
  const PinholeCamera cam = Camera();
  RasterVertices v(6, 3);
  // Two overlapping squares' worth of triangles at z = 1 (near) and z = 2 (far), same winding.
  v << -0.3f, -0.3f, 2, -0.3f, 0.3f, 2, 0.3f, -0.3f, 2,  //
      -0.2f, -0.2f, 1, -0.2f, 0.2f, 1, 0.2f, -0.2f, 1;
  RasterFaces f(2, 3);
  f << 0, 1, 2, 3, 4, 5;  // front-facing: negative signed area in image coordinates
  RasterBuffers buf;
  Rasterize(v, f, cam, RasterOptions{}, &buf);
  const int centre = 32 * cam.width + 28;
  ASSERT_EQ(buf.face[centre], 1);
  EXPECT_NEAR(buf.depth[centre], 1.0, 1e-5);
  RasterFaces swapped(2, 3);
  swapped << 3, 4, 5, 0, 1, 2;  // drawing order must not matter
  Rasterize(v, swapped, cam, RasterOptions{}, &buf);
  EXPECT_EQ(buf.face[centre], 0);
  EXPECT_NEAR(buf.depth[centre], 1.0, 1e-5);
  RasterFaces back(1, 3);
  back << 0, 2, 1;  // reversed winding: facing away
  Rasterize(v, back, cam, RasterOptions{}, &buf);
  EXPECT_EQ(buf.CoveredPixels(), 0);
  RasterOptions no_cull;
  no_cull.cull_back_faces = false;
  Rasterize(v, back, cam, no_cull, &buf);
  EXPECT_GT(buf.CoveredPixels(), 0);
  // Behind the near plane: dropped, not drawn inverted.
  RasterVertices behind = v;
  behind.col(2).setConstant(-1);
  Rasterize(behind, f, cam, no_cull, &buf);
  EXPECT_EQ(buf.CoveredPixels(), 0);
}

TEST(Shading, AmbientLightScalesAlbedoAndTextureIsSampled) {
  const PinholeCamera cam = Camera();
  RasterVertices v(4, 3);
  v << -0.5f, -0.5f, 1, 0.5f, -0.5f, 1, 0.5f, 0.5f, 1, -0.5f, 0.5f, 1;
  RasterFaces f(2, 3);
  f << 0, 3, 2, 0, 2, 1;
  RasterUvs uv(4, 2);
  uv << 0, 0, 1, 0, 1, 1, 0, 1;
  RasterBuffers buf;
  Rasterize(v, f, cam, RasterOptions{}, &buf);
  ASSERT_GT(buf.CoveredPixels(), 500);
  cv::Mat tex(2, 2, CV_32FC3);
  tex.at<cv::Vec3f>(0, 0) = {1, 0, 0};
  tex.at<cv::Vec3f>(0, 1) = {0, 1, 0};
  tex.at<cv::Vec3f>(1, 0) = {0, 0, 1};
  tex.at<cv::Vec3f>(1, 1) = {1, 1, 1};
  const cv::Mat albedo = SampleTexture(buf, f, uv, tex);
  // Top-left of the quad (image) samples the top-left texel: red.
  const cv::Vec3f tl = albedo.at<cv::Vec3f>(18, 18), br = albedo.at<cv::Vec3f>(45, 45);
  EXPECT_GT(tl[0], 0.9f);
  EXPECT_LT(tl[1], 0.1f);
  EXPECT_GT(br[1], 0.9f);
  ShLighting ambient{};
  for (int c = 0; c < 3; ++c) ambient[9 * c] = 2.0f;
  const cv::Mat normals(64, 64, CV_32FC3, cv::Scalar(0, 0, -1));
  const cv::Mat shaded = ShadeSphericalHarmonics(buf, albedo, normals, ambient, {0.5f, 0.5f, 0.5f});
  EXPECT_NEAR(shaded.at<cv::Vec3f>(18, 18)[0], tl[0] * 2.0f * 0.282095f, 1e-5);
  EXPECT_NEAR(shaded.at<cv::Vec3f>(0, 0)[1], 0.5f, 1e-6);  // background
}

TEST(HeadRender, BuiltinHeadSilhouetteIsPlausible) {
  const HeadModel m = MakeBuiltinHead();
  const PinholeCamera cam = PinholeCamera::FromFovY(256, 256, 24);
  const HeadModelOutput rest = m.Forward(HeadModelParams{});
  const HeadRender r = RenderHead(m, rest.vertices, FrontalCamFromHead(0.75), cam, AlbedoTexture(m));
  const int covered = cv::countNonZero(r.mask);
  EXPECT_GT(covered, 256 * 256 / 10);
  EXPECT_LT(covered, 256 * 256 / 2);
  // Left-right symmetric silhouette for a frontal view.
  cv::Mat flipped;
  cv::flip(r.mask, flipped, 1);
  cv::Mat diff;
  cv::absdiff(r.mask, flipped, diff);
  EXPECT_LT(cv::countNonZero(diff), covered / 20);
  // Depth at the image centre is about the camera distance minus the face depth.
  double lo, hi;
  cv::minMaxLoc(r.depth, &lo, &hi, nullptr, nullptr, r.mask);
  EXPECT_GT(lo, 0.6);
  EXPECT_LT(hi, 1.0);
  // The face is lit, the background is the background colour.
  const cv::Vec3b face = r.image_bgr.at<cv::Vec3b>(128, 128);
  EXPECT_GT(face[2], 100);
  EXPECT_EQ(r.image_bgr.at<cv::Vec3b>(2, 2), cv::Vec3b(51, 43, 41));
}

}  // namespace
}  // namespace headcast
