// The matte: the mask rules' bound on a posed head, the renderer's coverage
// (starting as the picture without one, bounded pixels exactly the
// background, learning the mask), and its file.
#include "common/avatar/matte.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

#include "common/avatar/avatar_pipeline.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"
#include "tests/testing/posed_head.h"
#include "tests/testing/test_data.h"
#include "tests/testing/tiny_avatar.h"

namespace headcast {
namespace {

const HeadModel& Builtin() { return *testing::BuiltinHead(); }

AvatarConfig TinyWithMatte(MatteMode mode) {
  AvatarConfig c = testing::TinyAvatarConfig();
  c.matte = mode;
  return c;
}

// Less turned than testing::Expressive(): both temples stay in view for the margins' checks.
FrameParams Turned() {
  FrameParams p = testing::Expressive();
  p.expression[0] = 0;
  p.jaw = Eigen::Vector3f(0.2f, 0, 0);
  p.neck = Eigen::Vector3f(0.05f, 0.25f, 0);
  return p;
}

// The posed head's silhouette and projected landmarks at `size`.
struct PosedView {
  cv::Mat silhouette;
  Landmarks2d landmarks;
};
PosedView View(const FrameParams& frame, int size) {
  const testing::Posed p = testing::Pose(frame, size);
  RasterBuffers raster;
  Rasterize(p.v_cam, Builtin().data().faces, p.camera, RasterOptions{}, &raster);
  PosedView v;
  v.silhouette = raster.Mask();
  for (int l = 0; l < kNumLandmarks; ++l)
    v.landmarks[l] = p.camera.Project(frame.CamFromHead().Apply(p.posed.landmarks.row(l).transpose().cast<double>()));
  return v;
}

cv::Mat Shown(Avatar& avatar, const FrameParams& frame, AvatarFrameInputs* buffers) {
  const HeadModel& m = Builtin();
  avatar.modules().eval();
  torch::InferenceMode inference;
  RaySampler sampler(avatar.config());
  cv::Mat image;
  RenderAvatarFrame(avatar.modules(), avatar.config(), m, m.MakeIdentity(avatar.subject().shape.cast<double>()),
                    avatar.subject(), frame, &sampler, buffers, &image);
  return image;
}

cv::Vec3b BackgroundBgr() {
  const cv::Vec3f rgb = HeadRenderOptions{}.background_rgb;
  return cv::Vec3b(cv::saturate_cast<uchar>(255 * rgb[2]), cv::saturate_cast<uchar>(255 * rgb[1]),
                   cv::saturate_cast<uchar>(255 * rgb[0]));
}

}  // namespace

TEST(DilateEllipse, EqualsOpenCvsDilationWithTheEllipticalElement) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> coin(0, 999);
  const PosedView view = View(Turned(), 256);
  for (const cv::Size size : {cv::Size(256, 256), cv::Size(97, 61), cv::Size(5, 300)}) {
    cv::Mat sparse(size, CV_8U);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) sparse.at<uint8_t>(y, x) = coin(rng) < 3 ? 255 : 0;
    for (const cv::Mat& mask : {sparse, size == view.silhouette.size() ? view.silhouette : sparse})
      for (int radius : {0, 1, 5, kDilateEllipseOwnRadius, kDilateEllipseOwnRadius + 1, 20, 41, 300}) {
        cv::Mat expected;
        cv::dilate(mask, expected, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * radius + 1, 2 * radius + 1}));
        const cv::Mat got = DilateEllipse(mask, radius);
        ASSERT_EQ(got.size(), mask.size());
        EXPECT_EQ(cv::countNonZero(got != expected), 0) << size << " radius " << radius;
      }
  }
  EXPECT_EQ(cv::countNonZero(DilateEllipse(cv::Mat::zeros(40, 40, CV_8U), 9)), 0);
  EXPECT_THROW(DilateEllipse(cv::Mat::zeros(4, 4, CV_32F), 1), std::invalid_argument);
}

TEST(MatteRules, TravelAsJsonAndRefuseBadMargins) {
  const MatteRules r{0.1, 0.03, true};
  EXPECT_TRUE(MatteRules::FromJson(r.ToJson()) == r);
  EXPECT_THROW((MatteRules{0.05, 0.1, false}.Check()), std::invalid_argument) << "sides beyond the hair";
  EXPECT_THROW((MatteRules{-0.1, 0, false}.Check()), std::invalid_argument);
  nlohmann::json j = r.ToJson();
  j.erase("keep_neck");
  EXPECT_THROW(MatteRules::FromJson(j), std::invalid_argument);
  j = r.ToJson();
  j["side_margin"] = "wide";
  EXPECT_THROW(MatteRules::FromJson(j), std::invalid_argument);
  j = r.ToJson();
  j["fill_skull"] = "yes";
  EXPECT_THROW(MatteRules::FromJson(j), std::invalid_argument);
  // Rules written before the skull fill existed were cut without it.
  j = r.ToJson();
  EXPECT_TRUE(MatteRules::FromJson(j).fill_skull);
  j.erase("fill_skull");
  EXPECT_FALSE(MatteRules::FromJson(j).fill_skull);
}

// GrabCut that took the hair for the wall (a mask that stops at the
// hairline): the cut mask holds the whole skull above the brows, not what
// lies beyond it, and leaves the rest of GrabCut's answer as it was.
TEST(CutTrainingMask, TheSkullAboveTheBrowsIsHead) {
  const int size = 128;
  const PosedView v = View(Turned(), size);
  const Landmarks2d& lm = v.landmarks;
  const Eigen::Vector2d chin = lm[8], brows = 0.5 * (lm[19] + lm[24]);
  const Eigen::Vector2d up = (brows - chin).normalized();
  auto at = [&](const cv::Mat& m, const Eigen::Vector2d& p) -> int {
    return m.at<uchar>(static_cast<int>(std::lround(p.y())), static_cast<int>(std::lround(p.x())));
  };
  // The skull's top along the face's up direction from the brows.
  double top = 0;
  while (at(v.silhouette, brows + (top + 1) * up) == 255) top += 1;
  ASSERT_GT(top, 10) << "no skull above the brows";
  const double face = (brows - chin).norm();
  // GrabCut's answer: the head below a hairline 0.2 face heights above the brows.
  cv::Mat grabcut = v.silhouette.clone();
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x)
      if ((Eigen::Vector2d(x, y) - brows).dot(up) > 0.2 * face) grabcut.at<uchar>(y, x) = 0;
  // ... and a notch it cut out of the cheek, below the brows.
  const Eigen::Vector2d cheek = 0.5 * (lm[3] + lm[30]);
  cv::circle(grabcut, cv::Point(cvRound(cheek.x()), cvRound(cheek.y())), 2, cv::Scalar(0), cv::FILLED);
  ASSERT_EQ(at(grabcut, brows + 0.7 * top * up), 0);

  const MatteRules rules;
  ASSERT_TRUE(rules.fill_skull);
  const cv::Mat cut = CutTrainingMask(grabcut, v.silhouette, lm, rules);
  EXPECT_EQ(at(cut, brows + 0.7 * top * up), 255) << "the skull above the hairline";
  EXPECT_EQ(at(cut, brows + (top + 4) * up), 0) << "beyond the skull: GrabCut's answer (background)";
  EXPECT_EQ(at(cut, cheek), 0) << "below the brows the mask is GrabCut's";
  EXPECT_EQ(cv::countNonZero(cut & ~MatteBound(v.silhouette, lm, rules)), 0) << "within the bound";
  // The inset: the skull's outline itself is not added.
  EXPECT_EQ(at(cut, brows + (top - 1) * up), 0);

  MatteRules without = rules;
  without.fill_skull = false;
  const cv::Mat as_before = CutTrainingMask(grabcut, v.silhouette, lm, without);
  EXPECT_EQ(at(as_before, brows + 0.7 * top * up), 0);
  cv::Mat expected = grabcut.clone();
  FillHairNotches(lm, &expected);
  cv::bitwise_and(expected, MatteBound(v.silhouette, lm, without), expected);
  EXPECT_EQ(cv::countNonZero(as_before != expected), 0) << "without the fill: notches filled, then bounded";
}

// A disc of radius `r` at (cx, cy) on a 96 x 96 mask, and the square's corners
// around it as the points that move with it.
cv::Mat Disc(double cx, double cy, double r) {
  cv::Mat m = cv::Mat::zeros(96, 96, CV_8U);
  cv::circle(m, cv::Point(static_cast<int>(std::lround(cx * 16)), static_cast<int>(std::lround(cy * 16))),
             static_cast<int>(std::lround(r * 16)), cv::Scalar(255), cv::FILLED, cv::LINE_8, 4);
  return m;
}
Eigen::Matrix2Xd Corners(double cx, double cy, double r) {
  Eigen::Matrix2Xd p(2, 4);
  p << cx - r, cx + r, cx + r, cx - r, cy - r, cy - r, cy + r, cy + r;
  return p;
}
int Differing(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat d;
  cv::compare(a, b, d, cv::CMP_NE);
  return cv::countNonZero(d);
}

TEST(SteadyMask, TakesANotchOutOfTheOutlineAndFollowsTheMotion) {
  // A head moving right 2 px and growing 0.5 px a frame; the centre frame's
  // segmentation cut a notch into its edge and added a tuft outside it.
  std::vector<cv::Mat> masks;
  std::vector<Eigen::Matrix2Xd> points;
  const std::vector<int64_t> numbers = {10, 11, 12, 13, 14};
  for (int i = 0; i < 5; ++i) {
    masks.push_back(Disc(40 + 2 * i, 48, 20 + 0.5 * i));
    points.push_back(Corners(40 + 2 * i, 48, 20 + 0.5 * i));
  }
  const cv::Mat clean = masks[2].clone();
  cv::rectangle(masks[2], cv::Rect(63, 44, 3, 8), cv::Scalar(0), cv::FILLED);    // notch at the right edge
  cv::rectangle(masks[2], cv::Rect(42, 24, 4, 2), cv::Scalar(255), cv::FILLED);  // tuft above the top
  ASSERT_GT(Differing(masks[2], clean), 25);

  const cv::Mat steady = SteadyMask(masks, points, numbers, 2, 2);
  EXPECT_EQ(steady.type(), CV_8U);
  // Within a few pixels: a rasterised disc's edge and a moved one's differ by some ties.
  EXPECT_LE(Differing(steady, clean), 10) << "the notch and tuft stay, or the outline lags the motion";
  // Unchanged by a radius of 0, and the first frame has neighbours on one side only.
  EXPECT_EQ(Differing(SteadyMask(masks, points, numbers, 2, 0), masks[2]), 0);
  EXPECT_LE(Differing(SteadyMask(masks, points, numbers, 0, 2), masks[0]), 10);
}

TEST(SteadyMask, LeavesFramesAcrossAGapAndUnplaceableOnesOut) {
  // Two empty neighbours outweigh the centre (3 against 2 + 2): the mask is
  // gone when they count, and kept whole when they may not.
  const cv::Mat empty = cv::Mat::zeros(96, 96, CV_8U);
  const std::vector<cv::Mat> masks = {empty, Disc(48, 48, 20), empty};
  const std::vector<Eigen::Matrix2Xd> points = {Corners(30, 48, 20), Corners(48, 48, 20), Corners(66, 48, 20)};
  EXPECT_EQ(cv::countNonZero(SteadyMask(masks, points, {0, 1, 2}, 1, 2)), 0);
  EXPECT_EQ(Differing(SteadyMask(masks, points, {0, 40, 80}, 1, 3), masks[1]), 0);  // beyond the radius
  // Points that do not fix an affine map (all on a line, or not finite).
  std::vector<Eigen::Matrix2Xd> bad = points;
  bad[0].row(1).setConstant(48);
  bad[2](0, 0) = std::nan("");
  EXPECT_EQ(Differing(SteadyMask(masks, bad, {0, 1, 2}, 1, 2), masks[1]), 0);
  // Mismatched inputs are refused.
  EXPECT_THROW(SteadyMask(masks, points, {0, 1}, 1, 2), std::invalid_argument);
  EXPECT_THROW(SteadyMask(masks, points, {0, 1, 2}, 3, 2), std::invalid_argument);
  std::vector<cv::Mat> sizes = masks;
  sizes[0] = cv::Mat::zeros(50, 50, CV_8U);
  EXPECT_THROW(SteadyMask(sizes, points, {0, 1, 2}, 1, 2), std::invalid_argument);
}

// The bound holds the silhouette above the jaw, grows it by the margins
// (more above the eyes), and nothing below the jaw line unless the neck is kept.
TEST(MatteBound, ReachesTheMarginsAndStopsAtTheJawLine) {
  const int size = 128;
  const PosedView v = View(Turned(), size);
  const MatteRules rules;  // 0.08 above the eyes, 0.02 below, no neck
  const cv::Mat bound = MatteBound(v.silhouette, v.landmarks, rules);
  ASSERT_EQ(bound.size(), v.silhouette.size());
  const Landmarks2d& lm = v.landmarks;
  const Eigen::Vector2d chin = lm[8], brows = 0.5 * (lm[19] + lm[24]);
  const Eigen::Vector2d down = (chin - brows).normalized();
  auto at = [&](const cv::Mat& m, const Eigen::Vector2d& p) -> int {
    const int x = static_cast<int>(std::lround(p.x())), y = static_cast<int>(std::lround(p.y()));
    return x >= 0 && y >= 0 && x < m.cols && y < m.rows ? m.at<uchar>(y, x) : -1;
  };
  // Below the chin: the silhouette (neck) is there, the bound is not.
  const Eigen::Vector2d under_chin = chin + 4 * down;
  ASSERT_EQ(at(v.silhouette, under_chin), 255)
      << "the built-in head has no neck under the chin: the test proves little";
  EXPECT_EQ(at(bound, under_chin), 0);
  EXPECT_EQ(at(MatteBound(v.silhouette, v.landmarks, MatteRules{0.08, 0.02, true}), under_chin), 255);
  // Above the brows every silhouette pixel is in the bound; past the top of
  // the head it reaches hair_margin * size, not twice that.
  const Eigen::Vector2d nose_bridge = lm[27];
  Eigen::Vector2d top = nose_bridge;
  while (at(v.silhouette, top - down) == 255) top -= down;
  EXPECT_EQ(at(bound, top), 255);
  EXPECT_EQ(at(bound, top - 0.5 * rules.hair_margin * size * down), 255);
  const Eigen::Vector2d across = (lm[17] - lm[26]).normalized();  // above the eyes, image left
  Eigen::Vector2d temple = lm[17];
  while (at(v.silhouette, temple + across) == 255) temple += across;
  EXPECT_EQ(at(bound, temple + 0.5 * rules.hair_margin * size * across), 255);
  EXPECT_EQ(at(bound, temple + 2.0 * rules.hair_margin * size * across), 0);
  // Beside the cheek (below the eyes) the margin is side_margin (the neck
  // kept, so that the jaw line's cut does not reach out there too).
  const cv::Mat with_neck = MatteBound(v.silhouette, v.landmarks, MatteRules{0.08, 0.02, true});
  const Eigen::Vector2d side = (lm[3] - lm[13]).normalized();  // image left
  Eigen::Vector2d cheek = lm[3];
  while (at(v.silhouette, cheek + side) == 255) cheek += side;
  EXPECT_EQ(at(with_neck, cheek + 0.5 * rules.side_margin * size * side), 255);
  EXPECT_EQ(at(with_neck, cheek + 3.0 * rules.side_margin * size * side), 0);
}

// Shoulders beyond the jaw's ends survive the jaw line's cut apart from the
// head: the bound keeps only the head's piece, and loses none of the head.
TEST(MatteBound, DropsWhatTheJawLinesCutLeavesApartFromTheHead) {
  const int size = 128;
  const PosedView v = View(Turned(), size);
  const int neck_row = static_cast<int>(std::lround(v.landmarks[8].y())) + 4;
  ASSERT_LT(neck_row, size - 8);
  ASSERT_GT(v.silhouette.at<uchar>(neck_row, static_cast<int>(std::lround(v.landmarks[8].x()))), 0)
      << "the shoulders must join the head through the neck for the test to prove anything";
  cv::Mat with_shoulders = v.silhouette.clone();
  with_shoulders.rowRange(neck_row, size).setTo(255);
  const MatteRules rules;
  const cv::Mat bound = MatteBound(with_shoulders, v.landmarks, rules);
  const cv::Point left(1, size - 2), right(size - 2, size - 2);  // beyond the jaw's ends
  EXPECT_EQ(bound.at<uchar>(left), 0);
  EXPECT_EQ(bound.at<uchar>(right), 0);
  // The cut alone leaves them (what the bound was before the head's piece was kept).
  cv::Mat cut = MaskReach(with_shoulders, v.landmarks, static_cast<int>(std::lround(rules.hair_margin * size)),
                          static_cast<int>(std::lround(rules.side_margin * size)));
  ClearBelowJawLine(v.landmarks, &cut);
  EXPECT_EQ(cut.at<uchar>(left), 255);
  EXPECT_EQ(cut.at<uchar>(right), 255);
  // Every pixel of the head's bound without shoulders is still in it.
  const cv::Mat head = MatteBound(v.silhouette, v.landmarks, rules);
  EXPECT_EQ(cv::countNonZero(head & ~bound), 0);
  EXPECT_GT(cv::countNonZero(head), size * size / 8);
  // With the neck kept the shoulders are joined to the head, and stay.
  const cv::Mat with_neck = MatteBound(with_shoulders, v.landmarks, MatteRules{0.08, 0.02, true});
  EXPECT_EQ(with_neck.at<uchar>(left), 255);
  // A mask without the nose tip is left alone.
  cv::Mat empty(size, size, CV_8U, cv::Scalar(0)), patch = empty.clone();
  patch(cv::Rect(0, 0, 10, 10)).setTo(255);
  KeepHeadPiece(v.landmarks, &patch);
  EXPECT_EQ(cv::countNonZero(patch), 100);
}

// A learned matte added to an avatar without one starts from its picture; a
// bounded one shows exactly the background outside the bound, and the bound is
// the one the mask rules give for the frame.
TEST(Matte, StartsAsThePictureWithoutAndBoundedPixelsAreBackground) {
  const HeadModel& m = Builtin();
  Avatar plain = Avatar::CreateRandom(testing::TinyAvatarConfig(), m, DefaultSubject(m, 128), 5);
  Avatar learned = plain.WithRuntimeSwitches(TinyWithMatte(MatteMode::kLearned));
  Avatar bounded = plain.WithRuntimeSwitches(TinyWithMatte(MatteMode::kBounded));
  const FrameParams frame = Turned();
  AvatarFrameInputs b0, b1, b2;
  const cv::Mat without = Shown(plain, frame, &b0);
  EXPECT_LE(cv::norm(without, Shown(learned, frame, &b1), cv::NORM_INF), 1) << "a new matte covers everything";
  EXPECT_TRUE(b1.matte_bound.empty());
  const cv::Mat shown = Shown(bounded, frame, &b2);
  ASSERT_FALSE(b2.matte_bound.empty());
  const PosedView v = View(frame, 128);
  EXPECT_EQ(cv::countNonZero(b2.matte_bound != MatteBound(v.silhouette, v.landmarks, MatteRules{})), 0);
  int outside = 0, inside_same = 0, inside = 0;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x) {
      if (b2.matte_bound.at<uchar>(y, x) == 0) {
        ++outside;
        EXPECT_EQ(shown.at<cv::Vec3b>(y, x), BackgroundBgr()) << "at " << x << "," << y;
      } else {
        ++inside;
        inside_same += cv::norm(shown.at<cv::Vec3b>(y, x), without.at<cv::Vec3b>(y, x), cv::NORM_INF) <= 1;
      }
    }
  EXPECT_GT(outside, 1000);
  EXPECT_EQ(inside_same, inside) << "inside the bound the picture is the one without a matte";
  // The bound is the mesh's: a texture shell beyond it changes nothing there.
  AvatarConfig shelled = TinyWithMatte(MatteMode::kBounded);
  shelled.surface_features = 4;
  shelled.surface_resolution = 32;
  shelled.surface_shell = 0.03;
  Avatar with_shell = plain.WithRuntimeSwitches(shelled);
  AvatarFrameInputs b3;
  Shown(with_shell, frame, &b3);
  EXPECT_GT(b3.surface.num_pixels(), b3.surface.mesh_pixels);
  EXPECT_EQ(cv::countNonZero(b3.matte_bound != b2.matte_bound), 0);
}

// A core (the silhouette eroded, inside the bound) shows the renderer's RGB
// whatever the coverage says; the rest of the bound follows the coverage.
TEST(Matte, ACoreIsCoveredWhateverTheCoverageSays) {
  const HeadModel& m = Builtin();
  Avatar plain = Avatar::CreateRandom(testing::TinyAvatarConfig(), m, DefaultSubject(m, 128), 5);
  AvatarConfig config = TinyWithMatte(MatteMode::kBounded);
  config.matte_core = 0.02;
  Avatar cored = plain.WithRuntimeSwitches(config);
  {
    torch::NoGradGuard no_grad;  // a coverage of nothing
    for (auto& p : cored.modules().renderer->named_parameters())
      if (p.key() == "input_alpha.bias") p.value().fill_(-20);
  }
  const FrameParams frame = Turned();
  AvatarFrameInputs b0, b1;
  const cv::Mat without = Shown(plain, frame, &b0), shown = Shown(cored, frame, &b1);
  ASSERT_FALSE(b1.matte_core.empty());
  const PosedView v = View(frame, 128);
  const cv::Mat bound = MatteBound(v.silhouette, v.landmarks, MatteRules{});
  EXPECT_EQ(cv::countNonZero(b1.matte_core != MatteCore(v.silhouette, bound, 0.02)), 0);
  int core = 0, rest = 0;
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x) {
      if (b1.matte_core.at<uchar>(y, x)) {
        ++core;
        EXPECT_EQ(shown.at<cv::Vec3b>(y, x), without.at<cv::Vec3b>(y, x)) << "at " << x << "," << y;
      } else {
        rest += shown.at<cv::Vec3b>(y, x) == BackgroundBgr();
      }
    }
  EXPECT_GT(core, 1000);
  EXPECT_EQ(rest, 128 * 128 - core) << "outside the core, a coverage of nothing shows the background";
  // The core lies inside the silhouette, at least the erosion away from its edge.
  EXPECT_EQ(cv::countNonZero(b1.matte_core & ~v.silhouette), 0);
  EXPECT_LT(core, cv::countNonZero(v.silhouette & bound));
}

// The coverage learns a mask: every matte weight gets a gradient, and a few
// steps on the cross-entropy take the coverage from everywhere towards the
// head's silhouette (lower loss, more inside than outside).
TEST(Matte, CoverageLearnsTheMask) {
  const HeadModel& m = Builtin();
  Avatar a = Avatar::CreateRandom(TinyWithMatte(MatteMode::kLearned), m, DefaultSubject(m, 128), 6);
  a.modules().train();
  AvatarFrameInputs inputs;
  RaySampler sampler(a.config());
  PrepareAvatarFrame(a.config(), m, m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape())), a.subject(), Turned(),
                     &sampler, nullptr, &inputs);
  cv::Mat head = View(Turned(), 128).silhouette;
  const torch::Tensor mask = torch::from_blob(head.data, {1, 1, 128, 128}, torch::kUInt8).gt(0).to(torch::kFloat);
  torch::optim::Adam adam(a.modules().parameters(), torch::optim::AdamOptions(1e-2));
  auto loss = [&] {
    return torch::binary_cross_entropy(RunAvatar(a.modules(), inputs).coverage.clamp(1e-5, 1 - 1e-5), mask);
  };
  const torch::Tensor first_loss = loss();
  first_loss.backward();
  for (const auto& p : a.modules().renderer->named_parameters()) {
    if (p.key().find("alpha") != std::string::npos) {
      EXPECT_GT(p.value().grad().abs().max().item<float>(), 0.f) << p.key();
    }
  }
  const float first = first_loss.item<float>();
  for (int step = 0; step < 120; ++step) {
    adam.zero_grad();
    loss().backward();
    adam.step();
  }
  const float last = loss().item<float>();
  EXPECT_LT(last, 0.5f * first) << first << " -> " << last;
  torch::NoGradGuard no_grad;
  const torch::Tensor c = RunAvatar(a.modules(), inputs).coverage;
  const float inside = (c * mask).sum().item<float>() / mask.sum().item<float>();
  const float outside = (c * (1 - mask)).sum().item<float>() / (1 - mask).sum().item<float>();
  EXPECT_GT(inside, 0.8f);
  EXPECT_LT(outside, 0.2f);
}

// The coverage is drawn as sigmoid(scale x logit): at 1 the picture it drew
// before the scale existed, below 1 each pixel's coverage nearer a half by
// exactly that; the file keeps the scale, files from before it draw at 1, and
// a scale out of range or not a number is refused.
TEST(Matte, TheScaleSoftensTheCoverageByItsLogit) {
  const HeadModel& m = Builtin();
  Avatar a = Avatar::CreateRandom(TinyWithMatte(MatteMode::kLearned), m, DefaultSubject(m, 128), 8);
  {
    torch::NoGradGuard no_grad;  // a coverage that varies over the picture, not the new matte's constant
    for (auto& p : a.modules().renderer->named_parameters())
      if (p.key().find("alpha") != std::string::npos) p.value().copy_(0.5 * torch::randn_like(p.value()));
  }
  AvatarConfig half = a.config();
  half.matte_scale = 0.5;
  Avatar soft = a.WithRuntimeSwitches(half);
  auto coverage = [&](Avatar& avatar) {
    avatar.modules().eval();
    torch::NoGradGuard no_grad;
    AvatarFrameInputs inputs;
    RaySampler sampler(avatar.config());
    PrepareAvatarFrame(avatar.config(), m, m.MakeIdentity(Eigen::VectorXd::Zero(m.num_shape())), avatar.subject(),
                       Turned(), &sampler, nullptr, &inputs);
    return RunAvatar(avatar.modules(), inputs).coverage.clone();
  };
  const torch::Tensor sharp = coverage(a), softer = coverage(soft);
  const torch::Tensor within = sharp.gt(0.01) & sharp.lt(0.99);
  ASSERT_GT(within.sum().item<int64_t>(), 1000) << "the coverage should vary over the picture";
  const torch::Tensor expected = torch::sigmoid(0.5 * torch::logit(sharp));
  EXPECT_LT(((softer - expected) * within).abs().max().item<float>(), 1e-4);
  EXPECT_LT(((softer - 0.5).abs() - (sharp - 0.5).abs()).max().item<float>(), 1e-6) << "never further from a half";
  EXPECT_GT((softer - sharp).abs().max().item<float>(), 0.05f);
  // The file keeps it; a file from before it draws at 1.
  const std::string dir = testing::TempDir("matte_scale");
  soft.Save(dir + "/s.hcavatar");
  EXPECT_EQ(Avatar::Load(dir + "/s.hcavatar", m).config().matte_scale, 0.5);
  ZipEntries entries = ReadZip(dir + "/s.hcavatar");
  nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
  manifest["config"].erase("matte_scale");
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/old.hcavatar", entries);
  EXPECT_EQ(Avatar::Load(dir + "/old.hcavatar", m).config().matte_scale, 1);
  for (double bad : {0.0, -1.0, 10.0, std::nan("")}) {
    manifest["config"]["matte_scale"] = bad;
    entries["manifest.json"] = manifest.dump();
    WriteZip(dir + "/bad.hcavatar", entries);
    EXPECT_THROW(Avatar::Load(dir + "/bad.hcavatar", m), std::runtime_error) << bad;
  }
}

TEST(Matte, TheFileKeepsItAndOldFilesHaveNone) {
  const HeadModel& m = Builtin();
  const std::string dir = testing::TempDir("matte");
  AvatarConfig config = TinyWithMatte(MatteMode::kBounded);
  config.matte_rules = MatteRules{0.1, 0.03, false};
  Avatar a = Avatar::CreateRandom(config, m, DefaultSubject(m, 128), 7);
  {
    torch::NoGradGuard no_grad;
    for (auto& t : a.modules().renderer->parameters()) t.add_(0.05 * torch::randn_like(t));
  }
  const std::string path = dir + "/m.hcavatar";
  a.Save(path);
  Avatar back = Avatar::Load(path, m);
  EXPECT_EQ(back.config().ToJson(), config.ToJson());
  AvatarFrameInputs b0, b1, b2;
  const cv::Mat y = Shown(back, Turned(), &b0);
  EXPECT_EQ(cv::norm(Shown(a, Turned(), &b1), y, cv::NORM_INF), 0) << "the loaded matte draws what the saved one did";
  EXPECT_EQ(cv::norm(y, Shown(back, Turned(), &b2), cv::NORM_INF), 0) << "deterministic";
  // A manifest that promises a matte the weights do not hold is refused.
  Avatar plain = Avatar::CreateRandom(testing::TinyAvatarConfig(), m, DefaultSubject(m, 128), 7);
  plain.Save(dir + "/p.hcavatar");
  ZipEntries entries = ReadZip(dir + "/p.hcavatar");
  nlohmann::json manifest = nlohmann::json::parse(entries["manifest.json"]);
  manifest["config"]["matte"] = "learned";
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/lying.hcavatar", entries);
  EXPECT_THROW(Avatar::Load(dir + "/lying.hcavatar", m), std::runtime_error);
  manifest["config"]["matte"] = "sharp";
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/foreign.hcavatar", entries);
  EXPECT_THROW(Avatar::Load(dir + "/foreign.hcavatar", m), std::runtime_error);
  // Files from before the matte (no such keys) load without one.
  manifest["config"].erase("matte");
  manifest["config"].erase("matte_rules");
  entries["manifest.json"] = manifest.dump();
  WriteZip(dir + "/old.hcavatar", entries);
  EXPECT_FALSE(Avatar::Load(dir + "/old.hcavatar", m).config().has_matte());
}

}  // namespace headcast
