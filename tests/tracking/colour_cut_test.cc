// The cut with carried colour models, and their learning, against
// cv::grabCut's own of the same energy, on renders of the built-in head over
// clutter.
#include "common/tracking/colour_cut.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "common/core/timer.h"
#include "tests/testing/resting_head_scenes.h"

namespace headcast {
namespace {

using testing::RestingHeadScenes;

// Seeds around a known mask: its inside certain, a band either side of its
// edge undecided, the rest certain background.
cv::Mat SeedsAround(const cv::Mat& mask) {
  cv::Mat inner, outer;
  const auto disc = [](int r) { return cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)); };
  cv::erode(mask, inner, disc(20));
  cv::dilate(mask, outer, disc(30));
  cv::Mat labels(mask.size(), CV_8U, cv::Scalar(cv::GC_BGD));
  labels.setTo(cv::GC_PR_BGD, outer);
  labels.setTo(cv::GC_PR_FGD, mask);
  labels.setTo(cv::GC_FGD, inner);
  return labels;
}

struct Models {
  cv::Mat background, foreground;
};

Models Learn(const cv::Mat& image, const cv::Mat& mask) {
  Models m;
  cv::Mat labels = SeedsAround(mask);
  cv::grabCut(image, labels, cv::Rect(), m.background, m.foreground, 3, cv::GC_INIT_WITH_MASK);
  return m;
}

int Differing(const cv::Mat& a, const cv::Mat& b) { return cv::countNonZero(a != b); }

TEST(ColourCut, CutsAsGrabCutsFrozenModelCut) {
  const RestingHeadScenes scenes(13);
  const RestingHeadScenes::Scene first = scenes.At(0.7, -6, 0);
  const Models models = Learn(first.image, first.mask);
  double ours_ms = 0, theirs_ms = 0;
  for (double yaw : {-3.0, 0.0, 4.0, 9.0}) {
    const RestingHeadScenes::Scene s = scenes.At(0.7, yaw, 5);
    const cv::Mat seeds = SeedsAround(s.mask);
    cv::Mat ours = seeds.clone(), theirs = seeds.clone();
    Stopwatch watch;
    CutWithColourModels(s.image, ours, models.background, models.foreground);
    ours_ms += watch.ElapsedMs();
    cv::Mat bgd = models.background.clone(), fgd = models.foreground.clone();
    watch.Restart();
    cv::grabCut(s.image, theirs, cv::Rect(), bgd, fgd, 1, cv::GC_EVAL_FREEZE_MODEL);
    theirs_ms += watch.ElapsedMs();
    const int undecided = cv::countNonZero(seeds == cv::GC_PR_BGD) + cv::countNonZero(seeds == cv::GC_PR_FGD);
    const int differ = Differing(ours, theirs);
    const cv::Mat head = (ours == cv::GC_PR_FGD) | (ours == cv::GC_FGD);
    std::printf("yaw %+.0f: %d of %d undecided pixels differ from cv::grabCut's; IoU with the truth %.4f\n", yaw,
                differ, undecided, cv::countNonZero(head & s.mask) * 1.0 / cv::countNonZero(head | s.mask));
    // The same energy cut: ties only (the mixtures' sums taken in another order).
    EXPECT_LE(differ, undecided / 500) << "yaw " << yaw;
    EXPECT_EQ(Differing(ours == cv::GC_FGD, seeds == cv::GC_FGD), 0) << "certain pixels stay";
    EXPECT_EQ(Differing(ours == cv::GC_BGD, seeds == cv::GC_BGD), 0) << "certain pixels stay";
  }
  std::printf("four cuts: %.1f ms here, %.1f ms by cv::grabCut\n", ours_ms, theirs_ms);
}

TEST(ColourCut, LearnsAsGrabCutLearns) {
  const RestingHeadScenes scenes(13);
  double ours_ms = 0, theirs_ms = 0;
  for (double yaw : {-8.0, 0.0, 7.0}) {
    const RestingHeadScenes::Scene s = scenes.At(0.7, yaw, -4);
    const cv::Mat seeds = SeedsAround(s.mask);
    cv::Mat ours = seeds.clone(), theirs = seeds.clone();
    cv::Mat our_back, our_head, their_back, their_head;
    cv::theRNG().state = 7;  // k-means++ draws its first centres from it
    Stopwatch watch;
    LearnColourModels(s.image, ours, 3, &our_back, &our_head);
    ours_ms += watch.ElapsedMs();
    cv::theRNG().state = 7;
    watch.Restart();
    cv::grabCut(s.image, theirs, cv::Rect(), their_back, their_head, 3, cv::GC_INIT_WITH_MASK);
    theirs_ms += watch.ElapsedMs();
    const int undecided = cv::countNonZero(seeds == cv::GC_PR_BGD) + cv::countNonZero(seeds == cv::GC_PR_FGD);
    const int differ = Differing(ours, theirs);
    std::printf("yaw %+.0f: %d of %d undecided pixels differ; models differ by %.2g (weights, means, covariances)\n",
                yaw, differ, undecided,
                std::max(cv::norm(our_back, their_back, cv::NORM_INF), cv::norm(our_head, their_head, cv::NORM_INF)));
    EXPECT_LE(differ, undecided / 500) << "yaw " << yaw;
    // The models cut the next frame as cv::grabCut's own do.
    const RestingHeadScenes::Scene next = scenes.At(0.7, yaw + 2, -4);
    cv::Mat with_ours = SeedsAround(next.mask), with_theirs = with_ours.clone();
    CutWithColourModels(next.image, with_ours, our_back, our_head);
    CutWithColourModels(next.image, with_theirs, their_back, their_head);
    EXPECT_LE(Differing(with_ours, with_theirs), undecided / 500) << "yaw " << yaw;
  }
  std::printf("three learnings: %.1f ms here, %.1f ms by cv::grabCut\n", ours_ms, theirs_ms);
  cv::Mat labels(8, 8, CV_8U, cv::Scalar(cv::GC_BGD)), back, head;
  labels.at<uchar>(4, 4) = cv::GC_FGD;  // one head pixel: too few for five components
  EXPECT_THROW(LearnColourModels(cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)), labels, 1, &back, &head),
               std::invalid_argument);
  EXPECT_THROW(LearnColourModels(cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)), labels, 0, &back, &head),
               std::invalid_argument);
}

// A learner that keeps only the models leaves out the last round's cut: the
// same models, the labels of the round before.
TEST(ColourCut, LearningWithoutTheLastCutLearnsTheSameModels) {
  const RestingHeadScenes scenes(13);
  const RestingHeadScenes::Scene s = scenes.At(0.7, 4, -4);
  const cv::Mat seeds = SeedsAround(s.mask);
  cv::Mat cut_last = seeds.clone(), not_cut = seeds.clone(), two_rounds = seeds.clone();
  cv::Mat back[3], head[3];
  cv::theRNG().state = 7;
  LearnColourModels(s.image, cut_last, 3, &back[0], &head[0]);
  cv::theRNG().state = 7;
  LearnColourModels(s.image, not_cut, 3, &back[1], &head[1], false);
  cv::theRNG().state = 7;
  LearnColourModels(s.image, two_rounds, 2, &back[2], &head[2]);
  EXPECT_EQ(cv::norm(back[0], back[1], cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(head[0], head[1], cv::NORM_INF), 0.0);
  EXPECT_EQ(Differing(not_cut, two_rounds), 0);
  EXPECT_GT(cv::norm(head[0], head[2], cv::NORM_INF), 0.0);  // the third round did refit
}

TEST(ColourCut, WithoutUndecidedPixelsNothingChanges) {
  const RestingHeadScenes scenes(13);
  const RestingHeadScenes::Scene s = scenes.At(0.7, 0, 0);
  const Models models = Learn(s.image, s.mask);
  cv::Mat labels(s.mask.size(), CV_8U, cv::Scalar(cv::GC_BGD));
  labels.setTo(cv::GC_FGD, s.mask);
  const cv::Mat before = labels.clone();
  CutWithColourModels(s.image, labels, models.background, models.foreground);
  EXPECT_EQ(Differing(labels, before), 0);
  // One undecided pixel alone among certain ones: decided by its colour and its neighbours.
  labels.at<uchar>(0, 0) = cv::GC_PR_FGD;
  CutWithColourModels(s.image, labels, models.background, models.foreground);
  EXPECT_EQ(labels.at<uchar>(0, 0), cv::GC_PR_BGD);
}

TEST(ColourCut, BadInputIsRefused) {
  const RestingHeadScenes scenes(13);
  const RestingHeadScenes::Scene s = scenes.At(0.7, 0, 0);
  const Models models = Learn(s.image, s.mask);
  cv::Mat labels = SeedsAround(s.mask);
  auto cut = [&](const cv::Mat& image, cv::Mat l, const cv::Mat& b, const cv::Mat& f) {
    CutWithColourModels(image, l, b, f);
  };
  EXPECT_THROW(cut(cv::Mat(), labels, models.background, models.foreground), std::invalid_argument);
  EXPECT_THROW(cut(s.image, labels.rowRange(0, 10).clone(), models.background, models.foreground),
               std::invalid_argument);
  cv::Mat wrong_label = labels.clone();
  wrong_label.at<uchar>(3, 3) = 7;
  EXPECT_THROW(cut(s.image, wrong_label, models.background, models.foreground), std::invalid_argument);
  EXPECT_THROW(cut(s.image, labels, cv::Mat(1, 64, CV_64F, cv::Scalar(0)), models.foreground), std::invalid_argument);
  cv::Mat not_a_distribution = models.foreground.clone();
  not_a_distribution.at<double>(0) += 0.5;
  EXPECT_THROW(cut(s.image, labels, models.background, not_a_distribution), std::invalid_argument);
  cv::Mat nan_mean = models.foreground.clone();
  nan_mean.at<double>(5) = NAN;
  EXPECT_THROW(cut(s.image, labels, models.background, nan_mean), std::invalid_argument);
  cv::Mat singular = models.background.clone();
  for (int k = 0; k < 5; ++k)
    for (int i = 0; i < 9; ++i) singular.at<double>(20 + 9 * k + i) = 0;
  EXPECT_THROW(cut(s.image, labels, singular, models.foreground), std::invalid_argument);
}

}  // namespace
}  // namespace headcast
