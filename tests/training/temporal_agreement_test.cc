// Frame-to-frame agreement of an avatar's pictures with the true frames'.
#include "training/temporal_agreement.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace headcast {
namespace {

// A dark disc at x on a mid-grey picture, lifted by `tint` grey levels.
cv::Mat Disc(double x, int tint = 0) {
  cv::Mat m(64, 96, CV_8UC3, cv::Scalar::all(128 + tint));
  cv::circle(m, cv::Point2d(x, 32), 12, cv::Scalar::all(40 + tint), cv::FILLED, cv::LINE_AA, 0);
  return m;
}

double ChangePsnr(const TemporalAgreement& t) { return t.Summary().at("change_psnr_db").get<double>(); }
double MotionRatio(const TemporalAgreement& t) { return t.Summary().at("motion_ratio").get<double>(); }

}  // namespace

TEST(TemporalAgreement, ASteadyErrorCancelsAJitterDoesNot) {
  TemporalAgreement same, tinted, jittery, frozen;
  for (int n = 0; n < 20; ++n) {
    const cv::Mat truth = Disc(30 + n);
    same.Add(n, truth, truth);
    tinted.Add(n, truth, Disc(30 + n, 20));                  // every frame off by the same colour
    jittery.Add(n, truth, Disc(30 + n + (n % 2 ? 2 : -2)));  // around the truth, 2 px either way
    frozen.Add(n, truth, Disc(30));                          // the first frame held
  }
  EXPECT_EQ(same.pairs(), 19);
  EXPECT_GT(ChangePsnr(same), 100);
  EXPECT_NEAR(MotionRatio(same), 1.0, 1e-9);
  // The tint is in both pictures of a pair: the change is the truth's.
  EXPECT_GT(ChangePsnr(tinted), 100);
  EXPECT_NEAR(MotionRatio(tinted), 1.0, 1e-6);
  // The jitter moves the disc 4-5 px a frame where the truth moves it 1.
  EXPECT_LT(ChangePsnr(jittery), ChangePsnr(same) - 60);
  EXPECT_GT(MotionRatio(jittery), 1.5);
  EXPECT_EQ(MotionRatio(frozen), 0.0);
  EXPECT_LT(ChangePsnr(frozen), 40);
}

TEST(TemporalAgreement, OnlyFollowingFramesMakePairs) {
  TemporalAgreement t;
  EXPECT_TRUE(t.Summary().at("change_psnr_db").is_null());
  t.Add(5, Disc(30), Disc(30));
  t.Add(7, Disc(32), Disc(32));  // a gap: no pair
  EXPECT_EQ(t.pairs(), 0);
  EXPECT_TRUE(t.Summary().at("motion_ratio").is_null());
  t.Add(8, Disc(33), Disc(33));
  EXPECT_EQ(t.pairs(), 1);
  EXPECT_THROW(t.Add(9, Disc(34), cv::Mat(32, 32, CV_8UC3)), std::invalid_argument);
  EXPECT_THROW(t.Add(9, Disc(34), cv::Mat(64, 96, CV_32FC3)), std::invalid_argument);
  EXPECT_EQ(t.pairs(), 1);
}

}  // namespace headcast
