// Mask geometry shared by the dataset and the avatar's matte.
#include "common/avatar/matte.h"

#include <Eigen/LU>
#include <cmath>
#include <cstdlib>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <stdexcept>
#include <vector>

#include "common/core/options.h"

namespace headcast {

void MatteRules::Check() const {
  OptionsCheck c("MatteRules");
  c.InRange("hair_margin", hair_margin, 0.0, 0.5).InRange("side_margin", side_margin, 0.0, hair_margin);
  c.ThrowIfErrors();
}

nlohmann::json MatteRules::ToJson() const {
  return {
      {"hair_margin", hair_margin}, {"side_margin", side_margin}, {"keep_neck", keep_neck}, {"fill_skull", fill_skull}};
}

MatteRules MatteRules::FromJson(const nlohmann::json& j) {
  MatteRules r;
  try {
    r.hair_margin = j.at("hair_margin");
    r.side_margin = j.at("side_margin");
    r.keep_neck = j.at("keep_neck");
    r.fill_skull = j.contains("fill_skull") ? j.at("fill_skull").get<bool>() : false;
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("MatteRules: bad or missing field: ") + e.what());
  }
  r.Check();
  return r;
}

void ClearBelowJawLine(const Landmarks2d& lm, cv::Mat* mask) {
  const Eigen::Vector2d brow = 0.5 * (lm[19] + lm[24]);
  Eigen::Vector2d down = lm[8] - brow;
  if (!(down.norm() > 1e-6)) return;
  down *= 4.0 * (mask->rows + mask->cols) / down.norm();
  std::vector<cv::Point> polygon;
  for (int l = 0; l < kNumContourLandmarks; ++l) polygon.emplace_back(cvRound(lm[l].x()), cvRound(lm[l].y()));
  const Eigen::Vector2d right_end = lm[kNumContourLandmarks - 1] + down, left_end = lm[0] + down;
  polygon.emplace_back(cvRound(right_end.x()), cvRound(right_end.y()));
  polygon.emplace_back(cvRound(left_end.x()), cvRound(left_end.y()));
  cv::fillPoly(*mask, std::vector<std::vector<cv::Point>>{polygon}, cv::Scalar(0));
}

void KeepHeadPiece(const Landmarks2d& landmarks, cv::Mat* mask) {
  const cv::Point nose(cvRound(landmarks[kNoseTipLandmark].x()), cvRound(landmarks[kNoseTipLandmark].y()));
  if (!cv::Rect(0, 0, mask->cols, mask->rows).contains(nose) || mask->at<uchar>(nose) == 0) return;
  cv::floodFill(*mask, nose, cv::Scalar(128), nullptr, cv::Scalar(), cv::Scalar(), 8);
  *mask = *mask == 128;
}

namespace {

// The half-plane on `up`'s side of the line through `point`, as a mask of `size`.
cv::Mat HalfPlane(cv::Size size, const Eigen::Vector2d& point, const Eigen::Vector2d& up) {
  const double far = 4.0 * (size.width + size.height);
  const Eigen::Vector2d along(-up.y(), up.x());
  const std::array<Eigen::Vector2d, 4> corners = {point - far * along, point + far * along,
                                                  point + far * along + far * up, point - far * along + far * up};
  std::vector<cv::Point> polygon;
  for (const Eigen::Vector2d& p : corners) polygon.emplace_back(cvRound(p.x()), cvRound(p.y()));
  cv::Mat out(size, CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(out, polygon, cv::Scalar(255));
  return out;
}

// The face's up direction in the image (brows minus chin), or nothing when degenerate.
std::optional<Eigen::Vector2d> FaceUp(const Landmarks2d& lm) {
  const Eigen::Vector2d up = 0.5 * (lm[19] + lm[24]) - lm[8];
  if (!(up.norm() > 1e-6)) return std::nullopt;
  return up.normalized();
}

// The half-plane above the brow line (landmarks 17..26, the face's up
// direction), or nothing when the landmarks are degenerate.
std::optional<cv::Mat> AboveBrows(cv::Size size, const Landmarks2d& lm) {
  const std::optional<Eigen::Vector2d> up = FaceUp(lm);
  Eigen::Vector2d brows = Eigen::Vector2d::Zero();
  for (int l = 17; l <= 26; ++l) brows += lm[l] / 10.0;
  if (!up || !brows.allFinite()) return std::nullopt;
  return HalfPlane(size, brows, *up);
}

}  // namespace

cv::Mat DilateEllipse(const cv::Mat& mask, int radius) {
  if (mask.type() != CV_8U) throw std::invalid_argument("DilateEllipse: a CV_8U mask is needed");
  if (radius <= 0) return mask.clone();
  const cv::Mat element = cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * radius + 1, 2 * radius + 1});
  auto opencv = [&] {
    cv::Mat out;
    cv::dilate(mask, out, element);
    return out;
  };
  if (radius <= kDilateEllipseOwnRadius) return opencv();  // a small element: OpenCV's walk is the faster
  // Half-width of each element row's run about the centre (-1: an empty row).
  std::vector<int> half(2 * radius + 1, -1);
  for (int i = 0; i <= 2 * radius; ++i) {
    const uint8_t* row = element.ptr<uint8_t>(i);
    int first = -1, last = -1, count = 0;
    for (int j = 0; j <= 2 * radius; ++j)
      if (row[j]) {
        if (first < 0) first = j;
        last = j;
        ++count;
      }
    if (count == 0) continue;
    if (count != last - first + 1 || first + last != 2 * radius) return opencv();  // not a centred run
    half[i] = radius - first;
  }
  // Per row, each pixel's distance to the nearest set pixel of its row (cols + 1: none).
  const int rows = mask.rows, cols = mask.cols;
  if (cols >= 65535) throw std::invalid_argument("DilateEllipse: the mask is too wide");
  const int none = cols + 1;
  cv::Mat distance(mask.size(), CV_16U);
  for (int y = 0; y < rows; ++y) {
    const uint8_t* in = mask.ptr<uint8_t>(y);
    uint16_t* d = distance.ptr<uint16_t>(y);
    int run = none;
    for (int x = 0; x < cols; ++x) {
      run = in[x] ? 0 : std::min(run + 1, none);
      d[x] = static_cast<uint16_t>(run);
    }
    run = none;
    for (int x = cols - 1; x >= 0; --x) {
      run = in[x] ? 0 : std::min(run + 1, none);
      d[x] = static_cast<uint16_t>(std::min<int>(d[x], run));
    }
  }
  cv::Mat out(mask.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < rows; ++y) {
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int i = 0; i <= 2 * radius; ++i) {
      const int source = y + i - radius;
      if (half[i] < 0 || source < 0 || source >= rows) continue;
      const uint16_t* d = distance.ptr<uint16_t>(source);
      const uint16_t w = static_cast<uint16_t>(std::min(half[i], cols));
      for (int x = 0; x < cols; ++x) o[x] |= d[x] <= w ? 255 : 0;
    }
  }
  return out;
}

void FillHairNotches(const Landmarks2d& lm, cv::Mat* mask) {
  const std::optional<cv::Mat> above_brows = AboveBrows(mask->size(), lm);
  if (!above_brows) return;
  const cv::Mat& above = *above_brows;
  cv::Mat top;
  cv::bitwise_and(*mask, above, top);
  std::vector<cv::Point> points;
  cv::findNonZero(top, points);
  if (points.size() < 3) return;
  std::vector<cv::Point> hull;
  cv::convexHull(points, hull);
  cv::Mat filled(mask->size(), CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(filled, hull, cv::Scalar(255));
  cv::bitwise_and(filled, above, filled);
  cv::bitwise_or(*mask, filled, *mask);
}

void FillSkull(const cv::Mat& silhouette, const Landmarks2d& lm, cv::Mat* mask) {
  const std::optional<cv::Mat> above = AboveBrows(mask->size(), lm);
  if (!above || silhouette.size() != mask->size()) return;
  const int radius = static_cast<int>(std::lround(kSkullInset * (0.5 * (lm[19] + lm[24]) - lm[8]).norm()));
  cv::Mat skull;
  if (radius > 0)
    cv::erode(silhouette, skull, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * radius + 1, 2 * radius + 1}));
  else
    skull = silhouette.clone();
  cv::bitwise_and(skull, *above, skull);
  cv::bitwise_or(*mask, skull, *mask);
}

cv::Mat CutTrainingMask(const cv::Mat& grabcut, const cv::Mat& silhouette, const Landmarks2d& landmarks,
                        const MatteRules& rules) {
  cv::Mat m = grabcut.clone();
  FillHairNotches(landmarks, &m);
  if (rules.fill_skull) FillSkull(silhouette, landmarks, &m);
  cv::bitwise_and(m, MatteBound(silhouette, landmarks, rules), m);
  return m;
}

cv::Mat MaskReach(const cv::Mat& silhouette, const Landmarks2d& lm, int hair_px, int side_px) {
  cv::Mat reach = DilateEllipse(silhouette, side_px);
  Eigen::Vector2d eyes = Eigen::Vector2d::Zero();
  for (int l = 36; l <= 47; ++l) eyes += lm[l] / 12.0;
  const std::optional<Eigen::Vector2d> up = FaceUp(lm);
  if (!up || !eyes.allFinite()) return reach;
  cv::Mat upper = HalfPlane(silhouette.size(), eyes, *up);
  cv::bitwise_and(upper, DilateEllipse(silhouette, hair_px), upper);
  cv::bitwise_or(reach, upper, reach);
  return reach;
}

cv::Mat MatteBound(const cv::Mat& silhouette, const Landmarks2d& landmarks, const MatteRules& rules) {
  const int size = silhouette.cols;
  cv::Mat bound = MaskReach(silhouette, landmarks, static_cast<int>(std::lround(rules.hair_margin * size)),
                            static_cast<int>(std::lround(rules.side_margin * size)));
  if (!rules.keep_neck) ClearBelowJawLine(landmarks, &bound);
  KeepHeadPiece(landmarks, &bound);
  return bound;
}

cv::Mat MatteCore(const cv::Mat& silhouette, const cv::Mat& bound, double erosion) {
  cv::Mat core;
  const int radius = static_cast<int>(std::lround(erosion * silhouette.cols));
  if (radius > 0)
    cv::erode(silhouette, core, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * radius + 1, 2 * radius + 1}));
  else
    core = silhouette.clone();
  cv::bitwise_and(core, bound, core);
  return core;
}

namespace {

// The least-squares affine map carrying `from` onto `to` (2 x P each); none
// when the points do not fix one (fewer than three, all on a line, not finite).
std::optional<cv::Matx23d> FitAffine(const Eigen::Matrix2Xd& from, const Eigen::Matrix2Xd& to) {
  if (from.cols() < 3 || from.cols() != to.cols() || !from.allFinite() || !to.allFinite()) return std::nullopt;
  Eigen::Matrix3Xd x(3, from.cols());
  x << from, Eigen::RowVectorXd::Ones(from.cols());
  const Eigen::Matrix3d normal = x * x.transpose();
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(normal);
  if (!lu.isInvertible()) return std::nullopt;
  const Eigen::Matrix<double, 2, 3> a = (to * x.transpose()) * lu.inverse();
  if (!a.allFinite()) return std::nullopt;
  return cv::Matx23d(a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2));
}

}  // namespace

cv::Mat SteadyMask(const std::vector<cv::Mat>& masks, const std::vector<Eigen::Matrix2Xd>& points,
                   const std::vector<int64_t>& frame_numbers, size_t centre, int radius) {
  if (masks.size() != points.size() || masks.size() != frame_numbers.size() || centre >= masks.size())
    throw std::invalid_argument("SteadyMask: " + std::to_string(masks.size()) + " masks, " +
                                std::to_string(points.size()) + " point sets, " + std::to_string(frame_numbers.size()) +
                                " frame numbers, centre " + std::to_string(centre));
  const cv::Mat& own = masks[centre];
  if (radius <= 0) return own.clone();
  cv::Mat sum, moved;
  own.convertTo(sum, CV_32F, static_cast<double>(radius + 1) / 255.0);
  double weights = radius + 1;
  const size_t lo = centre >= static_cast<size_t>(radius) ? centre - radius : 0;
  const size_t hi = std::min(masks.size() - 1, centre + radius);
  for (size_t i = lo; i <= hi; ++i) {
    const int64_t d = std::abs(frame_numbers[i] - frame_numbers[centre]);
    if (i == centre || d > radius) continue;
    if (masks[i].size() != own.size() || masks[i].type() != own.type())
      throw std::invalid_argument("SteadyMask: the masks differ in size or type");
    const std::optional<cv::Matx23d> affine = FitAffine(points[i], points[centre]);
    if (!affine) continue;
    cv::Mat source;
    masks[i].convertTo(source, CV_32F, 1.0 / 255.0);
    cv::warpAffine(source, moved, *affine, own.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const double w = radius + 1 - static_cast<double>(d);
    cv::scaleAdd(moved, w, sum, sum);
    weights += w;
  }
  cv::Mat steady;
  cv::threshold(sum, steady, 0.5 * weights, 255, cv::THRESH_BINARY);
  steady.convertTo(steady, CV_8U);
  return steady;
}

}  // namespace headcast
