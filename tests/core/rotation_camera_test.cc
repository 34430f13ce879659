// Rotations (with derivatives) and the pinhole camera.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "common/core/camera.h"
#include "common/core/rotation.h"

namespace headcast {
namespace {

TEST(Rotation, MatchesEigenAndInverts) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-2, 2);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d w(u(rng), u(rng), u(rng));
    const Eigen::Matrix3d R = AxisAngleToMatrix(w);
    const Eigen::Matrix3d expected = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    EXPECT_LT((R - expected).norm(), 1e-12);
    EXPECT_LT((AxisAngleToMatrix(MatrixToAxisAngle(R)) - R).norm(), 1e-9);
  }
  EXPECT_LT((AxisAngleToMatrix(Eigen::Vector3d::Zero()) - Eigen::Matrix3d::Identity()).norm(), 1e-15);
}

TEST(Rotation, DerivativeMatchesFiniteDifferences) {
  for (const Eigen::Vector3d& w : {Eigen::Vector3d(0.3, -0.7, 1.1), Eigen::Vector3d(1e-9, 0, 0),
                                   Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2.5, 0.1, -0.4)}) {
    std::array<Eigen::Matrix3d, 3> d;
    AxisAngleToMatrix(w, &d);
    const double h = 1e-6;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d e = Eigen::Vector3d::Unit(i) * h;
      const Eigen::Matrix3d numeric = (AxisAngleToMatrix(w + e) - AxisAngleToMatrix(w - e)) / (2 * h);
      EXPECT_LT((numeric - d[i]).norm(), 1e-6) << "w=" << w.transpose() << " i=" << i;
    }
  }
}

TEST(Camera, ProjectUnprojectAndJacobian) {
  PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 50);
  EXPECT_NO_THROW(cam.Check());
  const Eigen::Vector3d p(0.1, -0.05, 0.8);
  const Eigen::Vector2d px = cam.Project(p);
  EXPECT_LT((cam.Unproject(px, 0.8) - p).norm(), 1e-12);
  EXPECT_NEAR(cam.Project(Eigen::Vector3d(0, 0, 1)).x(), 319.5, 1e-12);
  const double h = 1e-7;
  const auto J = cam.ProjectJacobian(p);
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d e = Eigen::Vector3d::Unit(i) * h;
    EXPECT_LT(((cam.Project(p + e) - cam.Project(p - e)) / (2 * h) - J.col(i)).norm(), 1e-4);
  }
}

TEST(Camera, ResizedKeepsThePixelGrid) {
  // A point at a pixel's outer edge stays at the corresponding edge after resizing.
  const PinholeCamera cam = PinholeCamera::FromFovY(256, 256, 30);
  const PinholeCamera small = cam.Resized(32, 32);
  const Eigen::Vector3d p(0.02, 0.03, 0.7);
  const Eigen::Vector2d a = cam.Project(p), b = small.Project(p);
  EXPECT_NEAR((a.x() + 0.5) / 8.0 - 0.5, b.x(), 1e-9);
  EXPECT_NEAR((a.y() + 0.5) / 8.0 - 0.5, b.y(), 1e-9);
  EXPECT_EQ(cam.Scaled(0.5).width, 128);
}

TEST(Camera, CheckNamesTheBadField) {
  PinholeCamera cam;
  cam.fx = -1;
  cam.height = 0;
  try {
    cam.Check();
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("fx"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("height"), std::string::npos);
  }
}

}  // namespace
}  // namespace headcast
