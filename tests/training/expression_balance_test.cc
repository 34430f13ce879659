// Sampling weights that favour rare expressions.
#include "training/expression_balance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <random>

namespace headcast {
namespace {

// A resting face with small variations, and a few frames of one wide blink.
std::vector<Eigen::VectorXf> RestingFaceAndBlinks(int resting, int blinks) {
  std::mt19937 rng(4);
  std::normal_distribution<float> jitter(0, 0.03f);
  std::vector<Eigen::VectorXf> e;
  for (int i = 0; i < resting + blinks; ++i) {
    Eigen::VectorXf x(6);
    for (int k = 0; k < 6; ++k) x[k] = 0.2f + jitter(rng);
    if (i >= resting) x[0] = 0.95f + jitter(rng);  // eyeBlink far from the rest
    e.push_back(x);
  }
  return e;
}

TEST(RareExpressionWeights, DrawsTheRareFramesMoreOftenWithinTheCap) {
  const std::vector<Eigen::VectorXf> e = RestingFaceAndBlinks(200, 10);
  RareExpressionOptions o;
  o.strength = 1;
  const std::vector<double> w = RareExpressionWeights(e, o);
  ASSERT_EQ(w.size(), e.size());
  EXPECT_NEAR(std::accumulate(w.begin(), w.end(), 0.0) / w.size(), 1.0, 1e-9);
  double resting = 0, blinks = 0;
  for (int i = 0; i < 200; ++i) resting += w[i] / 200;
  for (int i = 200; i < 210; ++i) blinks += w[i] / 10;
  std::printf("mean weight: resting %.3f, blinks %.3f\n", resting, blinks);
  EXPECT_GT(blinks, 1.5 * resting);  // ten blink frames are sparser than two hundred resting ones
  const double lo = *std::min_element(w.begin(), w.end()), hi = *std::max_element(w.begin(), w.end());
  EXPECT_LE(hi / lo, o.cap * o.cap + 1e-9);
  // A lone outlier is held at the cap against the median frame.
  std::vector<Eigen::VectorXf> with_outlier = e;
  with_outlier.push_back(Eigen::VectorXf::Constant(6, 5.0f));
  const std::vector<double> wo = RareExpressionWeights(with_outlier, o);
  std::vector<double> sorted = wo;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_NEAR(wo.back() / sorted[sorted.size() / 2], o.cap, 1e-6);
}

TEST(RareExpressionWeights, OffOrDegenerateGivesEveryFrameTheSameWeight) {
  const std::vector<Eigen::VectorXf> e = RestingFaceAndBlinks(50, 5);
  for (double x : RareExpressionWeights(e, RareExpressionOptions{})) EXPECT_EQ(x, 1.0);  // strength 0
  RareExpressionOptions o;
  o.strength = 2;
  for (double x : RareExpressionWeights(std::vector<Eigen::VectorXf>(20, Eigen::VectorXf::Zero(6)), o))
    EXPECT_EQ(x, 1.0);  // one expression repeated
  EXPECT_EQ(RareExpressionWeights({Eigen::VectorXf::Zero(6)}, o), std::vector<double>{1.0});
}

TEST(RareExpressionWeights, RefusesBadInput) {
  RareExpressionOptions o;
  o.strength = 1;
  std::vector<Eigen::VectorXf> e = RestingFaceAndBlinks(10, 0);
  e[3][2] = NAN;
  EXPECT_THROW(RareExpressionWeights(e, o), std::invalid_argument);
  e[3] = Eigen::VectorXf::Zero(4);
  EXPECT_THROW(RareExpressionWeights(e, o), std::invalid_argument);
  o.strength = -1;
  EXPECT_THROW(RareExpressionWeights(RestingFaceAndBlinks(10, 0), o), std::invalid_argument);
  o.strength = 1;
  o.cap = 0.5;
  EXPECT_THROW(RareExpressionWeights(RestingFaceAndBlinks(10, 0), o), std::invalid_argument);
}

// Expressions that vary along two known directions (one three times the
// other) and a little noise: the directions come back first and second, with
// their signs set, nearly all the variance, and the projections' range.
TEST(PrincipalExpressions, FindsTheDirectionsTheFramesVaryAlong) {
  std::mt19937 rng(7);
  std::normal_distribution<float> unit(0, 1), noise(0, 0.01f);
  Eigen::VectorXf base(5), u(5), v(5);
  base << 0.2f, 0.1f, 0.3f, 0.05f, 0.4f;
  u << 0.6f, -0.8f, 0, 0, 0;  // largest entry negative: returned as -u
  v << 0, 0, 0.6f, 0.8f, 0;
  std::vector<Eigen::VectorXf> e;
  for (int i = 0; i < 400; ++i) {
    Eigen::VectorXf x = base + 0.3f * unit(rng) * u + 0.1f * unit(rng) * v;
    for (int k = 0; k < 5; ++k) x[k] += noise(rng);
    e.push_back(x);
  }
  const ExpressionDirections d = PrincipalExpressions(e, 2);
  ASSERT_EQ(d.directions.rows(), 2);
  ASSERT_EQ(d.directions.cols(), 5);
  EXPECT_GT(d.directions.row(0).dot(-u), 0.999f);
  EXPECT_GT(d.directions.row(1).dot(v), 0.999f);
  EXPECT_NEAR(d.directions.row(0).norm(), 1, 1e-5);
  EXPECT_LT((d.mean - base).cwiseAbs().maxCoeff(), 0.05f);
  EXPECT_GT(d.explained, 0.98);
  EXPECT_LT(d.explained, 1);
  float low = 1e9f, high = -1e9f;
  for (const Eigen::VectorXf& x : e) {
    const float p = d.directions.row(0).dot(x - d.mean);
    low = std::min(low, p);
    high = std::max(high, p);
  }
  EXPECT_NEAR(d.low[0], low, 1e-4);
  EXPECT_NEAR(d.high[0], high, 1e-4);
  EXPECT_LT(d.low[0], -0.5f);
  EXPECT_GT(d.high[0], 0.5f);
  EXPECT_NEAR(PrincipalExpressions(e, 5).explained, 1, 1e-9);
  EXPECT_THROW(PrincipalExpressions({}, 1), std::invalid_argument);
  EXPECT_THROW(PrincipalExpressions(e, 0), std::invalid_argument);
  EXPECT_THROW(PrincipalExpressions(e, 6), std::invalid_argument);
  e.push_back(Eigen::VectorXf::Zero(4));
  EXPECT_THROW(PrincipalExpressions(e, 1), std::invalid_argument) << "an expression of another size";
}

}  // namespace
}  // namespace headcast
