#include "common/tracking/pose_smoothing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/core/rotation.h"

namespace headcast {
namespace {

// A head turning and moving smoothly, fitted with noise in every frame: the
// smoothed placement lies nearer the true one than the fitted one did; the
// expression is left alone; a still head stays exactly where it was; frames
// beyond 3 sigma (a gap in the track) do not pull on each other.
TEST(SmoothHeadPlacement, TakesOutFrameToFrameNoiseAndNothingElse) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 1);
  std::vector<FrameParams> truth, fitted;
  for (int k = 0; k < 60; ++k) {
    FrameParams f;
    f.sequence = k < 30 ? k : k + 40;  // a gap of 40 frames
    const double t = 0.05 * k;
    f.cam_rotation = Eigen::Vector3f(0.1f * std::sin(t), 3.0f + 0.2f * std::sin(0.7 * t), 0.05f * std::cos(t));
    f.cam_translation = Eigen::Vector3f(0.02f * std::sin(t), -0.01f, 0.5f + 0.03f * std::cos(t));
    f.expression = Eigen::VectorXf::Constant(3, static_cast<float>(k % 2));
    truth.push_back(f);
    f.cam_rotation += 0.01f * Eigen::Vector3f(noise(rng), noise(rng), noise(rng));
    f.cam_translation += 0.002f * Eigen::Vector3f(noise(rng), noise(rng), noise(rng));
    fitted.push_back(f);
  }
  std::vector<FrameParams> smoothed = fitted;
  SmoothHeadPlacement(1.5, &smoothed);
  auto errors = [&](const std::vector<FrameParams>& track, double* turn, double* shift) {
    *turn = *shift = 0;
    for (size_t k = 0; k < track.size(); ++k) {
      const RigidTransform a = track[k].CamFromHead(), b = truth[k].CamFromHead();
      *turn += MatrixToAxisAngle(a.rotation.transpose() * b.rotation).norm() / track.size();
      *shift += (a.translation - b.translation).norm() / track.size();
    }
  };
  double fitted_turn, fitted_shift, smoothed_turn, smoothed_shift;
  errors(fitted, &fitted_turn, &fitted_shift);
  errors(smoothed, &smoothed_turn, &smoothed_shift);
  EXPECT_LT(smoothed_turn, 0.6 * fitted_turn);
  EXPECT_LT(smoothed_shift, 0.6 * fitted_shift);
  for (size_t k = 0; k < smoothed.size(); ++k) EXPECT_EQ(smoothed[k].expression, fitted[k].expression);

  // A still head, and a jump across the gap that must not leak into either side.
  std::vector<FrameParams> still;
  for (int k = 0; k < 20; ++k) {
    FrameParams f;
    f.sequence = k < 10 ? k : k + 40;
    f.cam_rotation = Eigen::Vector3f(0.1f, k < 10 ? 3.0f : 2.5f, 0);
    f.cam_translation = Eigen::Vector3f(0, 0, k < 10 ? 0.5f : 0.7f);
    still.push_back(f);
  }
  std::vector<FrameParams> kept = still;
  SmoothHeadPlacement(2, &kept);
  for (size_t k = 0; k < kept.size(); ++k) {
    EXPECT_LT((kept[k].cam_rotation - still[k].cam_rotation).norm(), 1e-5) << k;
    EXPECT_LT((kept[k].cam_translation - still[k].cam_translation).norm(), 1e-6) << k;
  }
  SmoothHeadPlacement(0, &kept);  // off
  EXPECT_THROW(SmoothHeadPlacement(-1, &kept), std::invalid_argument);
  EXPECT_THROW(SmoothHeadPlacement(std::nan(""), &kept), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
