// The head mask against renders whose mask is known: the built-in head at
// several turns and pitches over a cluttered background, seeded with exact
// projected landmarks and with the face tracker's own.
#include "common/tracking/head_mask.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "common/core/crop.h"
#include "common/core/timer.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_outline.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/face_tracker.h"
#include "common/tracking/frame_mask.h"
#include "tests/testing/resting_head_scenes.h"

namespace headcast {
namespace {

using testing::ClutteredBackground;
using testing::ExactLandmarks;
using testing::RestingHeadScenes;

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

// The sender's mask of a live frame, cut to the avatar's square as prep cuts
// a training target's: its outline is the head's (the render's silhouette),
// within a millimetre or two at the top; a frame of another aspect has no square.
TEST(FrameMask, TheCutMasksOutlineIsTheHeads) {
  const RestingHeadScenes scenes(9);
  CameraContract contract;
  contract.source = scenes.camera();
  contract.crop_x0 = 120;
  contract.crop_y0 = 40;
  contract.crop_side = 400;
  const std::optional<FrameCrop> crop = ContractCrop(contract, scenes.camera(), 256);
  ASSERT_TRUE(crop);
  EXPECT_EQ(crop->camera.width, 256);
  PinholeCamera wide = scenes.camera();
  wide.width = 853;  // 16:9
  EXPECT_FALSE(ContractCrop(contract, wide, 256));
  const HeadModel& model = scenes.model();
  const HeadIdentity identity = model.MakeIdentity(Eigen::VectorXd::Zero(model.num_shape()));
  const HeadFitter fitter(model);
  const OutlineOptions o;
  for (double pitch : {0.0, 15.0}) {
    const RestingHeadScenes::Scene s = scenes.At(0.7, 10, pitch);
    Stopwatch watch;
    HeadModelOutput posed;
    model.Forward(identity, s.params.expression.cast<double>(), s.params.HeadPose(), &posed);
    const cv::Mat cut = CutCropMask(CropGrabCutMask(s.image, s.landmarks, *crop), model, posed,
                                    fitter.Project(s.params, crop->camera), s.params, crop->camera, MatteRules{});
    std::printf("pitch %+.0f: mask cut in %.1f ms\n", pitch, watch.ElapsedMs());
    ASSERT_EQ(cut.rows, 256);
    cv::Mat truth = CropSquare(s.mask, crop->x0, crop->y0, crop->side, 256, cv::INTER_LINEAR);
    cv::threshold(truth, truth, 127, 255, cv::THRESH_BINARY);
    const OutlineFrame at = OutlineFrame::Of(crop->camera, s.params.CamFromHead(), o);
    const std::vector<float> measured = MeasureOutline(cut, at, o), true_mm = MeasureOutline(truth, at, o);
    int known = 0;
    for (int k = 0; k < o.bins; ++k) {
      if (true_mm[k] == kOutlineUnknown) continue;
      ++known;
      EXPECT_NE(measured[k], kOutlineUnknown) << "pitch " << pitch << " arc " << k;
      EXPECT_NEAR(measured[k], true_mm[k], 3.0) << "pitch " << pitch << " arc " << k;
      std::printf("  arc %d: %.1f mm (true %.1f)\n", k, measured[k], true_mm[k]);
    }
    EXPECT_GE(known, o.bins / 2) << "pitch " << pitch;
  }
}

// A sequence whose frames reuse the colour models learnt on every Nth: the
// frames between cut as closely to the head as a frame that learns its own.
TEST(HeadMask, CarriedColourModelsCutLikeAFramesOwn) {
  const RestingHeadScenes scenes(11);
  HeadMaskOptions every4;
  every4.refit_every = 4;
  HeadMaskModels carried;
  int frame = 0;
  for (double yaw : {-12.0, -9.0, -6.0, -3.0, 0.0, 3.0}) {
    const RestingHeadScenes::Scene s = scenes.At(0.7, yaw, 0);
    Stopwatch watch;
    const cv::Mat reused = HeadMask(s.image, s.landmarks, every4, &carried);
    const double reused_ms = watch.ElapsedMs();
    watch.Restart();
    const cv::Mat own = HeadMask(s.image, s.landmarks);
    const double own_ms = watch.ElapsedMs();
    EXPECT_EQ(carried.frames_since_fit, frame % 4) << "frame " << frame;
    ASSERT_FALSE(carried.background.empty());
    std::printf(
        "frame %d (%s models): IoU %.4f against the truth, %.4f against its own models' mask; %.1f ms vs %.1f\n", frame,
        frame % 4 ? "carried" : "its own", MaskIou(reused, s.mask), MaskIou(reused, own), reused_ms, own_ms);
    EXPECT_GT(MaskIou(reused, s.mask), 0.9) << "frame " << frame;
    EXPECT_GT(MaskIou(reused, own), 0.97) << "frame " << frame;
    ++frame;
  }
  HeadMaskOptions bad;
  bad.refit_every = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

TEST(HeadMask, ACarriedModelsCutOfTheWantedRowsIsTheWholeCutThere) {
  const RestingHeadScenes scenes(11);
  HeadMaskOptions o;
  o.refit_every = 100;
  for (double yaw : {-8.0, 0.0, 6.0}) {
    HeadMaskModels learnt;
    const RestingHeadScenes::Scene before = scenes.At(0.7, yaw - 3, 0);
    HeadMask(before.image, before.landmarks, o, &learnt);
    const RestingHeadScenes::Scene s = scenes.At(0.7, yaw, 0);
    double brow_y = 0;  // the rows above the brows: the hair's outline
    for (int k = 17; k <= 26; ++k) brow_y += 0.1 * s.landmarks[k].y();
    HeadMaskModels for_whole{learnt.background.clone(), learnt.foreground.clone(), 0, {}, {}},
        for_band{learnt.background.clone(), learnt.foreground.clone(), 0, {}, {}};
    Stopwatch watch;
    const cv::Mat whole = HeadMask(s.image, s.landmarks, o, &for_whole);
    const double whole_ms = watch.ElapsedMs();
    watch.Restart();
    const cv::Mat band = HeadMask(s.image, s.landmarks, o, &for_band, brow_y);
    const double band_ms = watch.ElapsedMs();
    const cv::Range above(0, static_cast<int>(brow_y));
    const double iou = MaskIou(band.rowRange(above), whole.rowRange(above));
    std::printf("yaw %+.0f: above the brows IoU %.4f with the whole cut, %.4f with the truth; %.1f ms vs %.1f\n", yaw,
                iou, MaskIou(band.rowRange(above), s.mask.rowRange(above)), band_ms, whole_ms);
    EXPECT_GT(iou, 0.99) << "yaw " << yaw;
    EXPECT_GT(MaskIou(band.rowRange(above), s.mask.rowRange(above)), 0.9) << "yaw " << yaw;
    // Beneath, the seeds' probable head: still one head, the face in it.
    EXPECT_GT(MaskIou(band, s.mask), 0.8) << "yaw " << yaw;
  }
  HeadMaskOptions bad;
  bad.wanted_margin = -0.1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// A frame cut near the last one's outline (HeadMaskOptions::band) comes out
// as the whole region's cut while the outline moves less than the band, and
// the band moves with the face; a last mask far off holds the cut near it.
TEST(HeadMask, ACutNearTheLastOutlineIsTheWholeCutWhileTheHeadMovesWithin) {
  const RestingHeadScenes scenes(11);
  HeadMaskOptions whole_o, band_o;
  whole_o.refit_every = band_o.refit_every = 100;
  band_o.band = 8;
  HeadMaskModels whole, banded;
  const RestingHeadScenes::Scene first = scenes.At(0.7, -6, 0);
  HeadMask(first.image, first.landmarks, band_o, &banded);
  EXPECT_TRUE(banded.last_mask.empty()) << "a learning leaves no last mask: the next cut is whole";
  whole = {banded.background.clone(), banded.foreground.clone(), 0, {}, {}};
  int frame = 0;
  for (const auto& [yaw, shift] : std::vector<std::pair<double, cv::Point2f>>{
           {-6, {0, 0}}, {-3, {0, 0}}, {0, {0, 0}}, {3, {0, 0}}, {3, {30, 12}}, {5, {-10, 20}}}) {
    const RestingHeadScenes::Scene s = scenes.Moved(scenes.At(0.7, yaw, 0), shift);
    Stopwatch watch;
    const cv::Mat near = HeadMask(s.image, s.landmarks, band_o, &banded);
    const double near_ms = watch.ElapsedMs();
    watch.Restart();
    const cv::Mat all = HeadMask(s.image, s.landmarks, whole_o, &whole);
    const double all_ms = watch.ElapsedMs();
    ASSERT_EQ(banded.last_mask.size(), s.image.size());
    EXPECT_EQ(cv::countNonZero(banded.last_mask != near), 0);
    std::printf(
        "yaw %+.0f, moved (%+.0f, %+.0f) px: IoU %.4f with the whole cut, %.4f with the truth; %.1f ms vs %.1f\n", yaw,
        shift.x, shift.y, MaskIou(near, all), MaskIou(near, s.mask), near_ms, all_ms);
    if (frame++ > 0) {  // the first is cut whole
      EXPECT_GT(MaskIou(near, all), 0.99) << "yaw " << yaw;
    }
    EXPECT_GT(MaskIou(near, s.mask), 0.9) << "yaw " << yaw;
  }
  // A last mask 40 px inside the head's: the cut cannot reach the true outline.
  const RestingHeadScenes::Scene s = scenes.At(0.7, 0, 0);
  cv::Mat shrunk;
  cv::erode(s.mask, shrunk, cv::getStructuringElement(cv::MORPH_ELLIPSE, {81, 81}));
  banded.last_mask = shrunk;
  banded.last_centre = {0, 0};
  for (const auto& p : s.landmarks) banded.last_centre += cv::Point2f(p.x(), p.y()) * (1.f / kNumLandmarks);
  const cv::Mat held = HeadMask(s.image, s.landmarks, band_o, &banded);
  const cv::Mat all = HeadMask(s.image, s.landmarks, whole_o, &whole);
  std::printf("last mask 40 px inside: %d head pixels against %d cut whole\n", cv::countNonZero(held),
              cv::countNonZero(all));
  EXPECT_LT(cv::countNonZero(held), 0.9 * cv::countNonZero(all));
  EXPECT_GT(MaskIou(all, s.mask), 0.9);
  HeadMaskOptions bad;
  bad.band = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// What a learner keeps: the models HeadMask learns on the frame, without its mask.
TEST(HeadMask, ItsModelsAloneAreTheModelsItLearns) {
  const RestingHeadScenes scenes(11);
  const RestingHeadScenes::Scene s = scenes.At(0.7, -5, 3);
  HeadMaskModels learnt;
  cv::theRNG().state = 5;
  Stopwatch watch;
  HeadMask(s.image, s.landmarks, {}, &learnt);
  const double mask_ms = watch.ElapsedMs();
  cv::theRNG().state = 5;
  watch.Restart();
  const HeadMaskModels alone = LearnHeadMaskModels(s.image, s.landmarks);
  std::printf("learnt with the mask %.1f ms, alone %.1f ms\n", mask_ms, watch.ElapsedMs());
  ASSERT_FALSE(alone.background.empty());
  EXPECT_EQ(cv::norm(learnt.background, alone.background, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(learnt.foreground, alone.foreground, cv::NORM_INF), 0.0);
  EXPECT_TRUE(alone.last_mask.empty());
  Landmarks2d tiny = s.landmarks;
  for (auto& p : tiny) p = Eigen::Vector2d(1, 1) + 1e-3 * p;  // a head a pixel across
  EXPECT_THROW(LearnHeadMaskModels(s.image, tiny), std::invalid_argument);
  EXPECT_EQ(cv::countNonZero(HeadMask(s.image, tiny)), 0);
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
