// Head masks by landmark-seeded GrabCut.
#include "common/tracking/head_mask.h"

#include <opencv2/imgproc.hpp>
#include <optional>
#include <stdexcept>

#include "common/core/options.h"
#include "common/tracking/colour_cut.h"

namespace headcast {

void HeadMaskOptions::Check() const {
  OptionsCheck c("HeadMaskOptions");
  c.InRange("iterations", iterations, 1, 20).InRange("working_size", working_size, 32, 2048);
  c.InRange("hair_height", hair_height, 0, 3).InRange("head_width", head_width, 1, 3);
  c.InRange("neck_height", neck_height, 0, 3).InRange("min_face_height", min_face_height, 0, 2);
  c.InRange("background_ring", background_ring, 0, 2).InRange("refit_every", refit_every, 1, 1000);
  c.InRange("wanted_margin", wanted_margin, 0, 1).InRange("band", band, 0, 200);
  c.ThrowIfErrors();
}

namespace {

// Undecided pixels of `labels` (the working region: `roi` of the frame at
// `scale`) further than `band` working pixels from `last`'s outline, moved by
// `shift` (frame pixels), become certain: head inside it, background outside.
void SettleFarFromOutline(const cv::Mat& last, cv::Point2f shift, const cv::Rect& roi, double scale, int band,
                          cv::Mat& labels) {
  const cv::Matx23d frame_to_work(scale, 0, (shift.x - roi.x) * scale, 0, scale, (shift.y - roi.y) * scale);
  cv::Mat moved;
  cv::warpAffine(last, moved, frame_to_work, labels.size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(0));
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * band + 1, 2 * band + 1));
  cv::Mat inside, reach;
  cv::erode(moved, inside, disc, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  cv::dilate(moved, reach, disc, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  for (int y = 0; y < labels.rows; ++y) {
    uchar* l = labels.ptr<uchar>(y);
    const uchar *in = inside.ptr<uchar>(y), *near = reach.ptr<uchar>(y);
    for (int x = 0; x < labels.cols; ++x) {
      if (l[x] != cv::GC_PR_FGD && l[x] != cv::GC_PR_BGD) continue;
      if (in[x])
        l[x] = cv::GC_FGD;
      else if (!near[x])
        l[x] = cv::GC_BGD;
    }
  }
}

// The head's region of `bgr`, scaled to the working size, and GrabCut's
// seeds there; nothing when the region is too small to cut.
struct SeededRegion {
  cv::Rect roi;  // of the frame
  double scale = 1;
  cv::Mat image, seeds;          // working size
  cv::Point2f landmarks_centre;  // frame pixels
};

std::optional<SeededRegion> SeedHeadRegion(const cv::Mat& bgr, const Landmarks2d& landmarks, const HeadMaskOptions& o) {
  o.Check();
  if (bgr.empty() || bgr.type() != CV_8UC3) throw std::invalid_argument("HeadMask: an 8-bit BGR image is needed");
  std::vector<cv::Point2f> pts;
  for (const auto& p : landmarks) {
    if (!p.allFinite()) throw std::invalid_argument("HeadMask: non-finite landmarks");
    pts.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  cv::Point2f landmarks_centre(0, 0);
  for (const auto& p : pts) landmarks_centre += p * (1.0f / pts.size());
  // Face geometry from the landmarks: brow line, chin, jaw width, the face's up direction.
  const cv::Point2f chin = pts[8];
  cv::Point2f brow(0, 0);
  for (int k = 17; k <= 26; ++k) brow += pts[k] * 0.1f;
  const cv::Point2f up_vec = brow - chin;
  const float brow_to_chin = std::max(1.f, static_cast<float>(cv::norm(up_vec)));
  const cv::Point2f up = up_vec / brow_to_chin, right(-up.y, up.x);
  const float jaw_w = static_cast<float>(cv::norm(pts[16] - pts[0]));
  const float face_h = std::max(brow_to_chin, static_cast<float>(o.min_face_height) * jaw_w);
  // The probable head: an ellipse from above the hair to the chin, then the neck.
  const cv::Point2f top = brow + up * (o.hair_height * face_h);
  // A turned head extends behind the face, away from where the nose points:
  // widen the ellipse and shift it that way by the nose's offset from the jaw's middle.
  const cv::Point2f jaw_mid = (pts[0] + pts[16]) * 0.5f;
  const float turn = (pts[30] - jaw_mid).dot(right) / std::max(1.f, jaw_w);
  const cv::Point2f centre = (top + chin) * 0.5f - right * (o.turn_shift * turn * jaw_w);
  const float angle = static_cast<float>(std::atan2(up.y, up.x) * 180 / M_PI);
  const cv::RotatedRect head(
      centre,
      cv::Size2f(static_cast<float>(cv::norm(top - chin)), o.head_width * jaw_w * (1 + o.turn_widen * std::abs(turn))),
      angle);
  const cv::Point2f neck_bottom = chin - up * (o.neck_height * face_h);
  const float neck_w = 0.35f * jaw_w;
  std::vector<cv::Point> neck = {chin + right * neck_w, chin - right * neck_w, neck_bottom - right * neck_w,
                                 neck_bottom + right * neck_w};
  // Work on the region around it, scaled to about working_size across.
  cv::Rect roi = head.boundingRect() | cv::boundingRect(neck);
  const int pad = static_cast<int>(0.25 * std::max(roi.width, roi.height));
  roi = cv::Rect(roi.x - pad, roi.y - pad, roi.width + 2 * pad, roi.height + 2 * pad) &
        cv::Rect(0, 0, bgr.cols, bgr.rows);
  if (roi.width < 8 || roi.height < 8) return std::nullopt;
  const double scale = std::min(1.0, static_cast<double>(o.working_size) / std::max(roi.width, roi.height));
  cv::Mat image;
  cv::resize(bgr(roi), image, cv::Size(), scale, scale, cv::INTER_AREA);
  auto to_work = [&](cv::Point2f p) { return cv::Point2f((p.x - roi.x) * scale, (p.y - roi.y) * scale); };
  cv::Mat seeds(image.size(), CV_8U, cv::Scalar(cv::GC_BGD));
  const float ring = static_cast<float>(2 * o.background_ring * face_h * scale);
  if (ring > 0)
    cv::ellipse(
        seeds,
        cv::RotatedRect(to_work(head.center),
                        cv::Size2f(head.size.width * scale + ring, head.size.height * scale + ring), head.angle),
        cv::Scalar(cv::GC_PR_BGD), cv::FILLED);
  cv::ellipse(
      seeds,
      cv::RotatedRect(to_work(head.center), cv::Size2f(head.size.width * scale, head.size.height * scale), head.angle),
      cv::Scalar(cv::GC_PR_FGD), cv::FILLED);
  std::vector<cv::Point> neck_work;
  for (const auto& p : neck) neck_work.push_back(to_work(p));
  cv::fillConvexPoly(seeds, neck_work, cv::Scalar(cv::GC_PR_FGD));
  // The face hull (shrunk a little toward its centre) is certainly head.
  std::vector<cv::Point2f> hull_f;
  cv::convexHull(pts, hull_f);
  cv::Point2f face_centre(0, 0);
  for (const auto& p : hull_f) face_centre += p * (1.0f / hull_f.size());
  std::vector<cv::Point> hull;
  for (const auto& p : hull_f) hull.push_back(to_work(face_centre + (p - face_centre) * 0.9f));
  cv::fillConvexPoly(seeds, hull, cv::Scalar(cv::GC_FGD));
  return SeededRegion{roi, scale, image, seeds, landmarks_centre};
}

}  // namespace

cv::Mat HeadMask(const cv::Mat& bgr, const Landmarks2d& landmarks, const HeadMaskOptions& o, HeadMaskModels* carried,
                 double wanted_above_y) {
  std::optional<SeededRegion> region = SeedHeadRegion(bgr, landmarks, o);
  cv::Mat full(bgr.size(), CV_8U, cv::Scalar(0));
  if (!region) return full;
  const cv::Rect roi = region->roi;
  const double scale = region->scale;
  const cv::Mat& image = region->image;
  cv::Mat& seeds = region->seeds;
  const cv::Point2f landmarks_centre = region->landmarks_centre;
  const bool cut_with_carried =
      carried && !carried->background.empty() && carried->frames_since_fit + 1 < o.refit_every;
  if (cut_with_carried) {
    const double wanted_rows = (wanted_above_y - roi.y) * scale + o.wanted_margin * image.rows;
    const int rows = wanted_rows < image.rows ? std::max(8, static_cast<int>(std::ceil(wanted_rows))) : image.rows;
    cv::Mat cut = seeds.rowRange(0, rows).clone();              // below: the seeds' probable head
    if (o.band > 0 && carried->last_mask.size() == bgr.size())  // near the last outline, moved with the face
      SettleFarFromOutline(carried->last_mask, landmarks_centre - carried->last_centre, roi, scale, o.band, cut);
    CutWithColourModels(image.rowRange(0, rows), cut, carried->background, carried->foreground);
    cut.copyTo(seeds.rowRange(0, rows));
    ++carried->frames_since_fit;
  } else {
    cv::Mat bgd_model, fgd_model;
    LearnColourModels(image, seeds, o.iterations, &bgd_model, &fgd_model);
    // The first cut with new models is made whole (no last mask): a band
    // would keep what the old models made far from the outline. (A learning
    // kept near the last outline as well learns other models, and the masks
    // they cut differ more than the band's.)
    if (carried) *carried = {bgd_model, fgd_model, 0, {}, {}};
  }
  cv::Mat fg = (seeds == cv::GC_FGD) | (seeds == cv::GC_PR_FGD);
  // The largest connected piece only, holes filled.
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(fg, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  cv::Mat clean(fg.size(), CV_8U, cv::Scalar(0));
  if (!contours.empty()) {
    size_t best = 0;
    for (size_t i = 1; i < contours.size(); ++i)
      if (cv::contourArea(contours[i]) > cv::contourArea(contours[best])) best = i;
    cv::drawContours(clean, contours, static_cast<int>(best), cv::Scalar(255), cv::FILLED);
  }
  cv::Mat back;
  cv::resize(clean, back, roi.size(), 0, 0, cv::INTER_LINEAR);
  cv::threshold(back, back, 127, 255, cv::THRESH_BINARY);
  back.copyTo(full(roi));
  if (cut_with_carried) {
    carried->last_mask = full.clone();  // the caller may write to what it is given
    carried->last_centre = landmarks_centre;
  }
  return full;
}

HeadMaskModels LearnHeadMaskModels(const cv::Mat& bgr, const Landmarks2d& landmarks, const HeadMaskOptions& o) {
  std::optional<SeededRegion> region = SeedHeadRegion(bgr, landmarks, o);
  if (!region) throw std::invalid_argument("LearnHeadMaskModels: the head's region is too small to learn on");
  HeadMaskModels models;
  LearnColourModels(region->image, region->seeds, o.iterations, &models.background, &models.foreground, false);
  return models;
}

double MaskIou(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size()) throw std::invalid_argument("MaskIou: masks of different sizes");
  const double inter = cv::countNonZero((a > 0) & (b > 0)), uni = cv::countNonZero((a > 0) | (b > 0));
  return uni == 0 ? 1.0 : inter / uni;
}

}  // namespace headcast
