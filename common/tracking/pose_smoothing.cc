#include "common/tracking/pose_smoothing.h"

#include <cmath>
#include <stdexcept>

#include "common/core/rotation.h"

namespace headcast {

void SmoothHeadPlacement(double sigma_frames, std::vector<FrameParams>* frames) {
  if (!(sigma_frames >= 0 && sigma_frames <= 100))
    throw std::invalid_argument("pose smoothing: sigma must be 0..100 frames");
  if (sigma_frames == 0) return;
  std::vector<RigidTransform> placed;
  for (const FrameParams& f : *frames) placed.push_back(f.CamFromHead());
  auto frame_number = [&](int i) { return static_cast<double>((*frames)[static_cast<size_t>(i)].sequence); };
  const double reach = 3 * sigma_frames;
  const int n = static_cast<int>(frames->size());
  for (int i = 0; i < n; ++i) {
    const Eigen::Matrix3d& own = placed[i].rotation;
    Eigen::Vector3d turn = Eigen::Vector3d::Zero(), shift = Eigen::Vector3d::Zero();
    double total = 0;
    auto add = [&](int j) {
      const double d = frame_number(j) - frame_number(i), w = std::exp(-0.5 * d * d / (sigma_frames * sigma_frames));
      turn += w * MatrixToAxisAngle(own.transpose() * placed[j].rotation);
      shift += w * placed[j].translation;
      total += w;
    };
    // Sequence numbers rise along a track; frames without a fit leave gaps.
    for (int j = i; j >= 0 && frame_number(i) - frame_number(j) <= reach; --j) add(j);
    for (int j = i + 1; j < n && frame_number(j) - frame_number(i) <= reach; ++j) add(j);
    (*frames)[i].SetCamFromHead({own * AxisAngleToMatrix(turn / total), shift / total});
  }
}

}  // namespace headcast
