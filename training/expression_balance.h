// How often each training frame is drawn. A talking-head video is mostly
// the person's resting face; blinks, wide eyes, frowns and open mouths are a
// few frames each, and drawn uniformly they teach the networks little — yet
// held-out frames are judged on exactly those.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace headcast {

struct RareExpressionOptions {
  // Exponent of the weight on a frame's isolation (0: every frame alike).
  double strength = 0;
  int neighbours = 8;  // isolation: the distance to this nearest other frame's expression
  double cap = 4;      // no frame is drawn more than cap times (nor less than 1/cap times) the median frame
  void Check() const;
};

// One weight per expression (mean 1): (d_i / median d)^strength, clamped to
// [1/cap, cap], where d_i is the Euclidean distance from expression i to its
// `neighbours`-th nearest other one. Expressions alike in size (ICT's 0..1
// coefficients, FLAME's unit-variance ones) need no scaling. Fewer than two
// expressions, or strength 0: all ones.
std::vector<double> RareExpressionWeights(const std::vector<Eigen::VectorXf>& expressions,
                                          const RareExpressionOptions& options);

// The directions a set of expressions varies along most: their mean, the
// first `count` principal directions (unit rows, by falling variance, each
// signed so its largest entry is positive) and the range of the expressions'
// projections on each. Throws for no expressions, sizes that differ, or
// count outside [1, the coefficients].
struct ExpressionDirections {
  Eigen::VectorXf mean;
  Eigen::MatrixXf directions;  // count x E
  Eigen::VectorXf low, high;   // count
  double explained = 0;        // the fraction of the expressions' variance along them
};
ExpressionDirections PrincipalExpressions(const std::vector<Eigen::VectorXf>& expressions, int count);

}  // namespace headcast
