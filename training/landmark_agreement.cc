// Landmark agreement between an avatar's pictures and the true frames.
#include "training/landmark_agreement.h"

#include <cmath>
#include <numeric>

namespace headcast {
namespace {

// dlib's 68-point layout.
struct Region {
  const char* name;
  int first, last;  // inclusive
};
constexpr Region kRegions[] = {
    {"eyes", 36, 47}, {"brows", 17, 26}, {"nose", 27, 35}, {"mouth", 48, 67}, {"jaw", 0, 16}};

Eigen::Vector2d Mean(const Landmarks2d& l, int first, int last) {
  Eigen::Vector2d m = Eigen::Vector2d::Zero();
  for (int i = first; i <= last; ++i) m += l[i];
  return m / (last - first + 1);
}

// Each region's mean length of its points' vectors.
std::array<double, 5> RegionSizes(const Landmarks2d& v) {
  std::array<double, 5> e{};
  for (size_t r = 0; r < 5; ++r) {
    const Region& g = kRegions[r];
    for (int i = g.first; i <= g.last; ++i) e[r] += v[i].norm();
    e[r] /= g.last - g.first + 1;
  }
  return e;
}

// Each point of `a` less `b`'s, over `scale`.
Landmarks2d Offsets(const Landmarks2d& a, const Landmarks2d& b, double scale) {
  Landmarks2d d;
  for (int i = 0; i < kNumLandmarks; ++i) d[i] = (a[i] - b[i]) / scale;
  return d;
}

// Each region's mean over the frames, and "all": every point alike (regions
// weighted by their point counts).
nlohmann::json RegionMeans(const std::vector<std::array<double, 5>>& frames) {
  const size_t n = frames.size();
  nlohmann::json errors = nlohmann::json::object();
  double all = 0;
  for (size_t r = 0; r < 5; ++r) {
    double sum = 0;
    for (const auto& e : frames) sum += e[r];
    errors[kRegions[r].name] = n ? sum / n : 0.0;
    all += sum * (kRegions[r].last - kRegions[r].first + 1) / 68.0;
  }
  errors["all"] = n ? all / n : 0.0;
  return errors;
}

// Per frame, each region's mean length of the points' offsets; with
// `moving`, each point's mean offset over the frames taken out first.
std::vector<std::array<double, 5>> OffsetSizes(const std::vector<Landmarks2d>& offsets, bool moving) {
  Landmarks2d steady;
  for (auto& p : steady) p.setZero();
  if (moving)
    for (const Landmarks2d& o : offsets)
      for (int i = 0; i < kNumLandmarks; ++i) steady[i] += o[i] / static_cast<double>(offsets.size());
  std::vector<std::array<double, 5>> sizes;
  for (const Landmarks2d& o : offsets) sizes.push_back(RegionSizes(Offsets(o, steady, 1.0)));
  return sizes;
}

FaceTrackerOptions StillImages(const std::string& predictor_path) {
  FaceTrackerOptions o;
  o.predictor_path = predictor_path;
  o.redetect_interval = 1;   // every picture on its own: no box carried over
  o.repair.enabled = false;  // nor landmarks: there is no motion between two pictures to follow
  return o;
}

}  // namespace

double PearsonCorrelation(const std::vector<double>& a, const std::vector<double>& b) {
  const size_t n = std::min(a.size(), b.size());
  if (n < 3) return 0;
  const double ma = std::accumulate(a.begin(), a.begin() + n, 0.0) / n;
  const double mb = std::accumulate(b.begin(), b.begin() + n, 0.0) / n;
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0;
}

double StandardDeviation(const std::vector<double>& v) {
  if (v.size() < 2) return 0;
  const double m = std::accumulate(v.begin(), v.end(), 0.0) / v.size();
  double sum = 0;
  for (double x : v) sum += (x - m) * (x - m);
  return std::sqrt(sum / (v.size() - 1));
}

double EyeOpening(const Landmarks2d& l) {
  auto eye = [&](int o) {  // o: the eye's first point (36 or 42), corners o and o + 3
    const double width = (l[o] - l[o + 3]).norm();
    const double lids = (l[o + 1] - l[o + 5]).norm() + (l[o + 2] - l[o + 4]).norm();
    return width > 0 ? lids / (2 * width) : 0;
  };
  return 0.5 * (eye(36) + eye(42));
}

LandmarkAgreement::LandmarkAgreement(const std::string& predictor_path) : tracker_(StillImages(predictor_path)) {}
LandmarkAgreement::~LandmarkAgreement() = default;

bool LandmarkAgreement::Detect(const cv::Mat& image, FaceObservation* out) {
  tracker_.Reset();
  *out = tracker_.Track(image, 0);
  return out->status != FaceStatus::kNoFace;
}

void LandmarkAgreement::Add(const cv::Mat& truth_bgr, const cv::Mat& avatar_bgr, const Landmarks2d* fitted) {
  ++frames_;
  FaceObservation seen_truth, seen_avatar;
  if (!Detect(truth_bgr, &seen_truth) || !Detect(avatar_bgr, &seen_avatar)) return;
  const Landmarks2d &truth = seen_truth.raw, &avatar = seen_avatar.raw;
  const double iod = (Mean(truth, 36, 41) - Mean(truth, 42, 47)).norm();
  if (!(iod > 1)) return;
  region_errors_.push_back(RegionSizes(Offsets(truth, avatar, iod)));
  if (fitted) {
    truth_from_fit_.push_back(Offsets(truth, *fitted, iod));
    avatar_from_fit_.push_back(Offsets(avatar, *fitted, iod));
  }
  truth_opening_.push_back(EyeOpening(truth));
  avatar_opening_.push_back(EyeOpening(avatar));
  const IrisObservation* irises[2][2] = {{&seen_truth.irises.right, &seen_avatar.irises.right},
                                         {&seen_truth.irises.left, &seen_avatar.irises.left}};
  for (int e = 0; e < 2; ++e) {
    if (!irises[e][0]->found || !irises[e][1]->found) continue;
    const int first = e == 0 ? 36 : 42;
    const Eigen::Vector2d t = IrisInEyeFrame(irises[e][0]->center, EyeLandmarks(truth, first));
    const Eigen::Vector2d a = IrisInEyeFrame(irises[e][1]->center, EyeLandmarks(avatar, first));
    for (int c = 0; c < 2; ++c) {
      truth_gaze_[c].push_back(t[c]);
      avatar_gaze_[c].push_back(a[c]);
    }
  }
}

nlohmann::json LandmarkAgreement::Summary() const {
  const size_t n = region_errors_.size();
  const size_t eyes = truth_gaze_[0].size();
  double gaze_error = 0;
  for (size_t i = 0; i < eyes; ++i)
    gaze_error += std::hypot(truth_gaze_[0][i] - avatar_gaze_[0][i], truth_gaze_[1][i] - avatar_gaze_[1][i]);
  const nlohmann::json gaze = {{"eyes", eyes},
                               {"correlation_x", PearsonCorrelation(truth_gaze_[0], avatar_gaze_[0])},
                               {"correlation_y", PearsonCorrelation(truth_gaze_[1], avatar_gaze_[1])},
                               {"error", eyes ? gaze_error / eyes : 0.0},
                               {"truth_sd_x", StandardDeviation(truth_gaze_[0])},
                               {"truth_sd_y", StandardDeviation(truth_gaze_[1])}};
  nlohmann::json summary = {{"frames", frames_},
                            {"found_in_both", n},
                            {"error_iod", RegionMeans(region_errors_)},
                            {"blink",
                             {{"correlation", PearsonCorrelation(truth_opening_, avatar_opening_)},
                              {"truth_opening_sd", StandardDeviation(truth_opening_)}}},
                            {"gaze", gaze}};
  if (!truth_from_fit_.empty())
    summary["fit"] = {{"frames", truth_from_fit_.size()},
                      {"truth_vs_fit", RegionMeans(OffsetSizes(truth_from_fit_, false))},
                      {"avatar_vs_fit", RegionMeans(OffsetSizes(avatar_from_fit_, false))},
                      {"truth_vs_fit_moving", RegionMeans(OffsetSizes(truth_from_fit_, true))},
                      {"avatar_vs_fit_moving", RegionMeans(OffsetSizes(avatar_from_fit_, true))}};
  return summary;
}

}  // namespace headcast
