// Face detection, landmarks and filtering with dlib.
#include "common/tracking/face_tracker.h"

#include <dlib/image_processing.h>
#include <dlib/image_processing/frontal_face_detector.h>
#include <dlib/opencv/cv_image.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

#include "common/core/options.h"

namespace headcast {

void FaceTrackerOptions::Check() const {
  OptionsCheck c("FaceTrackerOptions");
  c.NotEmpty("predictor_path", predictor_path).InRange("detect_width", detect_width, 64, 8192);
  c.InRange("redetect_interval", redetect_interval, 1, 100000).Positive("min_face_px", min_face_px);
  c.InRange("predictor_views", predictor_views, 1, kMaxPredictorViews)
      .That(std::find(kPredictorViewsPoints.begin(), kPredictorViewsPoints.end(), predictor_views_points) !=
                kPredictorViewsPoints.end(),
            "predictor_views_points is all, no-eyes or outline");
  c.InRange("max_tracked_scale_change", max_tracked_scale_change, 1.01, 10.0)
      .InRange("max_tracked_shift", max_tracked_shift, 0.01, 10.0)
      .InRange("max_scale_change_since_detection", max_scale_change_since_detection, 1.01, 10.0);
  c.Positive("filter_min_cutoff", filter_min_cutoff).NonNegative("filter_beta", filter_beta);
  c.ThrowIfErrors();
  iris.Check();
  repair.Check();
}

bool FaceTrackerOptions::TakesTheViewsMedian(int l) const {
  if (predictor_views_points == "no-eyes") return l < 36 || l > 47;
  if (predictor_views_points == "outline") return l <= 16 || (l >= 27 && l <= 35);  // jaw line, nose
  return true;
}

int MirroredLandmark(int l) {
  if (l < 0 || l >= kNumLandmarks) throw std::out_of_range("MirroredLandmark: no landmark " + std::to_string(l));
  // Each run of points mirrors onto itself read backwards: index first + last - l.
  struct Run {
    int first, last;
  };
  static constexpr Run kRuns[] = {{0, 16}, {17, 26}, {31, 35}, {36, 45}, {48, 54}, {55, 59}, {60, 64}, {65, 67}};
  // The eyes: the upper lids and corners 36-39 with 42-45, the lower lids 40-41 with 46-47.
  if ((l >= 40 && l <= 41) || (l >= 46 && l <= 47)) return 87 - l;
  for (const Run& r : kRuns)
    if (l >= r.first && l <= r.last) return r.first + r.last - l;
  return l;  // the nose's bridge, 27-30, lies on the mirror line
}

const char* FaceStatusName(FaceStatus s) {
  switch (s) {
    case FaceStatus::kDetected:
      return "detected";
    case FaceStatus::kTracked:
      return "tracked";
    case FaceStatus::kNoFace:
      return "no_face";
  }
  return "?";
}

double OneEuroFilter::Filter(double x, double t) {
  auto alpha = [](double cutoff, double dt) {
    const double tau = 1.0 / (2 * M_PI * cutoff);
    return 1.0 / (1.0 + tau / dt);
  };
  if (!initialised_ || t <= t_) {
    if (!initialised_) {
      x_ = x;
      dx_ = 0;
      t_ = t;
      initialised_ = true;
    }
    return x_;
  }
  const double dt = t - t_;
  const double dx = (x - x_) / dt;
  dx_ += alpha(d_cutoff_, dt) * (dx - dx_);
  const double cutoff = min_cutoff_ + beta_ * std::abs(dx_);
  x_ += alpha(cutoff, dt) * (x - x_);
  t_ = t;
  return x_;
}

struct FaceTracker::Impl {
  FaceTrackerOptions options;
  dlib::frontal_face_detector detector = dlib::get_frontal_face_detector();
  dlib::shape_predictor predictor;
  bool tracking = false;
  int since_detection = 0;
  Landmarks2d previous{};
  cv::Size2d detected;  // the landmarks' extent at the last detection, pixels
  std::vector<OneEuroFilter> filters;
  LandmarkRepair repair;
  cv::Mat previous_gray;  // the frame `previous` was found in

  // The box around landmarks as fractions of their bounding box's width and
  // height beyond each side (negative: inside). The fixed values are a rough
  // detector convention; with box_from_detection each detection measures them.
  struct Margins {
    double left = 0.05, top = 0.15, right = 0.05, bottom = 0.05;
  } margins;

  static cv::Rect2d Bounds(const Landmarks2d& l) {
    double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
    for (const auto& p : l) {
      x0 = std::min(x0, p.x());
      y0 = std::min(y0, p.y());
      x1 = std::max(x1, p.x());
      y1 = std::max(y1, p.y());
    }
    return cv::Rect2d(x0, y0, x1 - x0, y1 - y0);
  }

  cv::Rect BoxFromLandmarks(const Landmarks2d& l) const {
    const cv::Rect2d b = Bounds(l);
    return cv::Rect(cv::Point(static_cast<int>(std::lround(b.x - margins.left * b.width)),
                              static_cast<int>(std::lround(b.y - margins.top * b.height))),
                    cv::Point(static_cast<int>(std::lround(b.x + b.width + margins.right * b.width)),
                              static_cast<int>(std::lround(b.y + b.height + margins.bottom * b.height))));
  }

  // The shape predictor on the views of `box` (FaceTrackerOptions::predictor_views).
  Landmarks2d Predict(const cv::Mat& gray, const cv::Rect& box) const {
    // View v: mirrored when odd, the box scaled about its centre by kScale[v].
    static constexpr double kScale[kMaxPredictorViews] = {1, 1, 0.94, 1.06, 1.06, 0.94};
    const int views = options.predictor_views;
    cv::Mat mirrored;
    if (views > 1) cv::flip(gray, mirrored, 1);
    const double last_column = gray.cols - 1;
    const double cx = box.x + 0.5 * box.width, cy = box.y + 0.5 * box.height;
    std::array<Landmarks2d, kMaxPredictorViews> found;
    for (int v = 0; v < views; ++v) {
      const bool mirror = v % 2 == 1;
      const double hw = 0.5 * box.width * kScale[v], hh = 0.5 * box.height * kScale[v];
      const double left = mirror ? last_column - (cx + hw) : cx - hw;
      const dlib::full_object_detection shape = predictor(
          dlib::cv_image<unsigned char>(mirror ? mirrored : gray),
          dlib::rectangle(std::lround(left), std::lround(cy - hh), std::lround(left + 2 * hw), std::lround(cy + hh)));
      for (int l = 0; l < kNumLandmarks; ++l) {
        const double x = shape.part(l).x(), y = shape.part(l).y();
        found[v][mirror ? MirroredLandmark(l) : l] = Eigen::Vector2d(mirror ? last_column - x : x, y);
      }
    }
    if (views == 1) return found[0];
    // The median of each coordinate: one view whose cascade went astray does not pull it.
    Landmarks2d median;
    std::array<double, kMaxPredictorViews> values;
    for (int l = 0; l < kNumLandmarks; ++l)
      for (int c = 0; c < 2; ++c) {
        for (int v = 0; v < views; ++v) values[v] = found[v][l][c];
        std::sort(values.begin(), values.begin() + views);
        median[l][c] = 0.5 * (values[(views - 1) / 2] + values[views / 2]);
      }
    for (int l = 0; l < kNumLandmarks; ++l)
      if (!options.TakesTheViewsMedian(l)) median[l] = found[0][l];
    return median;
  }

  // Remembers how the detector's `box` sits around the landmarks found in it.
  void MeasureMargins(const cv::Rect& box, const Landmarks2d& l) {
    const cv::Rect2d b = Bounds(l);
    if (!(b.width > 1 && b.height > 1)) return;
    // Clamped: one odd detection must not make a box that loses the face.
    auto fraction = [](double px, double size) { return std::clamp(px / size, -0.3, 0.6); };
    margins.left = fraction(b.x - box.x, b.width);
    margins.top = fraction(b.y - box.y, b.height);
    margins.right = fraction(box.x + box.width - (b.x + b.width), b.width);
    margins.bottom = fraction(box.y + box.height - (b.y + b.height), b.height);
  }
};

FaceTracker::FaceTracker(const FaceTrackerOptions& options) : impl_(std::make_unique<Impl>()) {
  options.Check();
  impl_->options = options;
  impl_->repair = LandmarkRepair(options.repair);
  if (!std::filesystem::exists(options.predictor_path))
    throw std::runtime_error(options.predictor_path +
                             ": no such shape predictor (install libdlib-data, or give its path)");
  try {
    dlib::deserialize(options.predictor_path) >> impl_->predictor;
  } catch (const std::exception& e) {
    throw std::runtime_error(options.predictor_path + ": not a dlib shape predictor: " + e.what());
  }
  // The landmarks', then the two irises' (left x, y, right x, y).
  for (int i = 0; i < 2 * kNumLandmarks + 4; ++i)
    impl_->filters.emplace_back(options.filter_min_cutoff, options.filter_beta);
}

FaceTracker::~FaceTracker() = default;

void FaceTracker::Reset() {
  impl_->tracking = false;
  impl_->repair.Reset();
  for (auto& f : impl_->filters) f.Reset();
}

FaceObservation FaceTracker::Track(const cv::Mat& image, double time_s) {
  Impl& m = *impl_;
  FaceObservation obs;
  if (image.empty() || image.type() != CV_8UC3) return obs;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::Rect box;
  const bool detect = !m.tracking || m.since_detection + 1 >= m.options.redetect_interval;
  if (detect) {
    // HOG's cost grows with the pixel count; faces in a call fill much of the frame.
    // Small images are enlarged (up to 2x): HOG finds faces from about 80 px.
    double scale = std::clamp(static_cast<double>(m.options.detect_width) / gray.cols, 0.05, 2.0);
    auto run_detector = [&](double s) {
      cv::Mat small;
      cv::resize(gray, small, cv::Size(), s, s, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
      return m.detector(dlib::cv_image<unsigned char>(small));
    };
    std::vector<dlib::rectangle> faces = run_detector(scale);
    if (faces.empty() && scale < 1) {
      // Maybe a small face: look once more at full resolution (only frames without a found face pay).
      scale = std::min(2.0, std::max(1.0, 2.0 * m.options.detect_width / gray.cols));
      faces = run_detector(scale);
    }
    obs.faces_detected = static_cast<int>(faces.size());
    // Several faces: follow the one we track (nearest box), else the largest.
    double best = -1e18;
    const cv::Rect previous = m.tracking ? m.BoxFromLandmarks(m.previous) : cv::Rect();
    for (const auto& f : faces) {
      const double s = 1.0 / scale;
      const cv::Rect r(cv::Point(static_cast<int>(f.left() * s), static_cast<int>(f.top() * s)),
                       cv::Point(static_cast<int>(f.right() * s), static_cast<int>(f.bottom() * s)));
      if (r.width < m.options.min_face_px) continue;
      const double score =
          m.tracking ? -cv::norm((r.tl() + r.br()) / 2 - (previous.tl() + previous.br()) / 2) : r.area();
      if (score > best) best = score, box = r;
    }
    if (box.area() == 0) {
      m.tracking = false;
      return obs;  // no face: a status, not an error
    }
    m.since_detection = 0;
    obs.status = FaceStatus::kDetected;
  } else {
    box = m.BoxFromLandmarks(m.previous);
    ++m.since_detection;
    obs.status = FaceStatus::kTracked;
  }
  obs.raw = m.Predict(gray, box);
  // A face that left the frame or a box on nothing: the landmarks collapse or fly off.
  const cv::Rect found = m.BoxFromLandmarks(obs.raw);
  const bool plausible = found.width >= m.options.min_face_px * 0.5 && found.height >= m.options.min_face_px * 0.5 &&
                         (found & cv::Rect(0, 0, image.cols, image.rows)).area() > 0.5 * found.area();
  if (!plausible) {
    m.tracking = false;
    obs.status = FaceStatus::kNoFace;
    return obs;
  }
  // A followed box that slipped off the face (onto the mouth, say) gives
  // landmarks of another size or place than last frame's: a face does not do
  // that in 1/30 s. Detect again in this frame rather than follow the slip.
  if (!detect) {
    const cv::Rect2d was = Impl::Bounds(m.previous), now = Impl::Bounds(obs.raw);
    auto off = [](double scale, double limit) { return scale < 1 / limit || scale > limit; };
    const double frame_limit = m.options.max_tracked_scale_change;
    const double detection_limit = m.options.max_scale_change_since_detection;
    const cv::Point2d moved = (now.tl() + now.br()) / 2 - (was.tl() + was.br()) / 2;
    // Against the last frame (a sudden slip) and the last detection (a slow
    // creep, a few percent a frame, that no single frame shows).
    if (off(now.width / std::max(was.width, 1.0), frame_limit) ||
        off(now.width / std::max(m.detected.width, 1.0), detection_limit) ||
        off(now.height / std::max(m.detected.height, 1.0), detection_limit) ||
        cv::norm(moved) > m.options.max_tracked_shift * was.width) {
      m.since_detection = m.options.redetect_interval;
      FaceObservation again = Track(image, time_s);
      again.recovered = true;
      return again;
    }
  }
  if (detect && !m.tracking) {
    for (auto& f : m.filters) f.Reset();  // a new face: do not smooth from the old one
    m.repair.Reset();
  } else {
    const LandmarkRepair::Regions regions = m.repair.Check(m.previous_gray, m.previous, gray, &obs.raw);
    obs.disputed = regions.disputed;
    obs.repaired = regions.repaired;
  }
  for (int l = 0; l < kNumLandmarks; ++l)
    obs.landmarks[l] = !m.options.filter ? obs.raw[l]
                                         : Eigen::Vector2d(m.filters[2 * l].Filter(obs.raw[l].x(), time_s),
                                                           m.filters[2 * l + 1].Filter(obs.raw[l].y(), time_s));
  if (m.options.locate_irises) {
    obs.irises = LocateIrises(gray, obs.raw, m.options.iris);
    IrisObservation* irises[2] = {&obs.irises.left, &obs.irises.right};
    for (int e = 0; m.options.filter && e < 2; ++e) {
      OneEuroFilter* f = &m.filters[2 * kNumLandmarks + 2 * e];
      if (!irises[e]->found) {
        f[0].Reset();  // a blink: the iris comes back somewhere else
        f[1].Reset();
        continue;
      }
      irises[e]->center =
          Eigen::Vector2d(f[0].Filter(irises[e]->center.x(), time_s), f[1].Filter(irises[e]->center.y(), time_s));
    }
  }
  if (detect && m.options.box_from_detection) m.MeasureMargins(box, obs.raw);
  if (detect) m.detected = Impl::Bounds(obs.raw).size();
  obs.box = found;
  m.previous = obs.raw;
  m.previous_gray = gray;
  m.tracking = true;
  return obs;
}

namespace {

// One coordinate over the frames [begin, end): forwards and backwards, averaged.
// `get` reads the value of frame i, `set` writes the smoothed one.
template <typename Get, typename Set>
void SmoothRun(size_t begin, size_t end, const std::vector<double>& t, double min_cutoff, double beta, Get get,
               Set set) {
  std::vector<double> forward(end - begin);
  OneEuroFilter f(min_cutoff, beta);
  for (size_t i = begin; i < end; ++i) forward[i - begin] = f.Filter(get(i), t[i]);
  // Backwards in time: the filter sees time running forward from the run's end.
  OneEuroFilter b(min_cutoff, beta);
  for (size_t i = end; i-- > begin;)
    set(i, 0.5 * (forward[i - begin] + b.Filter(get(i), t[end - 1] - t[i] + t[begin])));
}

// Calls run(begin, end) for each maximal run of frames where inside(i).
template <typename Inside, typename Run>
void ForEachRun(size_t n, Inside inside, Run run) {
  for (size_t i = 0; i < n;) {
    if (!inside(i)) {
      ++i;
      continue;
    }
    size_t j = i;
    while (j < n && inside(j)) ++j;
    run(i, j);
    i = j;
  }
}

}  // namespace

void SmoothTrackTwoSided(std::vector<FaceObservation>* track, const std::vector<double>& t, double min_cutoff,
                         double beta) {
  std::vector<FaceObservation>& o = *track;
  if (t.size() != o.size()) throw std::invalid_argument("SmoothTrackTwoSided: one time per observation is needed");
  for (size_t i = 1; i < t.size(); ++i)
    if (!(t[i] > t[i - 1])) throw std::invalid_argument("SmoothTrackTwoSided: times must increase");
  if (!(min_cutoff > 0) || !(beta >= 0)) throw std::invalid_argument("SmoothTrackTwoSided: bad filter settings");
  ForEachRun(
      o.size(), [&](size_t i) { return o[i].status != FaceStatus::kNoFace; },
      [&](size_t begin, size_t end) {
        for (int l = 0; l < kNumLandmarks; ++l)
          for (int c = 0; c < 2; ++c)
            SmoothRun(
                begin, end, t, min_cutoff, beta, [&](size_t i) { return o[i].raw[l][c]; },
                [&](size_t i, double v) { o[i].landmarks[l][c] = v; });
      });
  for (IrisObservation EyeIrises::*eye : {&EyeIrises::left, &EyeIrises::right})
    ForEachRun(
        o.size(), [&](size_t i) { return o[i].status != FaceStatus::kNoFace && (o[i].irises.*eye).found; },
        [&](size_t begin, size_t end) {
          for (int c = 0; c < 2; ++c) {
            std::vector<double> found(end - begin);  // read all before writing: the run smooths the found centres
            for (size_t i = begin; i < end; ++i) found[i - begin] = (o[i].irises.*eye).center[c];
            SmoothRun(
                begin, end, t, min_cutoff, beta, [&](size_t i) { return found[i - begin]; },
                [&](size_t i, double v) { (o[i].irises.*eye).center[c] = v; });
          }
        });
}

}  // namespace headcast
