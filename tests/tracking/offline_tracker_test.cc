// The offline pass (TrackFrames) fed by a fake frame source: the built-in head
// rendered at known poses, with and without depth, one frame unreadable. The
// real dlib tracker and fitters run on the rendered pictures.
#include "common/tracking/offline_tracker.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <thread>

#include "common/core/rotation.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/skin_colour.h"
#include "common/tracking/background_identity.h"
#include "common/tracking/frame_tracker.h"

namespace headcast {
namespace {

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

// Frames of the built-in head turning slowly; frame `skip` is unreadable.
class FakeHeadSource : public FrameSource {
 public:
  FakeHeadSource(int frames, bool depth, int skip = -1) : frames_(frames), depth_(depth), skip_(skip) {
    params_.shape = Eigen::VectorXd::Zero(Model().num_shape());
    params_.shape[0] = 0.8;
    params_.expression = Eigen::VectorXd::Zero(Model().num_expression());
  }
  ReadStatus Read(CapturedFrame* frame, std::string* problem) override {
    if (next_ >= frames_) return ReadStatus::kEnd;
    const int n = next_++;
    if (n == skip_) {
      *problem = "frame " + std::to_string(n) + ": unreadable (the fake's corrupt frame)";
      return ReadStatus::kSkipped;
    }
    const HeadModel& model = Model();
    const RigidTransform cam_from_head = CamFromHead(n);
    const HeadRender r =
        RenderHead(model, model.Forward(params_).vertices, cam_from_head, camera(), AlbedoTexture(model));
    frame->bgr = r.image_bgr;
    if (depth_) {
      frame->depth_m = r.depth.clone();
      frame->depth_m.setTo(1.4f, r.mask == 0);  // a wall behind the head
      frame->camera = camera();
    }
    frame->capture_time_s = n / 30.0;
    frame->index = static_cast<uint64_t>(n);
    return ReadStatus::kFrame;
  }
  std::string Describe() const override { return "fake rendered head"; }
  double fps() const override { return 30; }
  bool has_depth() const override { return depth_; }

  static PinholeCamera camera() { return PinholeCamera::FromFovY(640, 480, 45); }
  static RigidTransform CamFromHead(int n) {
    return FrontalCamFromHead(0.5, -10 + 2.0 * n, 0, Model().rest_landmark_centroid());
  }
  const HeadModelParams& params() const { return params_; }

 private:
  int frames_, next_ = 0;
  bool depth_;
  int skip_;
  HeadModelParams params_;
};

TEST(OfflineTracker, RgbdFramesFreezeTheIdentityAndEveryFrameIsWritten) {
  OfflineTrackOptions o;
  o.input = "fake";
  o.calibration_frames = 4;
  o.masks = true;
  o.fit_appearance = false;
  int observed = 0, masks = 0;
  const OfflineTrack t = TrackFrames(
      Model(), o, [] { return std::make_unique<FakeHeadSource>(10, true, /*skip=*/3); },
      [&](const OfflineFrame& f) {
        EXPECT_EQ(f.index, observed) << "frame numbers count readable frames";
        ++observed;
        masks += !f.mask.empty();
      });
  EXPECT_EQ(t.frames_read, 9);
  EXPECT_EQ(observed, 9);
  EXPECT_EQ(t.report["unreadable_frames"], 1);
  ASSERT_EQ(static_cast<int>(t.frames.size()), 9) << t.report.dump(1);
  EXPECT_EQ(masks, 9);
  for (size_t i = 0; i < t.frames.size(); ++i) EXPECT_EQ(t.frames[i].sequence, i);
  EXPECT_LT(t.report["rgbd_accuracy_mm_median"].get<double>(), 1.5);
  EXPECT_EQ(t.report["identity"], "RGB-D: median shape of the first fitted frames");
  EXPECT_NEAR(t.subject.shape[0], 0.8, 0.3) << "the identity comes from the depth";
  // Frame 5 of the pass is source frame 6 (frame 3 was unreadable).
  const RigidTransform truth = FakeHeadSource::CamFromHead(6);
  EXPECT_LT((t.frames[5].cam_translation.cast<double>() - truth.translation).norm(), 0.005);
  const Eigen::Matrix3d fitted = AxisAngleToMatrix(t.frames[5].cam_rotation.cast<double>());
  EXPECT_LT(MatrixToAxisAngle(fitted.transpose() * truth.rotation).norm() * 180 / M_PI, 2.0);
}

TEST(BackgroundIdentity, MedianShapeAndOneFrameAtATime) {
  EXPECT_TRUE(MedianShape({Eigen::Vector2d(1, 5), Eigen::Vector2d(3, 4), Eigen::Vector2d(2, 6)})
                  .isApprox(Eigen::Vector2d(2, 5)));
  EXPECT_THROW(MedianShape({}), std::invalid_argument);
  FakeHeadSource source(2, true);
  CapturedFrame frame;
  std::string problem;
  ASSERT_EQ(source.Read(&frame, &problem), ReadStatus::kFrame);
  FaceTracker faces;
  const FaceObservation face = faces.Track(frame.bgr, 0);
  ASSERT_NE(face.status, FaceStatus::kNoFace);
  BackgroundIdentity identity(Model(), RgbdFitOptions{}, 1);
  ASSERT_TRUE(identity.Offer(face.landmarks, frame.depth_m, FakeHeadSource::camera()));
  EXPECT_FALSE(identity.Offer(face.landmarks, frame.depth_m, FakeHeadSource::camera()))
      << "one frame wanted, one taken";
  for (int i = 0; i < 3000 && !identity.Identity(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(identity.Identity().has_value());
  EXPECT_EQ(identity.fits_done(), 1);
  EXPECT_NEAR((*identity.Identity())[0], 0.8, 0.3);
  EXPECT_FALSE(identity.Offer(face.landmarks, frame.depth_m, FakeHeadSource::camera())) << "made: no more fits";
}

TEST(FrameTracker, LiveRgbdIdentityIsFittedBesideTracking) {
  FrameTrackerOptions o;
  o.rgbd_identity_frames = 3;
  o.rgbd_identity_in_background = true;
  FrameTracker tracker(Model(), o);
  const PinholeCamera camera = FakeHeadSource::camera();
  int frames = 0, provisional = 0, made = 0, last = 0;
  auto source = std::make_unique<FakeHeadSource>(10, true);
  // Every frame is tracked at once, the identity's fits beside it, until it is
  // made; then a few frames more with it.
  for (int after = 0; frames < 5000 && after < 4; ++frames) {
    CapturedFrame frame;
    std::string problem;
    if (source->Read(&frame, &problem) != ReadStatus::kFrame) {
      source = std::make_unique<FakeHeadSource>(10, true);
      ASSERT_EQ(source->Read(&frame, &problem), ReadStatus::kFrame);
    }
    FrameParams params;
    const TrackedFrame t = tracker.Track(frame.bgr, frame.depth_m, frames / 30.0, camera, &params);
    ASSERT_TRUE(t.fitted) << "frame " << frames << ": " << t.problem;
    EXPECT_FALSE(t.identity_frame) << "no frame waits for a free-shape fit";
    provisional += t.provisional_identity;
    made += t.identity_frozen_now;
    if (tracker.identity_frozen()) {
      ++after;
      EXPECT_FALSE(t.provisional_identity);
      last = static_cast<int>(frame.index);
      const RigidTransform truth = FakeHeadSource::CamFromHead(last);
      EXPECT_LT((params.cam_translation.cast<double>() - truth.translation).norm(), 0.005) << "frame " << frames;
    } else {
      EXPECT_TRUE(t.provisional_identity);
    }
  }
  EXPECT_EQ(made, 1);
  EXPECT_GE(provisional, 1);
  ASSERT_TRUE(tracker.identity_frozen()) << "no identity after " << frames << " frames";
  EXPECT_NEAR(tracker.identity()[0], 0.8, 0.3) << "the identity comes from the depth";
}

TEST(OfflineTracker, ColourFramesAreFittedWithTheGivenIdentityAndCamera) {
  OfflineTrackOptions o;
  o.input = "fake";
  o.fit_appearance = false;
  o.intrinsics = FakeHeadSource::camera();
  FakeHeadSource reference(1, false);
  o.identity = reference.params().shape;
  o.identity_source = "the fake's shape";
  const OfflineTrack t = TrackFrames(Model(), o, [] { return std::make_unique<FakeHeadSource>(6, false); });
  ASSERT_EQ(t.frames.size(), 6u) << t.report.dump(1);
  EXPECT_EQ(t.report["identity"], "the fake's shape");
  EXPECT_EQ(t.subject.intrinsics.width, 640);
  EXPECT_NEAR(t.subject.intrinsics.fx, FakeHeadSource::camera().fx, 1e-9);
  EXPECT_LT(t.report["landmark_error_iod_mean"].get<double>(), 0.1);
  const HeadModelOutput posed = Model().Forward(reference.params());
  for (int n = 0; n < 6; ++n) {
    const RigidTransform truth = FakeHeadSource::CamFromHead(n);
    EXPECT_LT((t.frames[n].cam_translation.cast<double>() - truth.translation).norm(), 0.03) << "frame " << n;
    // Each frame carries its skin colour: the median where the true landmarks
    // put the cheeks, nose and chin, up to the fit's few pixels of error.
    Landmarks2d landmarks;
    for (int l = 0; l < kNumLandmarks; ++l)
      landmarks[l] = FakeHeadSource::camera().Project(truth.Apply(posed.landmarks.row(l).transpose().cast<double>()));
    CapturedFrame frame;
    std::string problem;
    FakeHeadSource source(n + 1, false);
    for (int k = 0; k <= n; ++k) ASSERT_EQ(source.Read(&frame, &problem), ReadStatus::kFrame);
    const std::optional<Eigen::Vector3f> true_colour = SkinColour(frame.bgr, landmarks);
    ASSERT_TRUE(true_colour && t.frames[n].skin_colour) << "frame " << n;
    EXPECT_LT((*t.frames[n].skin_colour - *true_colour).cwiseAbs().maxCoeff(), 0.03f) << "frame " << n;
    EXPECT_GT(true_colour->maxCoeff(), 0.2f) << "lit skin, not the dark background";
  }
}

TEST(OfflineTracker, OptionsAreChecked) {
  OfflineTrackOptions o;
  EXPECT_THROW(o.Check(), std::invalid_argument);  // no input
  o.input = "/dev/video0";
  o.calibrate = true;
  EXPECT_THROW(o.Check(), std::invalid_argument);  // a camera cannot be read twice
  o.input = "clip.mp4";
  o.Check();
  o.identity = Eigen::VectorXd::Zero(3);
  EXPECT_THROW(o.Check(), std::invalid_argument);  // calibrate and a given identity
  o.calibrate = false;
  EXPECT_THROW(TrackFrames(Model(), o, [] { return std::make_unique<FakeHeadSource>(1, false); }),
               std::invalid_argument);  // 3 shape values for a 12-component model
  o.identity.resize(0);
  EXPECT_THROW(TrackFrames(Model(), o, [] { return std::make_unique<FakeHeadSource>(0, false); }),
               std::runtime_error);  // no readable frames
}

}  // namespace
}  // namespace headcast
