// The built-in head at rest over a cluttered background, where its mask and
// landmarks are known exactly: what the head-mask and outline tests cut.
#pragma once

#include <opencv2/imgproc.hpp>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/face_tracker.h"

namespace headcast::testing {

// Clutter: blurred coloured blobs, the background the renders are put on.
inline cv::Mat ClutteredBackground(cv::RNG& rng) {
  cv::Mat background(480, 640, CV_8UC3);
  rng.fill(background, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(background, background, {0, 0}, 9);
  cv::normalize(background, background, 0, 255, cv::NORM_MINMAX);
  return background;
}

inline Landmarks2d ExactLandmarks(const HeadModelOutput& out, const RigidTransform& cam_from_head,
                                  const PinholeCamera& cam) {
  Landmarks2d exact;
  for (int l = 0; l < kNumLandmarks; ++l)
    exact[l] = cam.Project(cam_from_head.Apply(out.landmarks.row(l).cast<double>().transpose()));
  return exact;
}

// The built-in head at rest over one cluttered background, where its mask and
// landmarks are known exactly.
class RestingHeadScenes {
 public:
  explicit RestingHeadScenes(int seed) : rng_(seed), background_(ClutteredBackground(rng_)) {}
  struct Scene {
    cv::Mat image, mask;
    Landmarks2d landmarks;
    FrameParams params;
  };
  Scene At(double distance, double yaw_deg, double pitch_deg) const {
    const RigidTransform cam_from_head =
        FrontalCamFromHead(distance, yaw_deg, pitch_deg, model_.rest_landmark_centroid());
    const HeadRender r = RenderHead(model_, out_.vertices, cam_from_head, cam_, AlbedoTexture(model_));
    Scene s{background_.clone(), r.mask, ExactLandmarks(out_, cam_from_head, cam_), {}};
    r.image_bgr.copyTo(s.image, r.mask);
    s.params.expression = Eigen::VectorXf::Zero(model_.num_expression());
    s.params.SetCamFromHead(cam_from_head);
    return s;
  }
  // `s`'s head moved across the picture by `shift` pixels (in front of the
  // same background; its params are left as they were).
  Scene Moved(const Scene& s, cv::Point2f shift) const {
    const cv::Matx23d by(1, 0, shift.x, 0, 1, shift.y);
    cv::Mat head, mask;
    cv::warpAffine(s.image, head, by, s.image.size(), cv::INTER_NEAREST);
    cv::warpAffine(s.mask, mask, by, s.mask.size(), cv::INTER_NEAREST);
    Scene moved{background_.clone(), mask, s.landmarks, s.params};
    head.copyTo(moved.image, mask);
    for (auto& p : moved.landmarks) p += Eigen::Vector2d(shift.x, shift.y);
    return moved;
  }
  const HeadModel& model() const { return model_; }
  const PinholeCamera& camera() const { return cam_; }

 private:
  const HeadModel model_ = MakeBuiltinHead();
  const PinholeCamera cam_ = PinholeCamera::FromFovY(640, 480, 40);
  const HeadModelOutput out_ = model_.Forward(HeadModelParams{});
  cv::RNG rng_;
  cv::Mat background_;
};

}  // namespace headcast::testing
