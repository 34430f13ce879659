// The head mask against renders whose mask is known: the built-in head at
// several turns and pitches over a cluttered background, seeded with exact
// projected landmarks and with the face tracker's own.
#include "common/tracking/head_mask.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/face_tracker.h"

namespace headcast {
namespace {

// Clutter: blurred coloured blobs, the background the renders are put on.
cv::Mat ClutteredBackground(cv::RNG& rng) {
  cv::Mat background(480, 640, CV_8UC3);
  rng.fill(background, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(background, background, {0, 0}, 9);
  cv::normalize(background, background, 0, 255, cv::NORM_MINMAX);
  return background;
}

Landmarks2d ExactLandmarks(const HeadModelOutput& out, const RigidTransform& cam_from_head, const PinholeCamera& cam) {
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
  };
  Scene At(double distance, double yaw_deg, double pitch_deg) const {
    const RigidTransform cam_from_head =
        FrontalCamFromHead(distance, yaw_deg, pitch_deg, model_.rest_landmark_centroid());
    const HeadRender r = RenderHead(model_, out_.vertices, cam_from_head, cam_, AlbedoTexture(model_));
    Scene s{background_.clone(), r.mask, ExactLandmarks(out_, cam_from_head, cam_)};
    r.image_bgr.copyTo(s.image, r.mask);
    return s;
  }

 private:
  const HeadModel model_ = MakeBuiltinHead();
  const PinholeCamera cam_ = PinholeCamera::FromFovY(640, 480, 40);
  const HeadModelOutput out_ = model_.Forward(HeadModelParams{});
  cv::RNG rng_;
  cv::Mat background_;
};

TEST(HeadMask, IouOnRendersWithKnownMasks) {
  const HeadModel model = MakeBuiltinHead();
  const PinholeCamera cam = PinholeCamera::FromFovY(640, 480, 40);
  cv::RNG rng(3);
  FaceTracker tracker;
  double sum_exact = 0, sum_tracked = 0;
  int tracked = 0;
  const double yaws[] = {-30, -10, 0, 15, 30};
  for (double yaw : yaws) {
    HeadModelParams p;
    p.pose[3 * kJawJoint] = 0.1;
    const HeadModelOutput out = model.Forward(p);
    const RigidTransform cam_from_head = FrontalCamFromHead(0.7, yaw, 0, model.rest_landmark_centroid());
    const HeadRender r = RenderHead(model, out.vertices, cam_from_head, cam, AlbedoTexture(model));
    cv::Mat image = ClutteredBackground(rng);
    r.image_bgr.copyTo(image, r.mask);
    const Landmarks2d exact = ExactLandmarks(out, cam_from_head, cam);
    const double iou = MaskIou(HeadMask(image, exact), r.mask);
    sum_exact += iou;
    const FaceObservation obs = tracker.Track(image, 0);
    double iou_tracked = -1;
    if (obs.status != FaceStatus::kNoFace) {
      iou_tracked = MaskIou(HeadMask(image, obs.raw), r.mask);
      sum_tracked += iou_tracked;
      ++tracked;
    }
    std::printf("yaw %+.0f: IoU %.3f with exact landmarks, %.3f with tracked ones\n", yaw, iou, iou_tracked);
  }
  const double mean_exact = sum_exact / std::size(yaws);
  std::printf("mean IoU: %.3f exact landmarks, %.3f tracked (%d of %zu found)\n", mean_exact,
              tracked ? sum_tracked / tracked : 0.0, tracked, std::size(yaws));
  EXPECT_GT(mean_exact, 0.9);
  ASSERT_GE(tracked, 3);
  EXPECT_GT(sum_tracked / tracked, 0.85);
}

// A head pitched chin-down looks short from brow to chin, and a region sized by
// that height alone left the top of the head out as certain background.
TEST(HeadMask, APitchedHeadKeepsItsTop) {
  const RestingHeadScenes scenes(5);
  HeadMaskOptions before;  // the region before the face height had a floor and the ring existed
  before.min_face_height = 0;
  before.background_ring = 0;
  double sum_now = 0, sum_before = 0;
  const double pitches[] = {-15, 20, 30, 40};
  for (double pitch : pitches) {
    const RestingHeadScenes::Scene r = scenes.At(0.7, 0, pitch);
    const cv::Mat now = HeadMask(r.image, r.landmarks), old = HeadMask(r.image, r.landmarks, before);
    const int true_top = cv::boundingRect(r.mask).y, top = cv::boundingRect(now).y;
    std::printf("pitch %+.0f: IoU %.3f (before: %.3f), top row %d (truth %d, before %d)\n", pitch, MaskIou(now, r.mask),
                MaskIou(old, r.mask), top, true_top, cv::boundingRect(old).y);
    sum_now += MaskIou(now, r.mask);
    sum_before += MaskIou(old, r.mask);
    EXPECT_LE(top - true_top, 12) << "pitch " << pitch;  // 2.5 % of the picture
    EXPECT_GT(MaskIou(now, r.mask), 0.9) << "pitch " << pitch;
  }
  EXPECT_GT(sum_now, sum_before);
}

// GrabCut's grid is the outline's: segmented coarser than the picture, the
// mask's edge is a staircase of the coarse pixels, up to half of one off.
TEST(HeadMask, AFinerWorkingGridDrawsTheOutlineCloser) {
  const RestingHeadScenes scenes(7);
  HeadMaskOptions coarse, fine;
  coarse.working_size = 100;
  fine.working_size = 400;
  int wrong_coarse = 0, wrong_fine = 0;
  for (double yaw : {-20.0, 0.0, 25.0}) {
    const RestingHeadScenes::Scene r = scenes.At(0.6, yaw, 0);
    const int c = cv::countNonZero(HeadMask(r.image, r.landmarks, coarse) != r.mask),
              f = cv::countNonZero(HeadMask(r.image, r.landmarks, fine) != r.mask);
    std::printf("yaw %+.0f: %d pixels wrong at working size %d, %d at %d\n", yaw, c, coarse.working_size, f,
                fine.working_size);
    wrong_coarse += c;
    wrong_fine += f;
  }
  EXPECT_LT(wrong_fine, wrong_coarse);
}

TEST(HeadMask, BadInputIsRefused) {
  Landmarks2d l;
  for (auto& p : l) p = Eigen::Vector2d(10, 10);
  EXPECT_THROW(HeadMask(cv::Mat(), l), std::invalid_argument);
  l[3] = Eigen::Vector2d(NAN, 0);
  EXPECT_THROW(HeadMask(cv::Mat(100, 100, CV_8UC3, cv::Scalar(0, 0, 0)), l), std::invalid_argument);
  EXPECT_THROW(MaskIou(cv::Mat(10, 10, CV_8U), cv::Mat(5, 5, CV_8U)), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
