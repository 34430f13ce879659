#include "training/expression_balance.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "common/core/median.h"
#include "common/core/options.h"

namespace headcast {

void RareExpressionOptions::Check() const {
  OptionsCheck c("RareExpressionOptions");
  c.InRange("strength", strength, 0.0, 4.0).InRange("neighbours", neighbours, 1, 1000).InRange("cap", cap, 1.0, 100.0);
  c.ThrowIfErrors();
}

std::vector<double> RareExpressionWeights(const std::vector<Eigen::VectorXf>& expressions,
                                          const RareExpressionOptions& o) {
  o.Check();
  const size_t n = expressions.size();
  std::vector<double> w(n, 1.0);
  if (n < 2 || o.strength == 0) return w;
  for (const Eigen::VectorXf& e : expressions)
    if (e.size() != expressions[0].size() || !e.allFinite())
      throw std::invalid_argument("RareExpressionWeights: expressions of different sizes or not finite");
  const size_t k = std::min<size_t>(static_cast<size_t>(o.neighbours), n - 1);
  std::vector<double> isolation(n), row(n);
  for (size_t i = 0; i < n; ++i) {
    row.clear();
    for (size_t j = 0; j < n; ++j)
      if (j != i) row.push_back((expressions[i] - expressions[j]).cast<double>().norm());
    std::nth_element(row.begin(), row.begin() + static_cast<std::ptrdiff_t>(k - 1), row.end());
    isolation[i] = row[k - 1];
  }
  const double median = Median(isolation);
  if (!(median > 0)) return w;  // most frames repeat one expression exactly: nothing to weigh by
  double sum = 0;
  for (size_t i = 0; i < n; ++i) {
    w[i] = std::clamp(std::pow(isolation[i] / median, o.strength), 1 / o.cap, o.cap);
    sum += w[i];
  }
  for (double& x : w) x *= static_cast<double>(n) / sum;
  return w;
}

ExpressionDirections PrincipalExpressions(const std::vector<Eigen::VectorXf>& expressions, int count) {
  if (expressions.empty()) throw std::invalid_argument("PrincipalExpressions: no expressions");
  const Eigen::Index e = expressions.front().size();
  if (count < 1 || count > e)
    throw std::invalid_argument("PrincipalExpressions: count must be in [1, " + std::to_string(e) + "]");
  Eigen::MatrixXd x(static_cast<Eigen::Index>(expressions.size()), e);
  for (size_t i = 0; i < expressions.size(); ++i) {
    if (expressions[i].size() != e) throw std::invalid_argument("PrincipalExpressions: expressions of different sizes");
    x.row(static_cast<Eigen::Index>(i)) = expressions[i].cast<double>().transpose();
  }
  const Eigen::RowVectorXd mean = x.colwise().mean();
  x.rowwise() -= mean;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(x.transpose() * x);
  const Eigen::VectorXd& variance = solver.eigenvalues();  // rising
  ExpressionDirections d;
  d.mean = mean.transpose().cast<float>();
  d.directions.resize(count, e);
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd v = solver.eigenvectors().col(e - 1 - k);
    Eigen::Index largest;
    v.cwiseAbs().maxCoeff(&largest);
    if (v(largest) < 0) v = -v;
    d.directions.row(k) = v.transpose().cast<float>();
  }
  const Eigen::MatrixXf projections = x.cast<float>() * d.directions.transpose();  // N x count
  d.low = projections.colwise().minCoeff().transpose();
  d.high = projections.colwise().maxCoeff().transpose();
  const double total = variance.sum();
  d.explained = total > 0 ? variance.tail(count).sum() / total : 1;
  return d;
}

}  // namespace headcast
