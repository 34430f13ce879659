// GrabCut's energy cut over the undecided pixels only, and its colour models' learning.
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
constexpr double kGamma = 50;

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
      // Invertible, as cv::grabCut asks (a learnt one is widened where it is not).
      if (!(det > std::numeric_limits<double>::epsilon()) || !std::isfinite(det)) refuse("has a singular covariance");
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(means[3 * k + c])) refuse("has a non-finite mean");
        mean_[n_][c] = means[3 * k + c];
      }
      const cv::Matx33d inv = cov.inv();
      const double i[6] = {inv(0, 0), inv(0, 1) + inv(1, 0), inv(0, 2) + inv(2, 0),
                           inv(1, 1), inv(1, 2) + inv(2, 1), inv(2, 2)};
      std::copy(i, i + 6, inv_[n_]);
      shape_[n_] = -0.5 * std::log(det);
      offset_[n_] = std::log(w) + shape_[n_];
      index_[n_] = k;
      ++n_;
    }
    if (n_ == 0 || std::abs(total - 1) > 1e-6) refuse("has weights that do not sum to 1");
  }

  // Without the 2π constant, as cv::grabCut: it is the same on both sides of
  // the cut. Summed as cv::grabCut sums it, so that a colour far from every
  // component costs what it costs there (nothing left of the sum: infinite).
  double NegLogLikelihood(const uchar* bgr) const {
    double sum = 0;
    for (int k = 0; k < n_; ++k) sum += std::exp(offset_[k] - 0.5 * Mahalanobis(k, bgr));
    return -std::log(sum);
  }

  // The component (its index in the model) whose density is highest at the
  // colour, its weight aside, as cv::grabCut assigns them: the first one
  // where no density is left above zero.
  int Likeliest(const uchar* bgr) const {
    int best = 0;
    double best_density = 0;
    for (int k = 0; k < n_; ++k) {
      const double density = std::exp(shape_[k] - 0.5 * Mahalanobis(k, bgr));
      if (density > best_density) best_density = density, best = index_[k];
    }
    return best;
  }

 private:
  double Mahalanobis(int k, const uchar* bgr) const {
    const double b = bgr[0] - mean_[k][0], g = bgr[1] - mean_[k][1], r = bgr[2] - mean_[k][2];
    const double* i = inv_[k];
    return b * (i[0] * b + i[1] * g + i[2] * r) + g * (i[3] * g + i[4] * r) + i[5] * r * r;
  }

  int n_ = 0;
  int index_[kComponents] = {};
  double offset_[kComponents] = {}, shape_[kComponents] = {}, mean_[kComponents][3] = {}, inv_[kComponents][6] = {};
};

// A mixture's sums over the pixels given to each component, and the model
// they make: weights by count, means, covariances (one whose determinant is
// at most 1e-6 widened by a hundredth on its diagonal, as cv::grabCut 4.6
// does: prep's masks of talking_d3 come out byte for byte as its).
class MixtureSums {
 public:
  void Add(int k, const uchar* c) {
    ++count_[k];
    for (int i = 0; i < 3; ++i) {
      sum_[k][i] += c[i];
      for (int j = 0; j < 3; ++j) product_[k][i][j] += c[i] * c[j];
    }
  }
  cv::Mat Model() const {
    cv::Mat model(1, 13 * kComponents, CV_64F, cv::Scalar(0));
    double* weight = model.ptr<double>();
    double* mean = weight + kComponents;
    double* cov = mean + 3 * kComponents;
    int64_t total = 0;
    for (int k = 0; k < kComponents; ++k) total += count_[k];
    for (int k = 0; k < kComponents; ++k) {
      if (count_[k] == 0) continue;
      const double n = static_cast<double>(count_[k]);
      weight[k] = n / static_cast<double>(total);
      for (int i = 0; i < 3; ++i) mean[3 * k + i] = static_cast<double>(sum_[k][i]) / n;
      double* c = cov + 9 * k;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          c[3 * i + j] = static_cast<double>(product_[k][i][j]) / n - mean[3 * k + i] * mean[3 * k + j];
      if (cv::determinant(cv::Matx33d(c)) <= 1e-6)
        for (int i = 0; i < 3; ++i) c[4 * i] += 0.01;
    }
    return model;
  }

 private:
  int64_t count_[kComponents] = {}, sum_[kComponents][3] = {}, product_[kComponents][3][3] = {};
};

bool OnBackground(uchar label) { return label == cv::GC_BGD || label == cv::GC_PR_BGD; }

void CheckImageAndLabels(const char* who, const cv::Mat& bgr, const cv::Mat& labels) {
  if (bgr.empty() || bgr.type() != CV_8UC3)
    throw std::invalid_argument(std::string(who) + ": an 8-bit BGR image is needed");
  if (labels.type() != CV_8U || labels.size() != bgr.size())
    throw std::invalid_argument(std::string(who) + ": labels must be CV_8U and the image's size");
  for (int y = 0; y < labels.rows; ++y)
    for (int x = 0; x < labels.cols; ++x)
      if (labels.at<uchar>(y, x) > cv::GC_PR_FGD)
        throw std::invalid_argument(std::string(who) + ": a label that is not one of cv::GrabCutClasses");
}

bool Undecided(uchar label) { return label == cv::GC_PR_BGD || label == cv::GC_PR_FGD; }

int SquaredDistance(const uchar* a, const uchar* b) {
  const int d0 = a[0] - b[0], d1 = a[1] - b[1], d2 = a[2] - b[2];
  return d0 * d0 + d1 * d1 + d2 * d2;
}

// The neighbours a pixel links to behind it in scan order: left, up-left, up, up-right.
constexpr int kBehind[4][2] = {{0, -1}, {-1, -1}, {-1, 0}, {-1, 1}};

// What a cut of an image and its seeds is made of, apart from the colours'
// terms: which pixel each vertex is (the undecided ones, in scan order), the
// links between undecided neighbours, and the links to certain ones (each
// paid when the undecided pixel takes the other side). The undecided pixels
// stay undecided whatever side a cut puts them on, so a learning's rounds
// cut the same graph with other colour models.
class CutGraph {
 public:
  CutGraph(const cv::Mat& bgr, const cv::Mat& labels) {
    // The contrast scale: neighbours split at the image's mean colour step pay exp(-1/2) of gamma.
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
    const double beta = sum_d2 > 0 ? pairs / (2.0 * sum_d2) : 0.0;
    std::vector<int> vertex(static_cast<size_t>(rows) * cols, -1);
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x)
        if (Undecided(labels.at<uchar>(y, x))) {
          vertex[static_cast<size_t>(y) * cols + x] = static_cast<int>(pixels_.size());
          pixels_.emplace_back(x, y);
        }
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x)
        for (int k = 0; k < 4; ++k) {
          const int qy = y + kBehind[k][0], qx = x + kBehind[k][1];
          if (qy < 0 || qx < 0 || qx >= cols) continue;
          const int vp = vertex[static_cast<size_t>(y) * cols + x], vq = vertex[static_cast<size_t>(qy) * cols + qx];
          if (vp < 0 && vq < 0) continue;
          const double w = (k % 2 ? kGamma / std::sqrt(2.0) : kGamma) *
                           std::exp(-beta * SquaredDistance(bgr.ptr<uchar>(y, x), bgr.ptr<uchar>(qy, qx)));
          if (vp >= 0 && vq >= 0) {
            links_.push_back({vp, vq, w});
          } else {
            const uchar certain = vp >= 0 ? labels.at<uchar>(qy, qx) : labels.at<uchar>(y, x);
            certain_.push_back({vp >= 0 ? vp : vq, certain == cv::GC_FGD, w});
          }
        }
  }

  // One minimum cut with these colour models: every undecided label set to its side.
  void Cut(const cv::Mat& bgr, const Mixture& back, const Mixture& head, cv::Mat& labels) const {
    const int n = static_cast<int>(pixels_.size());
    if (n == 0) return;
    // Per vertex: its link to the head's terminal (paid when it goes to the
    // background) and to the background's (paid when it goes to the head).
    std::vector<double> to_head(n), to_back(n);
    for (int v = 0; v < n; ++v) {
      const uchar* c = bgr.ptr<uchar>(pixels_[v].y, pixels_[v].x);
      to_head[v] = back.NegLogLikelihood(c);
      to_back[v] = head.NegLogLikelihood(c);
    }
    for (const Certain& l : certain_) (l.head ? to_head : to_back)[l.v] += l.w;
    cv::detail::GCGraph<double> graph(static_cast<unsigned>(n), static_cast<unsigned>(2 * links_.size()));
    for (int v = 0; v < n; ++v) graph.addVtx();
    for (const Link& l : links_) graph.addEdges(l.p, l.q, l.w, l.w);
    for (int v = 0; v < n; ++v) graph.addTermWeights(v, to_head[v], to_back[v]);
    const bool any_link = !links_.empty();
    if (any_link) graph.maxFlow();  // (GCGraph refuses a graph without edges)
    for (int v = 0; v < n; ++v) {
      const bool head_side = any_link ? graph.inSourceSegment(v) : to_head[v] > to_back[v];
      labels.at<uchar>(pixels_[v].y, pixels_[v].x) = head_side ? cv::GC_PR_FGD : cv::GC_PR_BGD;
    }
  }

 private:
  struct Link {
    int p, q;
    double w;
  };
  struct Certain {
    int v;
    bool head;  // the certain neighbour is head
    double w;
  };
  std::vector<cv::Point> pixels_;
  std::vector<Link> links_;
  std::vector<Certain> certain_;  // in scan order, as they are summed
};

}  // namespace

void CutWithColourModels(const cv::Mat& bgr, cv::Mat& labels, const cv::Mat& background, const cv::Mat& foreground) {
  CheckImageAndLabels("CutWithColourModels", bgr, labels);
  const Mixture back(background, "background"), head(foreground, "foreground");
  CutGraph(bgr, labels).Cut(bgr, back, head, labels);
}

void LearnColourModels(const cv::Mat& bgr, cv::Mat& labels, int iterations, cv::Mat* background, cv::Mat* foreground,
                       bool cut_last) {
  CheckImageAndLabels("LearnColourModels", bgr, labels);
  if (iterations < 1) throw std::invalid_argument("LearnColourModels: at least one iteration");
  // Each side's colours clustered: the components' first assignment.
  std::vector<float> side_colours[2];
  for (int y = 0; y < bgr.rows; ++y)
    for (int x = 0; x < bgr.cols; ++x) {
      const uchar* c = bgr.ptr<uchar>(y, x);
      std::vector<float>& colours = side_colours[OnBackground(labels.at<uchar>(y, x)) ? 0 : 1];
      colours.insert(colours.end(), {float(c[0]), float(c[1]), float(c[2])});
    }
  MixtureSums sums[2];
  for (int side = 0; side < 2; ++side) {
    const cv::Mat colours(static_cast<int>(side_colours[side].size() / 3), 3, CV_32F, side_colours[side].data());
    if (colours.rows < kComponents)
      throw std::invalid_argument(std::string("LearnColourModels: fewer ") + (side ? "head" : "background") +
                                  " pixels than colour components");
    cv::Mat cluster;
    cv::kmeans(colours, kComponents, cluster, cv::TermCriteria(cv::TermCriteria::MAX_ITER, 10, 0.0), 1,
               cv::KMEANS_PP_CENTERS);
    int i = 0;
    for (int y = 0; y < bgr.rows; ++y)
      for (int x = 0; x < bgr.cols; ++x)
        if (OnBackground(labels.at<uchar>(y, x)) == (side == 0))
          sums[side].Add(cluster.at<int>(i++), bgr.ptr<uchar>(y, x));
  }
  *background = sums[0].Model();
  *foreground = sums[1].Model();
  const CutGraph graph(bgr, labels);
  for (int it = 0; it < iterations; ++it) {
    const Mixture mixtures[2] = {Mixture(*background, "background"), Mixture(*foreground, "foreground")};
    MixtureSums refit[2];
    for (int y = 0; y < bgr.rows; ++y)
      for (int x = 0; x < bgr.cols; ++x) {
        const int side = OnBackground(labels.at<uchar>(y, x)) ? 0 : 1;
        const uchar* c = bgr.ptr<uchar>(y, x);
        refit[side].Add(mixtures[side].Likeliest(c), c);
      }
    *background = refit[0].Model();
    *foreground = refit[1].Model();
    if (it + 1 == iterations && !cut_last) break;  // the last cut changes only the labels
    graph.Cut(bgr, Mixture(*background, "background"), Mixture(*foreground, "foreground"), labels);
  }
}

}  // namespace headcast
