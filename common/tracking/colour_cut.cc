// One graph cut of GrabCut's energy over the undecided pixels only.
#include "common/tracking/colour_cut.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <opencv2/imgproc/detail/gcgraph.hpp>
#include <stdexcept>
#include <string>
#include <vector>

namespace headcast {
namespace {

constexpr int kComponents = 5;  // cv::grabCut's mixtures
// The smoothness weight of cv::grabCut (its gamma): what two like-coloured
// neighbours pay to be split; diagonal neighbours pay it over their distance.
constexpr float kGamma = 50;

// A Gaussian mixture over BGR colours, for its negative log-likelihood.
class Mixture {
 public:
  Mixture(const cv::Mat& model, const char* name) {
    auto refuse = [&](const std::string& why) {
      throw std::invalid_argument(std::string("CutWithColourModels: the ") + name + " model " + why);
    };
    if (model.type() != CV_64F || model.total() != 13 * kComponents || !model.isContinuous())
      refuse("is not cv::grabCut's 1x65 CV_64F layout");
    const double* weights = model.ptr<double>();
    const double* means = weights + kComponents;
    const double* covs = means + 3 * kComponents;
    double total = 0;
    for (int k = 0; k < kComponents; ++k) {
      const double w = weights[k];
      if (!std::isfinite(w) || w < 0 || w > 1) refuse("has a weight outside [0, 1]");
      total += w;
      if (w == 0) continue;
      const cv::Matx33d cov(covs + 9 * k);
      const double det = cv::determinant(cov);
      // Positive definite: the leading minors positive (cv::grabCut keeps them so by adding to the diagonal).
      if (!(cov(0, 0) > 0 && cov(0, 0) * cov(1, 1) - cov(0, 1) * cov(1, 0) > 0 && det > 0) || !std::isfinite(det))
        refuse("has a covariance that is not positive definite");
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(means[3 * k + c])) refuse("has a non-finite mean");
        mean_[n_][c] = static_cast<float>(means[3 * k + c]);
      }
      const cv::Matx33d inv = cov.inv();
      const float i[6] = {float(inv(0, 0)), float(inv(0, 1) + inv(1, 0)), float(inv(0, 2) + inv(2, 0)),
                          float(inv(1, 1)), float(inv(1, 2) + inv(2, 1)), float(inv(2, 2))};
      std::copy(i, i + 6, inv_[n_]);
      offset_[n_] = static_cast<float>(std::log(w) - 0.5 * std::log(det));
      ++n_;
    }
    if (n_ == 0 || std::abs(total - 1) > 1e-6) refuse("has weights that do not sum to 1");
  }

  // Without the 2π constant, as cv::grabCut: it is the same on both sides of the cut.
  float NegLogLikelihood(const uchar* bgr) const {
    float e[kComponents], best = -std::numeric_limits<float>::infinity();
    for (int k = 0; k < n_; ++k) {
      const float b = bgr[0] - mean_[k][0], g = bgr[1] - mean_[k][1], r = bgr[2] - mean_[k][2];
      const float* i = inv_[k];
      const float m = b * (i[0] * b + i[1] * g + i[2] * r) + g * (i[3] * g + i[4] * r) + i[5] * r * r;
      e[k] = offset_[k] - 0.5f * m;
      best = std::max(best, e[k]);
    }
    float sum = 0;
    for (int k = 0; k < n_; ++k) sum += std::exp(e[k] - best);
    return -(best + std::log(sum));
  }

 private:
  int n_ = 0;
  float offset_[kComponents] = {}, mean_[kComponents][3] = {}, inv_[kComponents][6] = {};
};

bool Undecided(uchar label) { return label == cv::GC_PR_BGD || label == cv::GC_PR_FGD; }

int SquaredDistance(const uchar* a, const uchar* b) {
  const int d0 = a[0] - b[0], d1 = a[1] - b[1], d2 = a[2] - b[2];
  return d0 * d0 + d1 * d1 + d2 * d2;
}

// The neighbours a pixel links to behind it in scan order: left, up-left, up, up-right.
constexpr int kBehind[4][2] = {{0, -1}, {-1, -1}, {-1, 0}, {-1, 1}};

}  // namespace

void CutWithColourModels(const cv::Mat& bgr, cv::Mat& labels, const cv::Mat& background, const cv::Mat& foreground) {
  if (bgr.empty() || bgr.type() != CV_8UC3)
    throw std::invalid_argument("CutWithColourModels: an 8-bit BGR image is needed");
  if (labels.type() != CV_8U || labels.size() != bgr.size())
    throw std::invalid_argument("CutWithColourModels: labels must be CV_8U and the image's size");
  for (int y = 0; y < labels.rows; ++y)
    for (int x = 0; x < labels.cols; ++x)
      if (labels.at<uchar>(y, x) > cv::GC_PR_FGD)
        throw std::invalid_argument("CutWithColourModels: a label that is not one of cv::GrabCutClasses");
  const Mixture back(background, "background"), head(foreground, "foreground");

  // The contrast scale: neighbours split at the image's mean colour step pay about a third of gamma.
  const int rows = bgr.rows, cols = bgr.cols;
  int64_t sum_d2 = 0, pairs = 0;
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x)
      for (const auto& d : kBehind) {
        const int qy = y + d[0], qx = x + d[1];
        if (qy < 0 || qx < 0 || qx >= cols) continue;
        sum_d2 += SquaredDistance(bgr.ptr<uchar>(y, x), bgr.ptr<uchar>(qy, qx));
        ++pairs;
      }
  const float beta = sum_d2 > 0 ? static_cast<float>(pairs / (2.0 * sum_d2)) : 0.f;

  std::vector<int> vertex(static_cast<size_t>(rows) * cols, -1);
  // Per vertex: its link to the head's terminal (paid when it goes to the
  // background) and to the background's (paid when it goes to the head).
  std::vector<float> to_head, to_back;
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x)
      if (Undecided(labels.at<uchar>(y, x))) {
        vertex[static_cast<size_t>(y) * cols + x] = static_cast<int>(to_head.size());
        const uchar* c = bgr.ptr<uchar>(y, x);
        to_head.push_back(back.NegLogLikelihood(c));
        to_back.push_back(head.NegLogLikelihood(c));
      }
  const int n = static_cast<int>(to_head.size());
  if (n == 0) return;

  cv::detail::GCGraph<float> graph(static_cast<unsigned>(n), static_cast<unsigned>(8 * n));
  for (int v = 0; v < n; ++v) graph.addVtx();
  bool any_edge = false;
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x)
      for (int k = 0; k < 4; ++k) {
        const int qy = y + kBehind[k][0], qx = x + kBehind[k][1];
        if (qy < 0 || qx < 0 || qx >= cols) continue;
        const int vp = vertex[static_cast<size_t>(y) * cols + x], vq = vertex[static_cast<size_t>(qy) * cols + qx];
        if (vp < 0 && vq < 0) continue;
        const float w = (k % 2 ? kGamma / std::sqrt(2.f) : kGamma) *
                        std::exp(-beta * SquaredDistance(bgr.ptr<uchar>(y, x), bgr.ptr<uchar>(qy, qx)));
        if (vp >= 0 && vq >= 0) {
          graph.addEdges(vp, vq, w, w);
          any_edge = true;
          continue;
        }
        // A certain neighbour never changes side: its link is paid when the
        // undecided pixel takes the other one.
        const int v = vp >= 0 ? vp : vq;
        const uchar certain = vp >= 0 ? labels.at<uchar>(qy, qx) : labels.at<uchar>(y, x);
        (certain == cv::GC_FGD ? to_head : to_back)[v] += w;
      }
  for (int v = 0; v < n; ++v) graph.addTermWeights(v, to_head[v], to_back[v]);
  if (any_edge) graph.maxFlow();  // (GCGraph refuses a graph without edges)
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) {
      const int v = vertex[static_cast<size_t>(y) * cols + x];
      if (v < 0) continue;
      const bool head_side = any_edge ? graph.inSourceSegment(v) : to_head[v] > to_back[v];
      labels.at<uchar>(y, x) = head_side ? cv::GC_PR_FGD : cv::GC_PR_BGD;
    }
}

}  // namespace headcast
