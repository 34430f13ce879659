// The canonical head: the surface texture's mapping through the rasterised
// posed mesh, the CNeRF samples' per-ray transforms, the texture's start (the
// picture unchanged), learning, and its file.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <limits>

#include "common/avatar/avatar_pipeline.h"
#include "common/avatar/triplane_lookup.h"
#include "common/core/rotation.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "tests/testing/posed_head.h"
#include "tests/testing/test_data.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

using testing::Expressive;
using testing::Pose;
using testing::Posed;
std::shared_ptr<const HeadModel> Builtin() { return testing::BuiltinHead(); }

AvatarConfig TinyWithSurface() {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.surface_features = 4;
  c.surface_resolution = 32;
  return c;
}

// What the receiver shows for `frame`.
cv::Mat Shown(Avatar& avatar, const FrameParams& frame) {
  const HeadModel& m = *Builtin();
  avatar.modules().eval();
  torch::InferenceMode inference;
  RaySampler sampler(avatar.config());
  AvatarFrameInputs buffers;
  cv::Mat image;
  RenderAvatarFrame(avatar.modules(), avatar.config(), m, m.MakeIdentity(avatar.subject().shape.cast<double>()),
                    avatar.subject(), frame, &sampler, &buffers, &image);
  return image;
}

// A texture of configuration `c` added to a random general model draws the
// general model's picture; with its weights drawn at random, saved under `dir`
// and loaded back, it draws what it drew. Returns the added and the loaded avatar.
std::pair<Avatar, Avatar> AddedSavedAndLoaded(const AvatarConfig& c, const std::string& dir) {
  const HeadModel& m = *Builtin();
  Avatar general = Avatar::CreateRandom(testing::TinyAvatarConfig(), m, DefaultSubject(m, 128), 3);
  Avatar with = general.WithRuntimeSwitches(c);
  const FrameParams frame = Expressive();
  EXPECT_EQ(cv::norm(Shown(general, frame), Shown(with, frame), cv::NORM_INF), 0) << "added: the same picture";
  {
    torch::NoGradGuard no_grad;
    for (auto& t : with.modules().surface->parameters()) t.uniform_(-1, 1);
  }
  with.Save(dir + "/added.hcavatar");
  Avatar back = Avatar::Load(dir + "/added.hcavatar", m);
  EXPECT_EQ(cv::norm(Shown(with, frame), Shown(back, frame), cv::NORM_INF), 0) << "loaded: what the saved one drew";
  return {std::move(with), std::move(back)};
}

// `to` takes every weight of `from` that it has by name (CNeRF, renderer,
// texture); returns the names of those it has and `from` lacks.
std::vector<std::string> CopySharedWeights(Avatar& from, Avatar& to) {
  torch::NoGradGuard no_grad;
  std::vector<std::string> missing;
  auto copy = [&](const torch::nn::Module& a, torch::nn::Module& b) {
    const auto source = a.named_parameters();
    for (auto& p : b.named_parameters()) {
      if (const torch::Tensor* t = source.find(p.key())) {
        p.value().copy_(*t);
      } else {
        missing.push_back(p.key());
      }
    }
  };
  copy(*from.modules().cnerf, *to.modules().cnerf);
  copy(*from.modules().renderer, *to.modules().renderer);
  copy(*from.modules().surface, *to.modules().surface);
  return missing;
}

Eigen::Vector3f Corner(const Eigen::VectorXf& flat, int v) { return {flat[3 * v], flat[3 * v + 1], flat[3 * v + 2]}; }

// The tiny avatar's mesh-guided rays of `frame`, posed as `p`, on a 32² feature map.
RayBatch FeatureRays(const Posed& p, const FrameParams& frame) {
  RayBatch rays;
  RaySampler(testing::TinyAvatarConfig())
      .Sample(p.v_cam, Builtin()->data().faces, p.camera.Resized(32, 32), frame.CamFromHead(), nullptr, &rays);
  return rays;
}

}  // namespace

// Each covered pixel's canonical point lies on the canonical triangle under
// the pixel, and carried back through that triangle's barycentrics onto the
// posed triangle it lands on the pixel: the mapping inverts the posed mesh on its surface.
TEST(SurfaceSampling, TheCanonicalPointMapsBackOntoThePixel) {
  const HeadModel& m = *Builtin();
  const Posed p = Pose(Expressive(), 128);
  const RasterFaces& faces = m.data().faces;
  RaySampler sampler(TinyWithSurface());
  SurfaceBatch surface;
  sampler.SampleSurface(p.v_cam, faces, p.identity.v_shaped, p.camera, &surface);
  RasterBuffers raster;
  Rasterize(p.v_cam, faces, p.camera, RasterOptions{}, &raster);
  ASSERT_EQ(surface.num_pixels(), raster.CoveredPixels());
  ASSERT_GT(surface.num_pixels(), 1000);
  ASSERT_EQ(surface.canonical.size(), 3u * surface.num_pixels());
  double worst_px = 0, worst_plane = 0, moved = 0;
  for (int i = 0; i < surface.num_pixels(); ++i) {
    const int px = surface.pixel[i], f = raster.face[px];
    ASSERT_GE(f, 0);
    const Eigen::Vector3f c(surface.canonical[3 * i], surface.canonical[3 * i + 1], surface.canonical[3 * i + 2]);
    // Barycentrics of c in the canonical triangle (least squares on the plane).
    const Eigen::Vector3f a = Corner(p.identity.v_shaped, faces(f, 0)), b = Corner(p.identity.v_shaped, faces(f, 1)),
                          d = Corner(p.identity.v_shaped, faces(f, 2));
    Eigen::Matrix<float, 3, 2> e;
    e << b - a, d - a;
    const Eigen::Vector2f uv = e.colPivHouseholderQr().solve(c - a);
    worst_plane = std::max<double>(worst_plane, (a + e * uv - c).norm());
    const Eigen::Vector3f w(1 - uv[0] - uv[1], uv[0], uv[1]);
    EXPECT_GE(w.minCoeff(), -1e-3f) << "outside its triangle at pixel " << px;
    // The same barycentrics on the posed triangle, in the camera frame, projected.
    Eigen::Vector3f q = Eigen::Vector3f::Zero();
    for (int k = 0; k < 3; ++k) q += w[k] * p.v_cam.row(faces(f, k)).transpose();
    const Eigen::Vector2d at = p.camera.Project(q.cast<double>());
    const double dx = at.x() - px % p.camera.width, dy = at.y() - px / p.camera.width;
    worst_px = std::max(worst_px, std::hypot(dx, dy));
    // Where the expression moved the surface, the canonical point is not the posed one.
    Eigen::Vector3f posed_point = Eigen::Vector3f::Zero();
    for (int k = 0; k < 3; ++k) posed_point += w[k] * p.posed.vertices.row(faces(f, k)).transpose();
    moved = std::max<double>(moved, (posed_point - c).norm());
  }
  EXPECT_LT(worst_plane, 1e-5);
  EXPECT_LT(worst_px, 0.02);
  EXPECT_GT(moved, 0.005) << "the expression and jaw moved nothing: the test frame proves little";
}

// With the posed vertices, each mesh pixel also gets the posed surface point
// there: carried into the camera by the head's placement, it lands on the
// pixel; on an expressive frame it is not the canonical point.
TEST(SurfaceSampling, ThePosedPointIsTheSurfaceSeenAtThePixel) {
  const HeadModel& m = *Builtin();
  const FrameParams frame = Expressive();
  const Posed p = Pose(frame, 128);
  RaySampler sampler(TinyWithSurface());
  SurfaceBatch plain, with;
  sampler.SampleSurface(p.v_cam, m.data().faces, p.identity.v_shaped, p.camera, &plain);
  EXPECT_TRUE(plain.posed.empty()) << "no posed vertices, no posed points";
  sampler.SampleSurface(p.v_cam, m.data().faces, p.identity.v_shaped, p.camera, &with, &p.posed.vertices);
  ASSERT_EQ(with.pixel, plain.pixel);
  ASSERT_EQ(with.canonical, plain.canonical);
  ASSERT_EQ(with.posed.size(), with.canonical.size());
  ASSERT_GT(with.num_pixels(), 1000);
  const RigidTransform cam_from_head = frame.CamFromHead();
  double worst_px = 0, moved = 0;
  for (int i = 0; i < with.num_pixels(); ++i) {
    const Eigen::Vector3d q(with.posed[3 * i], with.posed[3 * i + 1], with.posed[3 * i + 2]);
    const Eigen::Vector2d at = p.camera.Project(cam_from_head.rotation * q + cam_from_head.translation);
    const int px = with.pixel[i];
    worst_px = std::max(worst_px, std::hypot(at.x() - px % p.camera.width, at.y() - px / p.camera.width));
    moved = std::max(
        moved,
        (q - Eigen::Vector3d(with.canonical[3 * i], with.canonical[3 * i + 1], with.canonical[3 * i + 2])).norm());
  }
  EXPECT_LT(worst_px, 0.02);
  EXPECT_GT(moved, 0.005) << "the expression moved nothing: the test frame proves little";
  RowMatrixX3f fewer = p.posed.vertices.topRows(10);
  EXPECT_THROW(sampler.SampleSurface(p.v_cam, m.data().faces, p.identity.v_shaped, p.camera, &with, &fewer),
               std::invalid_argument);
}

// The eyeballs' canonical points are folded about their eye's pivot onto one
// meridian: the same distance from the pivot and angle from the pole (+z),
// azimuth zero; every other point stays. Each mesh pixel keeps its triangle.
TEST(SurfaceSampling, TheEyeballsPointsAreFoldedOntoOneMeridian) {
  const HeadModel& m = *Builtin();
  FrameParams frame = Expressive();
  frame.left_eye = Eigen::Vector3f(0.2f, 0.3f, 0);  // a gaze: the eyeball's pixels are not its rest front
  frame.right_eye = Eigen::Vector3f(0.2f, 0.3f, 0);
  const Posed p = Pose(frame, 256);
  RaySampler sampler(TinyWithSurface());
  SurfaceBatch plain;
  sampler.SampleSurface(p.v_cam, m.data().faces, p.identity.v_shaped, p.camera, &plain);
  ASSERT_EQ(plain.face.size(), static_cast<size_t>(plain.num_pixels()));
  SurfaceBatch folded = plain;
  const int moved = FoldEyeballPoints(m, p.identity, &folded);
  ASSERT_GT(moved, 20) << "the test frame shows too little of the eyeballs";
  EXPECT_LT(moved, plain.num_pixels() / 10);
  int changed = 0;
  for (int i = 0; i < plain.num_pixels(); ++i) {
    const Eigen::Vector3f a(plain.canonical[3 * i], plain.canonical[3 * i + 1], plain.canonical[3 * i + 2]);
    const Eigen::Vector3f b(folded.canonical[3 * i], folded.canonical[3 * i + 1], folded.canonical[3 * i + 2]);
    const int f = plain.face[i];
    int eye = -1;
    for (int joint : {kLeftEyeJoint, kRightEyeJoint})
      if (m.data().weights(m.data().faces(f, 0), joint) > 0.5f &&
          m.data().weights(m.data().faces(f, 1), joint) > 0.5f && m.data().weights(m.data().faces(f, 2), joint) > 0.5f)
        eye = joint;
    if (eye < 0) {
      EXPECT_EQ(a, b) << "pixel " << i << " is not on an eyeball";
      continue;
    }
    const Eigen::Vector3f c = p.identity.joints.row(eye).transpose();
    EXPECT_NEAR((b - c).norm(), (a - c).norm(), 1e-6);
    EXPECT_NEAR(b.z(), a.z(), 1e-7) << "the same angle from the pole";
    EXPECT_NEAR(b.y(), c.y(), 1e-7) << "on the meridian";
    EXPECT_GE(b.x(), c.x());
    changed += (a - b).norm() > 1e-4;
  }
  EXPECT_GT(changed, moved / 2) << "most eyeball points lie off the meridian";
  SurfaceBatch lost = plain;
  lost.face.clear();
  EXPECT_THROW(FoldEyeballPoints(m, p.identity, &lost), std::invalid_argument);
}

// The avatar option folds them where the receiver and training prepare a
// frame, needs a texture, is kept in the file and is not a run-time switch.
TEST(SurfaceSampling, EyeSymmetryFoldsTheEyeballsOfTheFramesItPrepares) {
  const HeadModel& m = *Builtin();
  AvatarConfig c = TinyWithSurface();
  c.surface_eye_symmetry = true;
  c.Check();
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).surface_eye_symmetry);
  nlohmann::json old = c.ToJson();
  old.erase("surface_eye_symmetry");
  EXPECT_FALSE(AvatarConfig::FromJson(old).surface_eye_symmetry);
  AvatarConfig bad = testing::TinyAvatarConfig();
  bad.surface_eye_symmetry = true;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "no texture to look up";
  bad = c;
  bad.surface_displacement = true;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "the displacement would start at a folded point";

  const FrameParams frame = Expressive();
  const HeadIdentity identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  const SubjectParams subject = DefaultSubject(m, 128);
  RaySampler plain_sampler(TinyWithSurface()), sampler(c);
  AvatarFrameInputs plain, folded;
  PrepareAvatarFrame(TinyWithSurface(), m, identity, subject, frame, &plain_sampler, nullptr, &plain);
  PrepareAvatarFrame(c, m, identity, subject, frame, &sampler, nullptr, &folded);
  SurfaceBatch expected = plain.surface;
  ASSERT_GT(FoldEyeballPoints(m, identity, &expected), 0);
  EXPECT_EQ(folded.surface.canonical, expected.canonical);
  EXPECT_NE(folded.surface.canonical, plain.surface.canonical);

  auto [with, back] = AddedSavedAndLoaded(c, testing::TempDir("eye_symmetry"));
  EXPECT_TRUE(back.config().surface_eye_symmetry);
  EXPECT_THROW(with.WithRuntimeSwitches(TinyWithSurface()), std::invalid_argument);
}

// The shell leaves the mesh's pixels as they were and adds pixels beyond its
// silhouette, each mapped to a point the shell's thickness off the canonical surface.
TEST(SurfaceShell, AddsPixelsBeyondTheMeshOffTheCanonicalSurface) {
  const HeadModel& m = *Builtin();
  const Posed p = Pose(Expressive(), 128);
  const RasterFaces& faces = m.data().faces;
  AvatarConfig with_shell = TinyWithSurface();
  with_shell.surface_shell = 0.02;
  RaySampler plain_sampler(TinyWithSurface()), shell_sampler(with_shell);
  SurfaceBatch plain, shell;
  plain_sampler.SampleSurface(p.v_cam, faces, p.identity.v_shaped, p.camera, &plain);
  shell_sampler.SampleSurface(p.v_cam, faces, p.identity.v_shaped, p.camera, &shell);
  EXPECT_EQ(plain.mesh_pixels, plain.num_pixels()) << "without a shell every pixel is the mesh's";
  ASSERT_EQ(shell.mesh_pixels, plain.num_pixels());
  EXPECT_TRUE(std::equal(plain.pixel.begin(), plain.pixel.end(), shell.pixel.begin()));
  EXPECT_TRUE(std::equal(plain.canonical.begin(), plain.canonical.end(), shell.canonical.begin()));
  const int added = shell.num_pixels() - shell.mesh_pixels;
  EXPECT_GT(added, 300) << "a 2 cm shell around a head ~100 px wide adds a ring of pixels";
  ASSERT_EQ(shell.canonical.size(), 3u * shell.num_pixels());
  std::vector<bool> on_mesh(128 * 128, false);
  for (int i = 0; i < shell.mesh_pixels; ++i) on_mesh[shell.pixel[i]] = true;
  const Eigen::Index vertices = p.identity.v_shaped.size() / 3;
  double nearest_min = 1e9, nearest_max = 0;
  for (int i = shell.mesh_pixels; i < shell.num_pixels(); ++i) {
    EXPECT_FALSE(on_mesh[shell.pixel[i]]) << "pixel " << shell.pixel[i] << " is the mesh's and the shell's";
    const Eigen::Vector3f c(shell.canonical[3 * i], shell.canonical[3 * i + 1], shell.canonical[3 * i + 2]);
    double nearest = 1e9;
    for (Eigen::Index v = 0; v < vertices; ++v)
      nearest = std::min<double>(nearest, (Corner(p.identity.v_shaped, v) - c).norm());
    nearest_min = std::min(nearest_min, nearest);
    nearest_max = std::max(nearest_max, nearest);
  }
  // The nearest vertex is a little farther than the surface; normals averaged
  // over corners bring the shell a little nearer than its thickness.
  EXPECT_GT(nearest_min, 0.6 * 0.02);
  EXPECT_LT(nearest_max, 1.5 * 0.02);
}

// Unposed and unexpressive, the posed mesh is the canonical one moved rigidly:
// a shell pixel's canonical point, moved alike, lands on the pixel.
TEST(SurfaceShell, OnTheNeutralHeadTheShellPointLandsOnItsPixel) {
  const HeadModel& m = *Builtin();
  FrameParams neutral;
  neutral.expression = Eigen::VectorXf::Zero(m.num_expression());
  neutral.SetCamFromHead(FrontalCamFromHead(0.62));
  const Posed p = Pose(neutral, 128);
  AvatarConfig c = TinyWithSurface();
  c.surface_shell = 0.03;
  RaySampler sampler(c);
  SurfaceBatch shell;
  sampler.SampleSurface(p.v_cam, m.data().faces, p.identity.v_shaped, p.camera, &shell);
  ASSERT_GT(shell.num_pixels() - shell.mesh_pixels, 300);
  const RigidTransform cam_from_head = neutral.CamFromHead();
  double worst_px = 0;
  for (int i = shell.mesh_pixels; i < shell.num_pixels(); ++i) {
    const Eigen::Vector3d c(shell.canonical[3 * i], shell.canonical[3 * i + 1], shell.canonical[3 * i + 2]);
    const Eigen::Vector2d at = p.camera.Project(cam_from_head.Apply(c));
    const int px = shell.pixel[i];
    worst_px = std::max(worst_px, std::hypot(at.x() - px % 128, at.y() - px / 128));
  }
  EXPECT_LT(worst_px, 0.05);
}

TEST(SurfaceShell, NeedsATextureAndTravelsInTheFile) {
  AvatarConfig c = TinyWithSurface();
  c.surface_shell = 0.025;
  EXPECT_EQ(AvatarConfig::FromJson(c.ToJson()).surface_shell, 0.025);
  nlohmann::json old = c.ToJson();
  old.erase("surface_shell");
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_shell, 0) << "files from before the shell: the mesh only";
  AvatarConfig bad = c;
  bad.surface_shell = -0.01;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = testing::TinyAvatarConfig();
  bad.surface_shell = 0.02;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a shell without a texture to look up";
}

TEST(SurfaceSampling, RefusesCanonicalVerticesOfAnotherMesh) {
  const Posed p = Pose(Expressive(), 64);
  RaySampler sampler(TinyWithSurface());
  SurfaceBatch surface;
  const Eigen::VectorXf fewer = p.identity.v_shaped.head(p.identity.v_shaped.size() - 3);
  EXPECT_THROW(sampler.SampleSurface(p.v_cam, Builtin()->data().faces, fewer, p.camera, &surface),
               std::invalid_argument);
}

// A point on the posed triangle under a ray lands on the same barycentric
// point of the canonical triangle, and a point off it along the posed normal
// lands as far along the canonical normal.
TEST(CanonicalSamples, TheRaysTriangleCarriesItsSamplesToTheNeutralHead) {
  const HeadModel& m = *Builtin();
  const FrameParams frame = Expressive();
  const Posed p = Pose(frame, 128);
  const RasterFaces& faces = m.data().faces;
  const RayBatch rays = FeatureRays(p, frame);
  ASSERT_GT(rays.num_rays(), 100);
  ASSERT_EQ(rays.face.size(), rays.pixel.size());
  std::vector<float> to;
  CanonicalTransforms(rays, p.posed.vertices, faces, p.identity.v_shaped, &to);
  ASSERT_EQ(to.size(), 12u * rays.num_rays());
  double worst = 0, moved = 0;
  for (int r = 0; r < rays.num_rays(); ++r) {
    const int f = rays.face[r];
    ASSERT_GE(f, 0) << "a mesh-guided ray without a triangle";
    const Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>> a(to.data() + 12 * r);
    const Eigen::Map<const Eigen::Vector3f> o(to.data() + 12 * r + 9);
    const Eigen::Vector3f pa = p.posed.vertices.row(faces(f, 0)), pb = p.posed.vertices.row(faces(f, 1)),
                          pc = p.posed.vertices.row(faces(f, 2));
    const Eigen::Vector3f ca = Corner(p.identity.v_shaped, faces(f, 0)), cb = Corner(p.identity.v_shaped, faces(f, 1)),
                          cc = Corner(p.identity.v_shaped, faces(f, 2));
    const Eigen::Vector3f pn = (pb - pa).cross(pc - pa).normalized(), cn = (cb - ca).cross(cc - ca).normalized();
    for (const Eigen::Vector3f& w : {Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0.2f, 0.3f, 0.5f)})
      for (float d : {0.f, 0.02f, -0.01f}) {
        const Eigen::Vector3f posed = w[0] * pa + w[1] * pb + w[2] * pc + d * pn;
        const Eigen::Vector3f want = w[0] * ca + w[1] * cb + w[2] * cc + d * cn;
        worst = std::max<double>(worst, (a * posed + o - want).norm());
        moved = std::max<double>(moved, (posed - want).norm());
      }
  }
  EXPECT_LT(worst, 2e-5);
  EXPECT_GT(moved, 0.005) << "the expression and pose moved nothing: the test frame proves little";
  // A ray without a triangle keeps its point.
  RayBatch lone = rays;
  lone.face.assign(lone.face.size(), -1);
  CanonicalTransforms(lone, p.posed.vertices, faces, p.identity.v_shaped, &to);
  EXPECT_EQ(to[0], 1.f);
  EXPECT_EQ(to[1], 0.f);
  EXPECT_EQ(to[8], 1.f);
  EXPECT_EQ(to[9], 0.f);
  EXPECT_THROW(CanonicalTransforms(rays, p.posed.vertices, faces, p.identity.v_shaped.head(6), &to),
               std::invalid_argument);
}

TEST(CanonicalSamples, NeedMeshGuidedSamplingAndTravelInTheFile) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.canonical_samples = true;
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).canonical_samples);
  c.sampling = SamplingMode::kUniform;
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

// With a rigid margin, the rays beside the silhouette carry no triangle (their
// samples stay in the head frame: the identity map), and the rays over the
// mesh keep theirs; depths and pixels are those of the plain sampler.
TEST(CanonicalSamples, ARigidMarginKeepsTheRaysBesideTheHeadInTheHeadFrame) {
  const HeadModel& m = *Builtin();
  const FrameParams frame = Expressive();
  const Posed p = Pose(frame, 128);
  const RasterFaces& faces = m.data().faces;
  const PinholeCamera feature_camera = p.camera.Resized(32, 32);
  AvatarConfig c = testing::TinyAvatarConfig();
  c.canonical_samples = true;
  RayBatch plain, rigid;
  RaySampler(c).Sample(p.v_cam, faces, feature_camera, frame.CamFromHead(), nullptr, &plain);
  c.rigid_margin = true;
  RaySampler(c).Sample(p.v_cam, faces, feature_camera, frame.CamFromHead(), nullptr, &rigid);
  ASSERT_EQ(plain.pixel, rigid.pixel);
  ASSERT_EQ(plain.depths, rigid.depths);
  RasterOptions culled;
  culled.cull_back_faces = true;
  RasterBuffers under;
  Rasterize(p.v_cam, faces, feature_camera, culled, &under);
  int margin = 0;
  std::vector<float> to;
  CanonicalTransforms(rigid, p.posed.vertices, faces, p.identity.v_shaped, &to);
  for (int r = 0; r < rigid.num_rays(); ++r) {
    ASSERT_GE(plain.face[r], 0);
    if (under.face[rigid.pixel[r]] >= 0) {
      EXPECT_EQ(rigid.face[r], plain.face[r]) << "a ray over the mesh lost its triangle";
      continue;
    }
    ++margin;
    EXPECT_EQ(rigid.face[r], -1) << "a margin ray kept the nearest triangle";
    const Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>> a(to.data() + 12 * r);
    const Eigen::Map<const Eigen::Vector3f> o(to.data() + 12 * r + 9);
    EXPECT_TRUE(a.isIdentity(0) && o.isZero(0));
  }
  EXPECT_GT(margin, 20) << "no rays beside the silhouette: the test proves little";
  // It travels in the file, files from before have none, and it needs canonical samples.
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).rigid_margin);
  nlohmann::json old = c.ToJson();
  old.erase("rigid_margin");
  EXPECT_FALSE(AvatarConfig::FromJson(old).rigid_margin);
  c.canonical_samples = false;
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

// Seen from the front, a face that shows in no pixel and has another surface
// more than 2 mm before its centre, within the depth, is covered; the
// covering surface, a face beside it, one behind it beyond the depth or
// within 2 mm of it, and one looking away are not.
TEST(CoveredFaces, AreWhatTheNeutralHeadHidesBehindASurfaceJustInFront) {
  // Squares of two triangles each, 2 cm tall, counter-clockwise seen from +z
  // unless they look away.
  std::vector<Eigen::Vector3f> v;
  RasterFaces faces(12, 3);
  auto square = [&](int at, float x0, float x1, float z, bool away) {
    const int base = static_cast<int>(v.size());
    v.insert(v.end(), {{x0, -0.01f, z}, {x1, -0.01f, z}, {x1, 0.01f, z}, {x0, 0.01f, z}});
    faces.row(2 * at) << base, base + 1, base + 2;
    faces.row(2 * at + 1) << base, base + 2, base + 3;
    if (away) {
      std::swap(faces(2 * at, 1), faces(2 * at, 2));
      std::swap(faces(2 * at + 1, 1), faces(2 * at + 1, 2));
    }
  };
  square(0, 0.f, 0.02f, 0.f, false);            // covered by the front one, 1 cm before it
  square(1, -0.005f, 0.025f, 0.01f, false);     // front (taller: the corners' rows)
  square(2, 0.005f, 0.015f, -0.1f, false);      // 11 cm behind the front one
  square(3, 0.005f, 0.015f, 0.004f, true);      // looks away
  square(4, 0.03f, 0.05f, 0.f, false);          // beside the front one: seen
  square(5, 0.f, 0.01f, 0.009f, false);         // 1 mm behind the front one
  for (int k : {4, 5, 6, 7}) v[k].y() *= 1.2f;  // the front square's corners beyond the others'
  Eigen::VectorXf flat(3 * v.size());
  for (size_t i = 0; i < v.size(); ++i) flat.segment<3>(3 * i) = v[i];
  const std::vector<uint8_t> covered = CoveredFaces(flat, faces, 0.055f);
  ASSERT_EQ(covered.size(), 12u);
  EXPECT_EQ(covered[0] + covered[1], 2) << "1 cm behind the front square";
  EXPECT_EQ(covered[2] + covered[3], 0) << "the front square covers, it is not covered";
  EXPECT_EQ(covered[4] + covered[5], 0) << "11 cm behind: beyond the depth";
  EXPECT_EQ(covered[6] + covered[7], 0) << "a face looking away";
  EXPECT_EQ(covered[8] + covered[9], 0) << "seen beside the front square";
  EXPECT_EQ(covered[10] + covered[11], 0) << "within 2 mm: a neighbour's pixel, not a covering surface";
  const std::vector<uint8_t> deeper = CoveredFaces(flat, faces, 0.2f);
  EXPECT_EQ(deeper[4] + deeper[5], 2) << "within a deeper depth";
  EXPECT_THROW(CoveredFaces(flat.head(5), faces, 0.055f), std::invalid_argument);
  EXPECT_THROW(CoveredFaces(flat, faces, 0.f), std::invalid_argument);

  // The head: some of its eyeballs' faces lie under the lids, and no face
  // that covers another is covered.
  const HeadModel& m = *Builtin();
  const HeadIdentity identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  const std::vector<uint8_t> head = CoveredFaces(identity.v_shaped, m.data().faces, 0.055f);
  int eyeball = 0, eyeball_covered = 0, any = 0;
  for (int f = 0; f < m.num_faces(); ++f) {
    bool on_eye = false;
    for (int joint : {kLeftEyeJoint, kRightEyeJoint})
      on_eye = on_eye || (m.data().weights(m.data().faces(f, 0), joint) > 0.5f &&
                          m.data().weights(m.data().faces(f, 1), joint) > 0.5f &&
                          m.data().weights(m.data().faces(f, 2), joint) > 0.5f);
    eyeball += on_eye;
    eyeball_covered += on_eye && head[f];
    any += head[f];
  }
  ASSERT_GT(eyeball, 0);
  EXPECT_GT(eyeball_covered, 0) << "the lids cover no part of the eyeballs";
  EXPECT_LT(eyeball_covered, eyeball) << "the eyes are open in the neutral head";
  EXPECT_LT(any, m.num_faces() / 5);
}

// With the covered table, a covered triangle's rays are carried on to the
// covered parts' place: To + s (the plain map - From); the others keep theirs.
TEST(CanonicalSamples, CoveredRaysAreCarriedApart) {
  const HeadModel& m = *Builtin();
  const FrameParams frame = Expressive();
  const Posed p = Pose(frame, 128);
  const RasterFaces& faces = m.data().faces;
  const RayBatch rays = FeatureRays(p, frame);
  std::vector<uint8_t> covered(static_cast<size_t>(faces.rows()), 0);
  for (size_t f = 0; f < covered.size(); f += 2) covered[f] = 1;
  std::vector<float> plain, apart;
  CanonicalTransforms(rays, p.posed.vertices, faces, p.identity.v_shaped, &plain);
  CanonicalTransforms(rays, p.posed.vertices, faces, p.identity.v_shaped, &apart, &covered);
  int moved = 0;
  for (int r = 0; r < rays.num_rays(); ++r) {
    const Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>> a(plain.data() + 12 * r),
        b(apart.data() + 12 * r);
    const Eigen::Map<const Eigen::Vector3f> oa(plain.data() + 12 * r + 9), ob(apart.data() + 12 * r + 9);
    const Eigen::Vector3f point(0.01f, 0.02f, 0.09f);
    const Eigen::Vector3f want =
        covered[rays.face[r]]
            ? Eigen::Vector3f(kCoveredApartTo + kCoveredApartScale * (a * point + oa - kCoveredApartFrom))
            : Eigen::Vector3f(a * point + oa);
    EXPECT_LT((b * point + ob - want).norm(), 1e-6) << "ray " << r;
    moved += covered[rays.face[r]];
  }
  EXPECT_GT(moved, 20);
  EXPECT_LT(moved, rays.num_rays());
  covered.pop_back();
  EXPECT_THROW(CanonicalTransforms(rays, p.posed.vertices, faces, p.identity.v_shaped, &apart, &covered),
               std::invalid_argument);
}

// The avatar option carries the covered parts apart where the receiver and
// training prepare a frame (rays and texture points alike), needs canonical
// samples, refuses the displacement and is kept in the file.
TEST(CanonicalSamples, CoveredApartMovesTheRaysAndTextureOfTheFramesItPrepares) {
  const HeadModel& m = *Builtin();
  AvatarConfig plain_config = TinyWithSurface();
  plain_config.canonical_samples = true;
  AvatarConfig c = plain_config;
  c.covered_apart = true;
  c.Check();
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).covered_apart);
  nlohmann::json old = c.ToJson();
  old.erase("covered_apart");
  EXPECT_FALSE(AvatarConfig::FromJson(old).covered_apart);
  AvatarConfig bad = c;
  bad.canonical_samples = false;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "nothing carries the rays";
  bad = c;
  bad.surface_displacement = true;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "the displacement would start at a moved point";

  FrameParams frame = Expressive();
  frame.jaw = Eigen::Vector3f(0.3f, 0, 0);                         // the mouth open: its inside seen
  frame.left_eye = frame.right_eye = Eigen::Vector3f(0.4f, 0, 0);  // the eyeballs turned: their covered parts seen
  const HeadIdentity identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  const SubjectParams subject = DefaultSubject(m, 128);
  RaySampler plain_sampler(plain_config), sampler(c);
  AvatarFrameInputs plain, apart;
  PrepareAvatarFrame(plain_config, m, identity, subject, frame, &plain_sampler, nullptr, &plain);
  PrepareAvatarFrame(c, m, identity, subject, frame, &sampler, nullptr, &apart);
  const std::vector<uint8_t> covered =
      CoveredFaces(identity.v_shaped, m.data().faces, static_cast<float>(c.shell_front + c.shell_back));
  EXPECT_EQ(sampler.Covered(identity.v_shaped, m.data().faces), covered);
  SurfaceBatch expected = plain.surface;
  EXPECT_GT(MoveCoveredPointsApart(covered, &expected), 0) << "the frame shows nothing the neutral head covers";
  EXPECT_EQ(apart.surface.canonical, expected.canonical);
  std::vector<float> transforms;
  CanonicalTransforms(plain.rays, plain.posed.vertices, m.data().faces, identity.v_shaped, &transforms, &covered);
  EXPECT_EQ(apart.to_canonical, transforms);
  EXPECT_NE(apart.to_canonical, plain.to_canonical);
  SurfaceBatch lost = plain.surface;
  lost.face.clear();
  EXPECT_THROW(MoveCoveredPointsApart(covered, &lost), std::invalid_argument);
}

// With a span, the networks are told each expression coefficient held between
// its training frames' extremes and the posed mesh the frame's own: the
// picture of a frame beyond the span is the one the same networks draw from
// the frame's mesh with the held coefficients. The span travels in the file;
// files from before have none; one of the wrong size, reversed or not finite
// is refused.
TEST(ExpressionSpan, TheNetworksAreToldExpressionsWithinItTheMeshTheFramesOwn) {
  const HeadModel& m = *Builtin();
  AvatarConfig c = testing::TinyAvatarConfig();
  c.num_expression = m.num_expression();
  Avatar free = Avatar::CreateRandom(c, m, DefaultSubject(m, c.output_size), 3);
  AvatarConfig spanned = free.config();
  spanned.expression_low.assign(spanned.num_expression, -0.1f);
  spanned.expression_high.assign(spanned.num_expression, 0.2f);
  spanned.expression_high[0] = 2.f;  // the smile (1.5) lies within, the parted lips (1.0) beyond
  Avatar held = free.WithRuntimeSwitches(spanned);
  const FrameParams frame = Expressive();
  FrameParams within = frame;
  within.expression[8] = 0.2f;

  const int psi = spanned.expression_offset();
  const torch::Tensor told = MakeConditioning(spanned, held.subject(), frame).geometry;
  EXPECT_FLOAT_EQ(told[0][psi + 0].item<float>(), 1.5f);
  EXPECT_FLOAT_EQ(told[0][psi + 8].item<float>(), 0.2f);
  EXPECT_FLOAT_EQ(told[0][psi + 1].item<float>(), 0.f);
  EXPECT_TRUE(torch::equal(told, MakeConditioning(free.config(), free.subject(), within).geometry));
  EXPECT_FLOAT_EQ(MakeConditioning(free.config(), free.subject(), frame).geometry[0][psi + 8].item<float>(), 1.f)
      << "no span: the frame's own";

  const HeadIdentity identity = m.MakeIdentity(held.subject().shape.cast<double>());
  RaySampler sampler(spanned);
  AvatarFrameInputs with_span, without;
  PrepareAvatarFrame(spanned, m, identity, held.subject(), frame, &sampler, nullptr, &with_span);
  PrepareAvatarFrame(free.config(), m, identity, free.subject(), frame, &sampler, nullptr, &without);
  EXPECT_TRUE(with_span.posed.vertices == without.posed.vertices) << "the mesh takes the frame's expression";
  EXPECT_EQ(with_span.rays.num_rays(), without.rays.num_rays());
  without.conditioning = MakeConditioning(free.config(), free.subject(), within);
  {
    torch::InferenceMode inference;
    held.modules().eval();
    free.modules().eval();
    EXPECT_TRUE(torch::allclose(RunAvatar(held.modules(), with_span).image, RunAvatar(free.modules(), without).image));
  }

  const AvatarConfig back = AvatarConfig::FromJson(spanned.ToJson());
  EXPECT_EQ(back.expression_low, spanned.expression_low);
  EXPECT_EQ(back.expression_high, spanned.expression_high);
  EXPECT_FALSE(AvatarConfig::FromJson(free.config().ToJson()).has_expression_span()) << "files from before it";
  AvatarConfig bad = spanned;
  bad.expression_low.pop_back();
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = spanned;
  bad.expression_low[3] = 0.5f;  // above its high
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  nlohmann::json j = spanned.ToJson();
  j["expression_span"]["high"][2] = nullptr;  // a NaN written by a JSON library
  EXPECT_THROW(AvatarConfig::FromJson(j), std::invalid_argument);
  j = spanned.ToJson();
  j["expression_span"]["high"] = nlohmann::json::array({1, 2});
  EXPECT_THROW(AvatarConfig::FromJson(j), std::invalid_argument);
}

// A conditioning bias is added to what the networks are told, after the
// span holds the expression and only where the motion conditioning tells
// them anything; it travels in the file; files from before have none; one of
// the wrong size or not finite is refused.
TEST(ConditioningBias, IsAddedToWhatTheNetworksAreToldAndTravelsInTheFile) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.num_expression = Builtin()->num_expression();
  const SubjectParams subject = DefaultSubject(*Builtin(), c.output_size);
  const FrameParams f = Expressive();
  const AvatarConditioning plain = MakeConditioning(c, subject, f);
  AvatarConfig biased = c;
  for (int i = 0; i < c.conditioning_dim(); ++i) biased.bias_geometry.push_back(0.01f * (i + 1));
  for (int i = 0; i < c.appearance_dim(); ++i) biased.bias_appearance.push_back(-0.02f * (i + 1));
  biased.Check();
  const AvatarConditioning told = MakeConditioning(biased, subject, f);
  for (int i = 0; i < c.conditioning_dim(); ++i)
    EXPECT_NEAR(told.geometry[0][i].item<float>() - plain.geometry[0][i].item<float>(), 0.01f * (i + 1), 1e-6) << i;
  for (int i = 0; i < c.appearance_dim(); ++i)
    EXPECT_NEAR(told.appearance[0][i].item<float>() - plain.appearance[0][i].item<float>(), -0.02f * (i + 1), 1e-6)
        << i;
  // After the span: a coefficient held at its high is told high + bias.
  const int psi = c.expression_offset();
  biased.expression_low.assign(c.num_expression, -1.f);
  biased.expression_high.assign(c.num_expression, 1.f);
  ASSERT_GT(f.expression[0], 1.f);
  EXPECT_NEAR(MakeConditioning(biased, subject, f).geometry[0][psi].item<float>(), 1.f + biased.bias_geometry[psi],
              1e-6);
  // Told only the neck: nothing else, bias or not.
  biased.motion_conditioning = MotionConditioning::kNeck;
  const torch::Tensor neck = MakeConditioning(biased, subject, f).geometry;
  const int jaw = c.pose_offset() + 3;
  EXPECT_EQ(neck.narrow(1, jaw, c.conditioning_dim() - jaw).abs().max().item<float>(), 0.f);
  EXPECT_NEAR(neck[0][0].item<float>() - plain.geometry[0][0].item<float>(), 0.01f, 1e-6) << "beta is always told";

  const AvatarConfig back = AvatarConfig::FromJson(biased.ToJson());
  EXPECT_EQ(back.bias_geometry, biased.bias_geometry);
  EXPECT_EQ(back.bias_appearance, biased.bias_appearance);
  EXPECT_FALSE(AvatarConfig::FromJson(c.ToJson()).has_conditioning_bias()) << "files from before it";
  AvatarConfig bad = biased;
  bad.bias_geometry.pop_back();
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = biased;
  bad.bias_appearance.clear();
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  nlohmann::json j = biased.ToJson();
  j["conditioning_bias"]["appearance"][4] = nullptr;  // a NaN written by a JSON library
  EXPECT_THROW(AvatarConfig::FromJson(j), std::invalid_argument);
  j = biased.ToJson();
  j["conditioning_bias"]["geometry"][2] = 1e30;
  EXPECT_THROW(AvatarConfig::FromJson(j), std::invalid_argument);
}

// What a mode leaves out of the conditioning is zero whatever the frame says;
// what it keeps is the frame's. The mode travels in the file; a foreign name
// is refused.
TEST(MotionConditioning, TellsTheNetworksOnlyWhatItsModeKeeps) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.num_expression = Builtin()->num_expression();
  const SubjectParams subject = DefaultSubject(*Builtin(), c.output_size);
  FrameParams f = Expressive();
  f.left_eye = Eigen::Vector3f(0.1f, -0.2f, 0);
  f.right_eye = Eigen::Vector3f(0.1f, -0.2f, 0);
  const int motion = c.num_shape;  // neck (3), jaw (3), eyes (6), then psi
  auto told = [&](MotionConditioning mode) {
    c.motion_conditioning = mode;
    return MakeConditioning(c, subject, f).geometry;
  };
  const torch::Tensor full = told(MotionConditioning::kFull);
  EXPECT_FLOAT_EQ(full[0][motion + 1].item<float>(), 0.3f);   // neck y
  EXPECT_FLOAT_EQ(full[0][motion + 3].item<float>(), 0.25f);  // jaw x
  EXPECT_FLOAT_EQ(full[0][motion + 7].item<float>(), -0.2f);  // left eye y
  EXPECT_FLOAT_EQ(full[0][motion + 12].item<float>(), 1.5f);  // psi 0
  const torch::Tensor no_expression = told(MotionConditioning::kNoExpression);
  EXPECT_TRUE(torch::equal(no_expression.narrow(1, 0, motion + 12), full.narrow(1, 0, motion + 12)));
  EXPECT_EQ(no_expression.narrow(1, motion + 12, c.num_expression).abs().max().item<float>(), 0.f);
  const torch::Tensor neck = told(MotionConditioning::kNeck);
  EXPECT_TRUE(torch::equal(neck.narrow(1, 0, motion + 3), full.narrow(1, 0, motion + 3)));
  EXPECT_EQ(neck.narrow(1, motion + 3, c.conditioning_dim() - motion - 3).abs().max().item<float>(), 0.f);

  for (MotionConditioning m :
       {MotionConditioning::kFull, MotionConditioning::kNoExpression, MotionConditioning::kNeck}) {
    c.motion_conditioning = m;
    EXPECT_EQ(AvatarConfig::FromJson(c.ToJson()).motion_conditioning, m) << MotionConditioningName(m);
  }
  nlohmann::json j = c.ToJson();
  j.erase("motion_conditioning");
  EXPECT_EQ(AvatarConfig::FromJson(j).motion_conditioning, MotionConditioning::kFull) << "files from before it";
  j["motion_conditioning"] = "expression";
  try {
    AvatarConfig::FromJson(j);
    ADD_FAILURE() << "a foreign mode accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("full, no_expression or neck"), std::string::npos) << e.what();
  }
}

// With the view's rotation told, the neck's place holds the head's rotation
// as the camera sees it composed with the neck's: zero for a frontal view
// and no neck, the neck's own for a frontal view, the view's for a turned
// head without one; off, the neck alone. It travels in the file.
TEST(MotionConditioning, TheViewsRotationIsToldInTheNecksPlace) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.num_expression = Builtin()->num_expression();
  const SubjectParams subject = DefaultSubject(*Builtin(), c.output_size);
  const int neck = c.pose_offset();
  auto told = [&](const FrameParams& f) {
    const torch::Tensor g = MakeConditioning(c, subject, f).geometry;
    return Eigen::Vector3d(g[0][neck].item<float>(), g[0][neck + 1].item<float>(), g[0][neck + 2].item<float>());
  };
  FrameParams frontal = Expressive();  // a frontal camera, the neck turned
  FrameParams turned = Expressive();
  turned.neck.setZero();
  turned.SetCamFromHead(FrontalCamFromHead(0.62, 20, -10));
  const Eigen::Vector3d view = ViewRotation(turned.CamFromHead().rotation);
  ASSERT_GT(view.norm(), 0.3);
  EXPECT_LT((told(turned)).norm(), 1e-6) << "off: the neck alone";
  c.view_rotation = true;
  EXPECT_LT((told(turned) - view).norm(), 1e-5);
  EXPECT_LT((told(frontal) - frontal.neck.cast<double>()).norm(), 1e-5);
  FrameParams both = turned;
  both.neck = Eigen::Vector3f(0, 0.2f, 0);
  const Eigen::Vector3d composed =
      MatrixToAxisAngle(AxisAngleToMatrix(view) * AxisAngleToMatrix(both.neck.cast<double>()));
  EXPECT_LT((told(both) - composed).norm(), 1e-5);
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).view_rotation);
  nlohmann::json old = c.ToJson();
  old.erase("view_rotation");
  EXPECT_FALSE(AvatarConfig::FromJson(old).view_rotation);
}

// A face is the hair's when no expression coefficient alone, at one unit,
// moves any of its corners by the reach (the head model posed, not its basis
// read) and none is skinned to the jaw or an eye; the table has both kinds.
TEST(HairConditioning, TheHairsFacesAreThoseNoExpressionMoves) {
  const HeadModel& m = *Builtin();
  const float reach = 0.003f;
  const std::vector<uint8_t> hair = HairFaces(m, reach);
  ASSERT_EQ(hair.size(), static_cast<size_t>(m.num_faces()));
  const HeadIdentity identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  HeadModelOutput rest, moved;
  m.Forward(identity, Eigen::VectorXd::Zero(m.num_expression()), PoseVector::Zero(), &rest);
  Eigen::VectorXf largest = Eigen::VectorXf::Zero(m.num_vertices());
  for (int e = 0; e < m.num_expression(); ++e) {
    m.Forward(identity, Eigen::VectorXd::Unit(m.num_expression(), e), PoseVector::Zero(), &moved);
    largest = largest.cwiseMax((moved.vertices - rest.vertices).rowwise().norm());
  }
  const auto& w = m.data().weights;
  int hair_faces = 0, face_faces = 0;
  for (int f = 0; f < m.num_faces(); ++f) {
    bool still = true;
    for (int k = 0; k < 3; ++k) {
      const int v = m.data().faces(f, k);
      still =
          still && largest[v] < reach - 1e-5f && w(v, kJawJoint) + w(v, kLeftEyeJoint) + w(v, kRightEyeJoint) <= 0.01f;
    }
    if (largest[m.data().faces(f, 0)] > reach + 1e-5f) EXPECT_EQ(hair[f], 0) << "face " << f << " moves";
    if (still) EXPECT_EQ(hair[f], 1) << "face " << f << " is still";
    (hair[f] ? hair_faces : face_faces)++;
  }
  EXPECT_GT(hair_faces, m.num_faces() / 10) << "no hair: the test proves little";
  EXPECT_GT(face_faces, m.num_faces() / 10) << "no face: the test proves little";
  EXPECT_EQ(HairFaces(m, 0.f), std::vector<uint8_t>(hair.size(), 0)) << "no reach: no hair";
  // However far the reach, what the jaw or an eye moves is the face's.
  ASSERT_TRUE(m.JointIsArticulated(kJawJoint));
  const std::vector<uint8_t> far = HairFaces(m, 1.f);
  int jaw = 0;
  for (int f = 0; f < m.num_faces(); ++f)
    if (w(m.data().faces(f, 0), kJawJoint) > 0.5f) {
      ++jaw;
      EXPECT_EQ(far[f], 0) << "face " << f << " turns with the jaw";
    }
  EXPECT_GT(jaw, 0);
}

// Per ray: 1 over a hair face or without a triangle (a rigid margin), 0
// elsewhere; a triangle beyond the table is refused.
TEST(HairConditioning, TheHairsRaysAreThoseOverItsFacesOrBesideTheHead) {
  RayBatch rays;
  rays.pixel = {0, 1, 2};
  rays.face = {0, 1, -1};
  std::vector<float> hair;
  HairRays(rays, {1, 0}, &hair);
  EXPECT_EQ(hair, (std::vector<float>{1, 0, 1}));
  rays.face[0] = 2;
  EXPECT_THROW(HairRays(rays, {1, 0}, &hair), std::invalid_argument);
}

// The hair's samples are told what the mode keeps (here the neck alone), the
// other samples everything: each draws what the network draws for its own
// conditioning, a change of the expression or jaw leaves the hair's alone,
// and the per-frame bias gives what concatenating every sample's gives.
TEST(HairConditioning, TheHairsSamplesAreToldOnlyWhatItsModeKeeps) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.num_expression = Builtin()->num_expression();
  c.hair_conditioning = MotionConditioning::kNeck;
  torch::manual_seed(5);
  CNeRF fast(c);
  c.precompute_conditioning = false;
  CNeRF slow(c);
  {
    torch::NoGradGuard no_grad;
    auto src = fast->named_parameters();
    for (auto& p : slow->named_parameters()) p.value().copy_(src[p.key()]);
  }
  torch::NoGradGuard no_grad;
  const int64_t n = 40;
  const torch::Tensor points = torch::randn({n, 3}) * 0.1;
  const torch::Tensor hair = (torch::arange(n) % 3 == 0).to(torch::kFloat);
  const AvatarConditioning cond{torch::randn({1, c.conditioning_dim()}), torch::randn({1, c.appearance_dim()})};
  AvatarConditioning neck = cond;
  neck.geometry = cond.geometry.clone();
  neck.geometry.narrow(1, c.pose_offset() + 3, c.conditioning_dim() - c.pose_offset() - 3).zero_();
  const auto [d, f] = fast->forward(points, cond, hair);
  const auto [d_all, f_all] = fast->forward(points, cond);
  const auto [d_neck, f_neck] = fast->forward(points, neck);
  const torch::Tensor is_hair = hair.to(torch::kBool);
  EXPECT_LT((f - torch::where(is_hair.unsqueeze(1), f_neck, f_all)).abs().max().item<float>(), 1e-5);
  EXPECT_LT((d - torch::where(is_hair, d_neck, d_all)).abs().max().item<float>(), 1e-5);
  EXPECT_GT((f_neck - f_all).abs().max().item<float>(), 1e-3) << "the motion changed nothing: the test proves little";
  const auto [d_slow, f_slow] = slow->forward(points, cond, hair);
  EXPECT_LT((f - f_slow).abs().max().item<float>(), 1e-5);
  EXPECT_LT((d - d_slow).abs().max().item<float>(), 1e-5);
  EXPECT_THROW(fast->forward(points, cond, hair.narrow(0, 0, n - 1)), std::invalid_argument);

  // It travels in the file; files from before have none; it needs mesh-guided sampling.
  EXPECT_EQ(AvatarConfig::FromJson(c.ToJson()).hair_conditioning, MotionConditioning::kNeck);
  nlohmann::json old = c.ToJson();
  old.erase("hair_conditioning");
  old.erase("hair_reach");
  EXPECT_EQ(AvatarConfig::FromJson(old).hair_conditioning, MotionConditioning::kFull);
  EXPECT_EQ(AvatarConfig::FromJson(old).hair_reach, AvatarConfig().hair_reach);
  c.sampling = SamplingMode::kUniform;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c.sampling = SamplingMode::kMeshGuided;
  c.hair_reach = -0.01;
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

// A frame's preparation marks its hair rays only when the avatar asks: off,
// none; on, the rays over the scalp and beside the head.
TEST(HairConditioning, TheFramesPreparationMarksTheHairsRays) {
  const HeadModel& m = *Builtin();
  AvatarConfig c = testing::TinyAvatarConfig();
  c.canonical_samples = true;
  const SubjectParams subject = DefaultSubject(m, c.output_size);
  const HeadIdentity identity = m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape()));
  AvatarFrameInputs inputs;
  RaySampler plain(c);
  PrepareAvatarRays(c, m, identity, subject, Expressive(), &plain, nullptr, &inputs);
  EXPECT_TRUE(inputs.hair_rays.empty());
  c.hair_conditioning = MotionConditioning::kNoExpression;
  RaySampler sampler(c);
  PrepareAvatarRays(c, m, identity, subject, Expressive(), &sampler, nullptr, &inputs);
  ASSERT_EQ(inputs.hair_rays.size(), static_cast<size_t>(inputs.rays.num_rays()));
  const std::vector<uint8_t> hair = HairFaces(m, static_cast<float>(c.hair_reach));
  int marked = 0;
  for (int r = 0; r < inputs.rays.num_rays(); ++r) {
    EXPECT_EQ(inputs.hair_rays[r], hair[inputs.rays.face[r]] ? 1.f : 0.f);
    marked += inputs.hair_rays[r] > 0;
  }
  EXPECT_GT(marked, 0);
  EXPECT_LT(marked, inputs.rays.num_rays());
}

TEST(SurfaceTexture, SamplesItsPlanesAtCanonicalPoints) {
  AvatarConfig c = TinyWithSurface();
  SurfaceTexture texture(c);
  const torch::Tensor points = torch::tensor({0.f, 0.f, 0.f, 0.05f, -0.1f, 0.02f, 9.f, 9.f, 9.f}).view({3, 3});
  EXPECT_EQ(texture->forward(points).abs().max().item<float>(), 0.f) << "a new texture is zero";
  {
    torch::NoGradGuard no_grad;
    for (auto& t : texture->parameters()) t.fill_(0.25f);
  }
  const torch::Tensor f = texture->forward(points);
  ASSERT_EQ(f.sizes(), (std::vector<int64_t>{3, c.surface_features}));
  // Three planes, each 0.25 everywhere (also beyond the extent: the border).
  EXPECT_NEAR(f.min().item<float>(), 0.75f, 1e-6);
  EXPECT_NEAR(f.max().item<float>(), 0.75f, 1e-6);
}

// The receiver's lookup (planes texel-major, no gradients) reads the same
// features as grid_sample: inside the planes, on texel centres and edges, and
// beyond the extent (the border repeated); with gradients it stays grid_sample.
TEST(SurfaceTexture, TheTexelMajorLookupReadsWhatGridSampleReads) {
  for (const int channels : {8, 5}) {  // the shipped count has a loop of its own
    AvatarConfig c = TinyWithSurface();
    c.surface_features = channels;
    SurfaceTexture texture(c);
    {
      torch::NoGradGuard no_grad;
      for (auto& t : texture->parameters()) t.uniform_(-1, 1);
    }
    const double e = c.surface_extent, texel = 2 * e / c.surface_resolution;
    const torch::Tensor points =
        torch::cat({(torch::rand({2000, 3}) * 2 - 1) * (1.2 * e),  // some beyond the extent
                    torch::tensor({0.f, 0.f, 0.f}).view({1, 3}),
                    torch::full({1, 3}, static_cast<float>(-e + texel / 2)),  // the first texel's centre
                    torch::full({1, 3}, static_cast<float>(e - texel / 2)),   // the last texel's centre
                    torch::full({1, 3}, static_cast<float>(e)), torch::full({1, 3}, -9.f)});
    const torch::Tensor expected = texture->forward(points).detach();
    texture->UseChannelsLast();
    torch::Tensor looked_up;
    {
      torch::NoGradGuard no_grad;
      looked_up = texture->forward(points);
    }
    ASSERT_EQ(looked_up.sizes(), expected.sizes());
    EXPECT_LT((looked_up - expected).abs().max().item<float>(), 1e-6) << channels;
    EXPECT_GT(expected.abs().max().item<float>(), 0.5f) << "a lookup of random planes is not zero";
    // Not a number (the receiver refuses such frames before) reads inside the planes.
    {
      torch::NoGradGuard no_grad;
      const float nan = std::numeric_limits<float>::quiet_NaN();
      EXPECT_TRUE(torch::isfinite(texture->forward(torch::tensor({nan, 0.f, nan}).view({1, 3}))).all().item<bool>());
    }
    // Training after the switch: grid_sample's gradients still reach the planes.
    texture->forward(points).sum().backward();
    EXPECT_GT(texture->parameters()[0].grad().abs().sum().item<float>(), 0.f) << channels;
  }
}

// The receiver's blended lookup blends only the texels the points read: what
// it adds is what blending every texel and looking the sum up gives — inside
// the planes, on their edges, beyond them, and for a point that is not a
// number — and the features already there are kept.
TEST(SurfaceTexture, TheReceiverBlendsOnlyTheTexelsItReads) {
  for (const int channels : {8, 5}) {
    const int64_t r = 16, k = 6;
    const torch::Tensor shapes = torch::rand({3 * r * r, k, channels}) * 2 - 1;  // texel, component, channel
    const torch::Tensor weights = torch::rand({k}) * 2 - 1;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    // A patch of the planes, as a face covers, and points on and beyond their edges.
    const torch::Tensor points =
        torch::cat({torch::rand({500, 3}) * 0.5 - 0.1,
                    torch::tensor({-1.f, -1.f, -1.f, 1.f, 1.f, 1.f, 2.f, -3.f, 0.f, nan, 0.2f, nan}).view({4, 3})})
            .contiguous();
    const torch::Tensor blended = (shapes * weights.view({1, k, 1})).sum(1).contiguous();  // texel-major planes
    const int64_t n = points.size(0);
    torch::Tensor expected = torch::empty({n, channels});
    LookUpTriplanes({blended.data_ptr<float>(), r, channels}, points.data_ptr<float>(), n, expected.data_ptr<float>());
    const torch::Tensor before = torch::rand({n, channels});
    torch::Tensor features = before.clone();
    AddBlendedLookUp({shapes.data_ptr<float>(), r, k, channels}, weights.data_ptr<float>(), points.data_ptr<float>(), n,
                     features.data_ptr<float>());
    EXPECT_TRUE(torch::isfinite(features).all().item<bool>()) << channels;
    EXPECT_LT((features - before - expected).abs().max().item<float>(), 1e-5) << channels;
    EXPECT_GT(expected.abs().max().item<float>(), 0.3f) << "random blendshapes add something";
  }
  EXPECT_THROW(AddBlendedLookUp({}, nullptr, nullptr, 0, nullptr), std::invalid_argument);
}

// Blendshapes changed after the switch to the receiver's layout (a load, a
// training step) are what its lookup reads.
TEST(SurfaceTexture, TheReceiversBlendshapesFollowTheirWeights) {
  AvatarConfig c = TinyWithSurface();
  c.surface_blend = 8;
  SurfaceTexture texture(c);
  const torch::Tensor canonical = (torch::rand({300, 3}) * 2 - 1) * 0.15;
  const torch::Tensor psi = torch::rand({1, c.num_expression}) * 2 - 1;
  texture->UseChannelsLast();
  torch::NoGradGuard no_grad;
  const torch::Tensor zero = texture->forward(canonical, {}, psi).clone();
  texture->named_parameters()["blend"].uniform_(-1, 1);
  const torch::Tensor changed = texture->forward(canonical, {}, psi);
  EXPECT_GT((changed - zero).abs().max().item<float>(), 0.1f) << "the new weights are read";
  // The same as the training path (grid_sample over every blended texel).
  torch::Tensor expected;
  {
    torch::AutoGradMode grad(true);
    expected = texture->forward(canonical, {}, psi).detach();
  }
  EXPECT_LT((changed - expected).abs().max().item<float>(), 1e-5);
}

// Adding a texture to an avatar without one (a fine-tune of a general model)
// changes nothing it draws until training moves it; then the texture learns.
TEST(SurfaceTexture, StartsAsTheAvatarWithoutItAndLearns) {
  const HeadModel& m = *Builtin();
  AvatarConfig plain = testing::TinyAvatarConfig();
  Avatar general = Avatar::CreateRandom(plain, m, DefaultSubject(m, 128), 3);
  Avatar with = general.WithRuntimeSwitches(TinyWithSurface());
  ASSERT_TRUE(with.modules().surface);
  const FrameParams frame = Expressive();
  EXPECT_EQ(cv::norm(Shown(general, frame), Shown(with, frame), cv::NORM_INF), 0);
  // A changed texture, or one taken away, is refused: only adding is a switch.
  AvatarConfig other = TinyWithSurface();
  other.surface_resolution = 64;
  EXPECT_THROW(with.WithRuntimeSwitches(other), std::invalid_argument);
  EXPECT_THROW(with.WithRuntimeSwitches(plain), std::invalid_argument);

  // Train on a flat target: after a few steps the texture is no longer zero.
  with.modules().train();
  AvatarFrameInputs inputs;
  RaySampler sampler(with.config());
  PrepareAvatarFrame(with.config(), m, m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape())), with.subject(), frame,
                     &sampler, nullptr, &inputs);
  ASSERT_GT(inputs.surface.num_pixels(), 0);
  const torch::Tensor target = torch::full({1, 3, 128, 128}, 0.8f);
  torch::optim::Adam adam(with.modules().parameters(), torch::optim::AdamOptions(1e-2));
  for (int step = 0; step < 3; ++step) {
    adam.zero_grad();
    torch::mse_loss(RunAvatar(with.modules(), inputs).image, target).backward();
    adam.step();
  }
  EXPECT_GT(with.modules().surface->parameters()[0].abs().max().item<float>(), 0.f);
}

// The receiver's surface branch (channels-last, no gradients) runs in one
// pass over the covered pixels at the shipped sizes (8 -> 16 -> 8): the same
// term as the layers one after the other, plain and conditioned, and as the
// layers at other sizes; pixels outside the image are refused.
TEST(SurfaceTexture, TheReceiversOnePassBranchDrawsWhatTheLayersDraw) {
  for (const auto [conditioned, shipped] : {std::pair{false, true}, {true, true}, {true, false}}) {
    AvatarConfig c = TinyWithSurface();
    c.surface_conditioned = conditioned;
    if (shipped) {
      c.surface_features = 8;
      c.renderer_channels.back() = 8;
    }
    NeuralRenderer net(c);
    torch::manual_seed(3);
    {
      torch::NoGradGuard no_grad;
      for (auto& p : net->parameters()) p.uniform_(-0.5, 0.5);
    }
    const torch::Tensor features = torch::randn({300, c.surface_features});
    const torch::Tensor pixels = torch::randperm(32 * 24).narrow(0, 0, 300);
    const torch::Tensor motion = conditioned ? torch::randn({1, c.motion_dim()}) : torch::Tensor();
    const torch::Tensor layers = net->SurfaceTerm(features, pixels, 32, 24, motion).detach();
    net->UseChannelsLast();
    torch::NoGradGuard no_grad;
    const torch::Tensor one_pass = net->SurfaceTerm(features, pixels, 32, 24, motion);
    ASSERT_EQ(one_pass.sizes(), layers.sizes());
    EXPECT_TRUE(one_pass.is_contiguous(torch::MemoryFormat::ChannelsLast));
    EXPECT_LT((one_pass - layers).abs().max().item<float>(), 1e-5) << conditioned << shipped;
    EXPECT_GT((layers - layers.mean()).abs().max().item<float>(), 0.1f) << "a random branch draws something";
    EXPECT_ANY_THROW(net->SurfaceTerm(features, torch::full({300}, 32 * 24, torch::kLong), 32, 24, motion));
  }
}

// A conditioned branch starts as the plain one; once its FiLM weights move,
// the same texture draws differently for another expression, it learns, and
// a branch asked without the frame's motion refuses.
TEST(SurfaceTexture, AConditionedBranchStartsPlainAndFollowsTheExpression) {
  const HeadModel& m = *Builtin();
  Avatar plain = Avatar::CreateRandom(TinyWithSurface(), m, DefaultSubject(m, 128), 6);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : plain.modules().surface->parameters()) t.uniform_(-1, 1);
    for (auto& p : plain.modules().renderer->named_parameters())
      if (p.key().find("surface_out") != std::string::npos) p.value().uniform_(-0.5, 0.5);
  }
  AvatarConfig conditioned_config = TinyWithSurface();
  conditioned_config.surface_conditioned = true;
  EXPECT_TRUE(AvatarConfig::FromJson(conditioned_config.ToJson()).surface_conditioned);
  Avatar conditioned = Avatar::CreateRandom(conditioned_config, m, plain.subject(), 6);
  CopySharedWeights(plain, conditioned);  // the plain avatar's weights, the FiLM at its zero start
  FrameParams smile = Expressive(), other = Expressive();
  other.expression[0] = -1.0f;
  EXPECT_EQ(cv::norm(Shown(plain, smile), Shown(conditioned, smile), cv::NORM_INF), 0);

  // The texture's contribution (the surface term) at the same canonical
  // points for two expressions: equal without FiLM, different with it.
  const torch::Tensor canonical = torch::rand({200, 3}) * 0.2 - 0.1;
  auto term = [&](Avatar& a, const FrameParams& f) {
    torch::NoGradGuard no_grad;
    const AvatarConfig& c = a.config();
    const torch::Tensor motion = MakeConditioning(c, a.subject(), f).geometry.narrow(1, c.num_shape, c.motion_dim());
    return a.modules().renderer->SurfaceTerm(a.modules().surface->forward(canonical), torch::arange(200), 16, 16,
                                             c.surface_conditioned ? motion : torch::Tensor());
  };
  EXPECT_EQ((term(plain, smile) - term(plain, other)).abs().max().item<float>(), 0.f);
  {
    torch::NoGradGuard no_grad;
    for (auto& p : conditioned.modules().renderer->named_parameters())
      if (p.key().find("surface_film") != std::string::npos) p.value().uniform_(-0.5, 0.5);
  }
  EXPECT_GT((term(conditioned, smile) - term(conditioned, other)).abs().max().item<float>(), 1e-3f);
  EXPECT_THROW(conditioned.modules().renderer->SurfaceTerm(torch::zeros({1, 4}), torch::zeros({1}, torch::kLong), 4, 4),
               std::invalid_argument);

  // Its FiLM weights get gradients from the picture.
  conditioned.modules().train();
  RaySampler sampler(conditioned.config());
  AvatarFrameInputs inputs;
  PrepareAvatarFrame(conditioned.config(), m, m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape())),
                     conditioned.subject(), smile, &sampler, nullptr, &inputs);
  torch::mse_loss(RunAvatar(conditioned.modules(), inputs).image, torch::full({1, 3, 128, 128}, 0.8f)).backward();
  for (auto& p : conditioned.modules().renderer->named_parameters()) {
    if (p.key().find("surface_film") != std::string::npos) {
      EXPECT_GT(p.value().grad().abs().max().item<float>(), 0.f) << p.key();
    }
  }
}

// The texture joins the level before the last too when asked: it starts as the
// avatar without that path, the path's weights learn once the texture draws,
// then the picture differs from the last-level-only one; the file keeps it.
TEST(SurfaceTexture, JoinsAnEarlierLevelWhenAskedAndStartsWithoutIt) {
  const HeadModel& m = *Builtin();
  AvatarConfig two = TinyWithSurface();
  two.surface_levels = 2;
  nlohmann::json old = two.ToJson();
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_levels, 2);
  old.erase("surface_levels");
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_levels, 1) << "files from before: the last level only";
  for (int bad : {0, 4}) {
    AvatarConfig c = two;
    c.surface_levels = bad;
    EXPECT_THROW(c.Check(), std::invalid_argument) << bad;
  }
  AvatarConfig untextured = testing::TinyAvatarConfig();
  untextured.surface_levels = 2;
  EXPECT_THROW(untextured.Check(), std::invalid_argument);

  Avatar last = Avatar::CreateRandom(TinyWithSurface(), m, DefaultSubject(m, 128), 8);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : last.modules().surface->parameters()) t.uniform_(-1, 1);
    for (auto& p : last.modules().renderer->named_parameters())
      if (p.key().find("surface_out") != std::string::npos) p.value().uniform_(-0.5, 0.5);
  }
  Avatar both = Avatar::CreateRandom(two, m, last.subject(), 8);
  // The last-level avatar's weights; the earlier level's path at its zero start.
  const std::vector<std::string> early = CopySharedWeights(last, both);
  for (const std::string& key : early) EXPECT_NE(key.find("surface_early"), std::string::npos) << key;
  EXPECT_EQ(early.size(), 2u) << "one 1x1 layer (weight, bias) for the level before the last";
  const FrameParams frame = Expressive();
  EXPECT_EQ(cv::norm(Shown(last, frame), Shown(both, frame), cv::NORM_INF), 0);
  EXPECT_THROW(last.WithRuntimeSwitches(two), std::invalid_argument) << "a texture's levels are not a switch";

  both.modules().train();
  RaySampler sampler(both.config());
  AvatarFrameInputs inputs;
  PrepareAvatarFrame(both.config(), m, m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape())), both.subject(), frame,
                     &sampler, nullptr, &inputs);
  torch::mse_loss(RunAvatar(both.modules(), inputs).image, torch::full({1, 3, 128, 128}, 0.8f)).backward();
  for (auto& p : both.modules().renderer->named_parameters()) {
    if (p.key().find("surface_early") != std::string::npos && p.key().find("weight") != std::string::npos) {
      EXPECT_GT(p.value().grad().abs().max().item<float>(), 0.f) << p.key();
    }
  }
  {
    torch::NoGradGuard no_grad;
    for (auto& p : both.modules().renderer->named_parameters())
      if (p.key().find("surface_early") != std::string::npos) p.value().uniform_(-0.5, 0.5);
  }
  const cv::Mat drawn = Shown(both, frame);
  EXPECT_GT(cv::norm(Shown(last, frame), drawn, cv::NORM_INF), 0);
  const std::string path = testing::TempDir("surface_levels") + "/l.hcavatar";
  both.Save(path);
  Avatar back = Avatar::Load(path, m);
  EXPECT_EQ(back.config().surface_levels, 2);
  EXPECT_EQ(cv::norm(drawn, Shown(back, frame), cv::NORM_INF), 0);
}

TEST(SurfaceTexture, TheBranchWidthIsChosenAndOldFilesKeepTwiceTheFeatures) {
  const HeadModel& m = *Builtin();
  AvatarConfig c = TinyWithSurface();
  EXPECT_EQ(c.surface_hidden_channels(), 2 * c.surface_features);
  c.surface_hidden = 24;
  Avatar a = Avatar::CreateRandom(c, m, DefaultSubject(m, 128), 2);
  const auto params = a.modules().renderer->named_parameters();
  ASSERT_NE(params.find("surface_hidden.weight"), nullptr);
  EXPECT_EQ(params["surface_hidden.weight"].size(0), 24);
  const std::string path = testing::TempDir("surface_hidden") + "/h.hcavatar";
  a.Save(path);
  EXPECT_EQ(Avatar::Load(path, m).config().surface_hidden_channels(), 24);
  nlohmann::json old = c.ToJson();
  old.erase("surface_hidden");
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_hidden_channels(), 2 * c.surface_features);
  c.surface_hidden = -1;
  EXPECT_THROW(c.Check(), std::invalid_argument);
}

// The rigid texture is a second set of planes looked up at the posed points
// and added: it starts at zero (the picture as without it), reads what
// grid_sample reads on the receiver's texel-major planes, is refused without
// the posed points, needs a texture and no shell, and travels in the file.
TEST(SurfaceTexture, ARigidTextureAddsPlanesLookedUpAtThePosedPoints) {
  AvatarConfig c = TinyWithSurface();
  c.surface_rigid = true;
  SurfaceTexture texture(c);
  ASSERT_TRUE(texture->rigid());
  ASSERT_EQ(texture->parameters().size(), 2u);
  const torch::Tensor canonical = (torch::rand({500, 3}) * 2 - 1) * 0.15,
                      posed = (torch::rand({500, 3}) * 2 - 1) * 0.15;
  EXPECT_EQ(texture->forward(canonical, posed).abs().max().item<float>(), 0.f) << "a new texture is zero";
  EXPECT_THROW(texture->forward(canonical), std::invalid_argument);
  {
    torch::NoGradGuard no_grad;
    texture->named_parameters()["rigid_planes"].uniform_(-1, 1);
  }
  // The canonical planes are still zero: only the posed points decide.
  const torch::Tensor f = texture->forward(canonical, posed).detach();
  EXPECT_LT((texture->forward(canonical * 0.5, posed) - f).abs().max().item<float>(), 1e-6);
  EXPECT_GT((texture->forward(canonical, posed * 0.5) - f).abs().max().item<float>(), 0.1);
  {
    torch::NoGradGuard no_grad;
    texture->named_parameters()["planes"].uniform_(-1, 1);
  }
  SurfaceTexture plain(TinyWithSurface());
  {
    torch::NoGradGuard no_grad;
    plain->named_parameters()["planes"].copy_(texture->named_parameters()["planes"]);
  }
  const torch::Tensor both = texture->forward(canonical, posed).detach();
  EXPECT_LT((both - plain->forward(canonical).detach() - f).abs().max().item<float>(), 1e-5) << "the sum of the two";
  texture->UseChannelsLast();
  {
    torch::NoGradGuard no_grad;
    EXPECT_LT((texture->forward(canonical, posed) - both).abs().max().item<float>(), 1e-6);
  }

  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).surface_rigid);
  nlohmann::json old = c.ToJson();
  old.erase("surface_rigid");
  EXPECT_FALSE(AvatarConfig::FromJson(old).surface_rigid) << "files from before it: the canonical texture only";
  AvatarConfig bad = testing::TinyAvatarConfig();
  bad.surface_rigid = true;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a rigid texture without a texture";
  bad = c;
  bad.surface_shell = 0.02;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a shell pixel has no posed point";

  const HeadModel& m = *Builtin();
  const std::string dir = testing::TempDir("rigid_surface");
  auto [with, back] = AddedSavedAndLoaded(c, dir);
  EXPECT_TRUE(back.config().surface_rigid);
  const FrameParams frame = Expressive();
  const cv::Mat y = Shown(back, frame);
  EXPECT_EQ(cv::norm(y, Shown(back, frame), cv::NORM_INF), 0) << "the same frame twice, the same picture";
  AvatarConfig canonical_only = c;
  canonical_only.surface_rigid = false;
  EXPECT_THROW(with.WithRuntimeSwitches(canonical_only), std::invalid_argument) << "a texture is not changed";
  // A manifest that promises the rigid planes the weights do not hold.
  Avatar one = Avatar::CreateRandom(TinyWithSurface(), m, DefaultSubject(m, 128), 4);
  one.Save(dir + "/one.hcavatar");
  ZipEntries entries = ReadZip(dir + "/one.hcavatar");
  nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
  manifest["config"]["surface_rigid"] = true;
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/lying.hcavatar", entries);
  EXPECT_THROW(Avatar::Load(dir + "/lying.hcavatar", m), std::runtime_error);
}

// The displacement: the surface branch's inputs are the texture's channels
// and each mesh pixel's posed point less its canonical one. Added to a general
// model it draws the general model's picture; with the branch drawing, a frame
// that moves nothing draws the same whatever the displacement's weights and an
// expressive one does not; those weights learn from the picture; refused
// without a texture or with a shell; kept in the file; not a run-time switch.
TEST(SurfaceTexture, TheBranchIsToldHowFarTheExpressionMovedTheSkin) {
  AvatarConfig c = TinyWithSurface();
  c.surface_displacement = true;
  c.Check();
  EXPECT_EQ(c.surface_branch_inputs(), c.surface_features + 3);
  EXPECT_TRUE(c.needs_posed_points());
  EXPECT_TRUE(AvatarConfig::FromJson(c.ToJson()).surface_displacement);
  nlohmann::json old = c.ToJson();
  old.erase("surface_displacement");
  EXPECT_FALSE(AvatarConfig::FromJson(old).surface_displacement) << "files from before it: the texture only";
  AvatarConfig bad = testing::TinyAvatarConfig();
  bad.surface_displacement = true;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a displacement without a texture";
  bad = c;
  bad.surface_shell = 0.02;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "a shell pixel has no posed point";

  const HeadModel& m = *Builtin();
  auto [with, back] = AddedSavedAndLoaded(c, testing::TempDir("surface_displacement"));
  EXPECT_TRUE(back.config().surface_displacement);
  const int64_t features = c.surface_features;
  torch::Tensor hidden = back.modules().renderer->named_parameters()["surface_hidden.weight"];
  ASSERT_EQ(hidden.size(1), features + 3);
  {
    torch::NoGradGuard no_grad;
    for (auto& p : back.modules().renderer->named_parameters())
      if (p.key().rfind("surface_", 0) == 0) p.value().uniform_(-0.5, 0.5);
  }
  FrameParams still = Expressive(), moved = Expressive();
  still.expression.setZero();
  still.jaw.setZero();
  still.neck.setZero();
  moved.neck.setZero();  // the expression and the jaw alone move the skin
  RaySampler sampler(back.config());
  AvatarFrameInputs inputs;
  PrepareAvatarFrame(back.config(), m, m.MakeIdentity(back.subject().shape.cast<double>()), back.subject(), moved,
                     &sampler, nullptr, &inputs);
  ASSERT_GT(inputs.surface.num_pixels(), 0);
  EXPECT_EQ(inputs.surface.posed.size(), inputs.surface.canonical.size()) << "each mesh pixel's posed point";

  // The displacement's weights get gradients from an expressive frame's picture.
  back.modules().train();
  torch::mse_loss(RunAvatar(back.modules(), inputs).image, torch::full({1, 3, 128, 128}, 0.8f)).backward();
  EXPECT_GT(hidden.grad().narrow(1, features, 3).abs().max().item<float>(), 0.f);

  const cv::Mat still_drawn = Shown(back, still), moved_drawn = Shown(back, moved);
  {
    torch::NoGradGuard no_grad;
    hidden.narrow(1, features, 3).zero_();
  }
  EXPECT_LE(cv::norm(still_drawn, Shown(back, still), cv::NORM_INF), 1) << "nothing moved: no displacement to read";
  EXPECT_GT(cv::norm(moved_drawn, Shown(back, moved), cv::NORM_INF), 2) << "the moved skin reads its displacement";
  AvatarConfig without = c;
  without.surface_displacement = false;
  EXPECT_THROW(with.WithRuntimeSwitches(without), std::invalid_argument) << "the branch's inputs are not a switch";
}

// The expression blendshapes: planes per coefficient, summed with the
// frame's coefficients as weights and looked up at the canonical points. Zero
// at first (the picture as without them); a neutral frame reads the texture
// alone; the lookup is linear in the coefficients; the receiver's texel-major
// lookup reads what grid_sample reads; refused without the coefficients;
// checked, kept in the file, and drawn the same after loading.
TEST(SurfaceTexture, ExpressionBlendshapesAddPlanesWeightedByTheFrame) {
  AvatarConfig c = TinyWithSurface();
  c.surface_blend = 8;
  c.Check();
  SurfaceTexture texture(c);
  ASSERT_TRUE(texture->blended());
  ASSERT_EQ(texture->parameters().size(), 2u);
  const int e = c.num_expression;
  const torch::Tensor canonical = (torch::rand({400, 3}) * 2 - 1) * 0.15;
  const torch::Tensor psi = torch::rand({1, e}) * 2 - 1;
  EXPECT_EQ(texture->forward(canonical, {}, psi).abs().max().item<float>(), 0.f) << "new blendshapes are zero";
  EXPECT_THROW(texture->forward(canonical), std::invalid_argument) << "no coefficients";
  EXPECT_THROW(texture->forward(canonical, {}, torch::zeros({1, e + 1})), std::invalid_argument);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : texture->parameters()) t.uniform_(-1, 1);
  }
  SurfaceTexture plain(TinyWithSurface());
  {
    torch::NoGradGuard no_grad;
    plain->named_parameters()["planes"].copy_(texture->named_parameters()["planes"]);
  }
  const torch::Tensor base = plain->forward(canonical).detach();
  EXPECT_LT((texture->forward(canonical, {}, torch::zeros({1, e})) - base).abs().max().item<float>(), 1e-6)
      << "a neutral frame reads the texture alone";
  const torch::Tensor once = texture->forward(canonical, {}, psi).detach() - base;
  EXPECT_GT(once.abs().max().item<float>(), 0.1) << "an expression changes the features";
  const torch::Tensor two = texture->forward(canonical, {}, 2 * psi).detach() - base;
  EXPECT_LT((two - 2 * once).abs().max().item<float>(), 1e-4) << "linear in the coefficients";
  // One coefficient alone reads its own planes: (3, C, B, B) from its row, texel after texel.
  const int64_t b = c.surface_blend, ch = c.surface_features;
  torch::Tensor unit = torch::zeros({1, e});
  unit[0][3] = 1;
  const torch::Tensor alone = texture->forward(canonical, {}, unit).detach() - base;
  const torch::Tensor row_at_b = [&] {
    AvatarConfig cb = TinyWithSurface();
    cb.surface_resolution = static_cast<int>(b);
    SurfaceTexture t(cb);
    torch::NoGradGuard no_grad;
    t->named_parameters()["planes"].copy_(
        texture->named_parameters()["blend"][3].view({3, b, b, ch}).permute({0, 3, 1, 2}));
    return t->forward(canonical).detach();
  }();
  EXPECT_LT((alone - row_at_b).abs().max().item<float>(), 1e-5) << "one coefficient: its own planes";
  const torch::Tensor both = texture->forward(canonical, {}, psi).detach();
  texture->UseChannelsLast();
  {
    torch::NoGradGuard no_grad;
    EXPECT_LT((texture->forward(canonical, {}, psi) - both).abs().max().item<float>(), 1e-5)
        << "the receiver's lookup reads the same";
  }
  // Gradients reach each coefficient's planes in proportion to its weight.
  SurfaceTexture learning(c);
  torch::Tensor w = torch::zeros({1, e});
  w[0][1] = 0.5;
  learning->forward(canonical, {}, w).sum().backward();
  const torch::Tensor g = learning->named_parameters()["blend"].grad();
  EXPECT_GT(g[1].abs().sum().item<float>(), 0.f);
  EXPECT_EQ(g[2].abs().sum().item<float>(), 0.f) << "a coefficient of zero learns nothing";

  EXPECT_EQ(AvatarConfig::FromJson(c.ToJson()).surface_blend, 8);
  nlohmann::json old = c.ToJson();
  old.erase("surface_blend");
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_blend, 0) << "files from before them: none";
  AvatarConfig bad = testing::TinyAvatarConfig();
  bad.surface_blend = 8;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "blendshapes without a texture";
  bad = c;
  bad.surface_blend = 2;
  EXPECT_THROW(bad.Check(), std::invalid_argument);

  // An expression changes the picture.
  const HeadModel& m = *Builtin();
  const std::string dir = testing::TempDir("blend_surface");
  auto [with, back] = AddedSavedAndLoaded(c, dir);
  EXPECT_EQ(back.config().surface_blend, 8);
  const FrameParams frame = Expressive();
  const cv::Mat y = Shown(back, frame);
  FrameParams other = frame;
  other.expression[0] = 0.5f;
  EXPECT_GT(cv::norm(Shown(back, other), y, cv::NORM_INF), 0) << "the expression reaches the texture";
  AvatarConfig without = c;
  without.surface_blend = 0;
  EXPECT_THROW(with.WithRuntimeSwitches(without), std::invalid_argument) << "a texture is not changed";
  // A manifest that promises blendshapes the weights do not hold.
  Avatar one = Avatar::CreateRandom(TinyWithSurface(), m, DefaultSubject(m, 128), 4);
  one.Save(dir + "/one.hcavatar");
  ZipEntries entries = ReadZip(dir + "/one.hcavatar");
  nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
  manifest["config"]["surface_blend"] = 8;
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/lying.hcavatar", entries);
  EXPECT_THROW(Avatar::Load(dir + "/lying.hcavatar", m), std::runtime_error);
}

// Blendshapes over principal directions: one set of planes per direction,
// weighted by the frame's expression projected onto the directions (less the
// mean) and held within each projection's range. Nothing until the directions
// are set; within the ranges, the per-coefficient blendshapes the directions
// span draw the same; beyond, the weights stop at the range's ends. Checked,
// refused when malformed, kept through a run-time switch and in the file.
TEST(SurfaceTexture, BlendshapesOverPrincipalDirectionsFollowTheFramesProjections) {
  AvatarConfig c = TinyWithSurface();
  c.surface_blend = 8;
  c.surface_blend_components = 3;
  c.Check();
  const int64_t e = c.num_expression, k = 3;
  SurfaceTexture texture(c);
  ASSERT_EQ(texture->named_parameters()["blend"].size(0), k);
  EXPECT_FALSE(texture->has_blend_basis());
  {
    torch::NoGradGuard no_grad;
    for (auto& t : texture->parameters()) t.uniform_(-1, 1);
  }
  SurfaceTexture plain(TinyWithSurface());
  {
    torch::NoGradGuard no_grad;
    plain->named_parameters()["planes"].copy_(texture->named_parameters()["planes"]);
  }
  const torch::Tensor canonical = (torch::rand({400, 3}) * 2 - 1) * 0.15;
  const torch::Tensor base = plain->forward(canonical).detach();
  const torch::Tensor psi = torch::rand({1, e}) * 0.1;
  EXPECT_LT((texture->forward(canonical, {}, psi).detach() - base).abs().max().item<float>(), 1e-6)
      << "no directions yet: nothing added";
  const torch::Tensor mean = torch::rand({e}) * 0.1;
  const torch::Tensor directions = std::get<0>(torch::linalg_qr(torch::randn({e, k}))).t().contiguous();  // (K, E)
  const torch::Tensor low = torch::full({k}, -0.5), high = torch::full({k}, 0.5);
  texture->SetBlendBasis(mean, directions, low, high);
  EXPECT_TRUE(texture->has_blend_basis());
  // Within the ranges: per-coefficient blendshapes directions^T x blend draw the same.
  AvatarConfig per_coefficient = c;
  per_coefficient.surface_blend_components = 0;
  SurfaceTexture spanned(per_coefficient);
  {
    torch::NoGradGuard no_grad;
    spanned->named_parameters()["planes"].copy_(texture->named_parameters()["planes"]);
    spanned->named_parameters()["blend"].copy_(torch::mm(directions.t(), texture->named_parameters()["blend"]));
  }
  const torch::Tensor projected = torch::mm(psi - mean, directions.t());
  ASSERT_LT(projected.abs().max().item<float>(), 0.5) << "the test frame is within the ranges";
  EXPECT_TRUE(torch::allclose(texture->BlendWeights(psi), projected, 1e-5, 1e-6));
  EXPECT_LT(
      (texture->forward(canonical, {}, psi) - spanned->forward(canonical, {}, psi - mean)).abs().max().item<float>(),
      1e-4)
      << "the directions' blendshapes are the coefficients' they span";
  // Beyond: each weight stops at its range's end.
  const torch::Tensor far = mean.unsqueeze(0) + 10 * directions[0].unsqueeze(0) - 10 * directions[1].unsqueeze(0);
  const torch::Tensor held = texture->BlendWeights(far);
  EXPECT_NEAR(held[0][0].item<float>(), 0.5, 1e-5);
  EXPECT_NEAR(held[0][1].item<float>(), -0.5, 1e-5);
  EXPECT_NEAR(held[0][2].item<float>(), 0, 1e-4);
  // Refusals.
  EXPECT_THROW(texture->SetBlendBasis(mean, directions.narrow(0, 0, 2), low, high), std::invalid_argument);
  EXPECT_THROW(texture->SetBlendBasis(mean.narrow(0, 0, e - 1), directions, low, high), std::invalid_argument);
  torch::Tensor nan = directions.clone();
  nan[1][2] = std::nanf("");
  EXPECT_THROW(texture->SetBlendBasis(mean, nan, low, high), std::invalid_argument);
  EXPECT_THROW(texture->SetBlendBasis(mean, directions, high, low - 1), std::invalid_argument) << "low > high";
  EXPECT_THROW(spanned->SetBlendBasis(mean, directions, low, high), std::invalid_argument)
      << "per-coefficient blendshapes take no directions";
  EXPECT_THROW(texture->BlendWeights(torch::zeros({1, e + 1})), std::invalid_argument);
  EXPECT_EQ(AvatarConfig::FromJson(c.ToJson()).surface_blend_components, 3);
  nlohmann::json old = c.ToJson();
  old.erase("surface_blend_components");
  EXPECT_EQ(AvatarConfig::FromJson(old).surface_blend_components, 0) << "files from before them: per coefficient";
  AvatarConfig bad = c;
  bad.surface_blend_components = c.num_expression + 1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = TinyWithSurface();
  bad.surface_blend_components = 2;
  EXPECT_THROW(bad.Check(), std::invalid_argument) << "directions without blendshapes";

  // Through a run-time switch and the file: the directions are kept.
  const HeadModel& m = *Builtin();
  Avatar a = Avatar::CreateRandom(c, m, DefaultSubject(m, 128), 4);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : a.modules().surface->parameters()) t.uniform_(-1, 1);
  }
  a.modules().surface->SetBlendBasis(mean, directions, low, high);
  AvatarConfig switched = a.config();
  switched.expression_low.assign(e, -1.f);
  switched.expression_high.assign(e, 1.f);
  Avatar b = a.WithRuntimeSwitches(switched);
  EXPECT_TRUE(torch::equal(b.modules().surface->named_buffers()["blend_directions"], directions));
  const std::string dir = testing::TempDir("blend_directions");
  b.Save(dir + "/d.hcavatar");
  Avatar back = Avatar::Load(dir + "/d.hcavatar", m);
  const auto buffers = back.modules().surface->named_buffers();
  EXPECT_TRUE(torch::equal(buffers["blend_mean"], mean));
  EXPECT_TRUE(torch::equal(buffers["blend_directions"], directions));
  EXPECT_TRUE(torch::equal(buffers["blend_low"], low));
  EXPECT_TRUE(torch::equal(buffers["blend_high"], high));
  FrameParams frame = Expressive();
  EXPECT_EQ(cv::norm(Shown(b, frame), Shown(back, frame), cv::NORM_INF), 0) << "loaded: what the saved one drew";
}

TEST(SurfaceTexture, TheFileKeepsItAndRefusesOneWithoutIt) {
  const HeadModel& m = *Builtin();
  const std::string dir = testing::TempDir("surface");
  Avatar a = Avatar::CreateRandom(TinyWithSurface(), m, DefaultSubject(m, 128), 4);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : a.modules().surface->parameters()) t.uniform_(-1, 1);
  }
  const std::string path = dir + "/s.hcavatar";
  a.Save(path);
  Avatar back = Avatar::Load(path, m);
  EXPECT_EQ(back.config().ToJson(), TinyWithSurface().ToJson());
  const FrameParams frame = Expressive();
  const cv::Mat y = Shown(back, frame);
  EXPECT_EQ(cv::norm(Shown(a, frame), y, cv::NORM_INF), 0) << "the loaded texture draws what the saved one did";
  EXPECT_EQ(cv::norm(y, Shown(back, frame), cv::NORM_INF), 0) << "the same frame twice, the same picture";
  // A manifest that promises a texture the weights do not hold.
  Avatar plain = Avatar::CreateRandom(testing::TinyAvatarConfig(), m, DefaultSubject(m, 128), 4);
  const std::string plain_path = dir + "/p.hcavatar";
  plain.Save(plain_path);
  ZipEntries entries = ReadZip(plain_path);
  nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
  manifest["config"]["surface_features"] = 4;
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/lying.hcavatar", entries);
  try {
    Avatar::Load(dir + "/lying.hcavatar", m);
    ADD_FAILURE() << "a texture-less file claiming a texture loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("weights do not match"), std::string::npos) << e.what();
  }
  // Files from before surface textures (no such keys) load without one.
  manifest["config"].erase("surface_features");
  manifest["config"].erase("surface_resolution");
  manifest["config"].erase("surface_extent");
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/old.hcavatar", entries);
  EXPECT_FALSE(Avatar::Load(dir + "/old.hcavatar", m).config().has_surface());
}

}  // namespace headcast
