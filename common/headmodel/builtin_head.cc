// The built-in procedural head. Everything is a smooth function of a vertex's
// place on a deformed generalised cylinder (row height, angle around the
// head), so shape and expression components are exact linear displacement
// fields and landmarks/regions/albedo are looked up from the same functions.
#include "common/headmodel/builtin_head.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>

#include "common/core/options.h"

namespace headcast {
namespace {

constexpr double kPi = M_PI;
constexpr double kMouthY = -0.048;  // lip line height, m
constexpr double kMouthHalfWidth = 0.025;
constexpr double kPocketDepth = 0.026;          // how far the mouth interior reaches back, m
constexpr double kLipGap = 0.0012;              // closed lips leave a hairline, m
constexpr double kEyeX = 0.032, kEyeY = 0.030;  // eye centres (±x), m
constexpr double kEyeHalfWidth = 0.0145, kEyeUpper = 0.0062, kEyeLower = 0.0050;
constexpr double kEyeballRadius = 0.0118;
constexpr double kSocketDepth = 0.016;

double Smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}
double Gauss2(double dx, double dy, double sx, double sy) {
  return std::exp(-0.5 * (dx * dx / (sx * sx) + dy * dy / (sy * sy)));
}

// Cross-section of the head at one height: half-widths and centre.
struct Section {
  double rx, rz_front, rz_back, zc;
};

// Body profile below the cranium cap, interpolated by monotone cubic Hermite.
struct ProfileKey {
  double y;
  Section s;
};
const ProfileKey kProfile[] = {
    {0.040, {0.0770, 0.0920, 0.1000, -0.012}},  {0.020, {0.0772, 0.0935, 0.1000, -0.014}},
    {0.000, {0.0760, 0.0945, 0.0980, -0.016}},  {-0.020, {0.0735, 0.0940, 0.0940, -0.018}},
    {-0.040, {0.0680, 0.0915, 0.0860, -0.020}}, {-0.060, {0.0610, 0.0880, 0.0760, -0.022}},
    {-0.075, {0.0540, 0.0850, 0.0680, -0.024}}, {-0.088, {0.0450, 0.0790, 0.0620, -0.026}},
    {-0.098, {0.0440, 0.0620, 0.0590, -0.028}}, {-0.108, {0.0500, 0.0500, 0.0570, -0.030}},
    {-0.125, {0.0520, 0.0480, 0.0560, -0.032}}, {-0.165, {0.0560, 0.0520, 0.0590, -0.034}},
};
constexpr double kCapBottom = 0.040, kTop = 0.114, kNeckBottom = -0.165, kBottom = -0.176;

Section ProfileAt(double y) {
  const int n = sizeof(kProfile) / sizeof(kProfile[0]);
  y = std::clamp(y, kProfile[n - 1].y, kProfile[0].y);
  int i = 0;
  while (i < n - 2 && y < kProfile[i + 1].y) ++i;
  const ProfileKey& a = kProfile[i];
  const ProfileKey& b = kProfile[i + 1];
  const double h = b.y - a.y, t = (y - a.y) / h;
  auto channel = [&](auto get) {
    auto slope = [&](int k) {
      if (k <= 0 || k >= n - 1) return 0.0;  // flat at the ends: joins the cap and neck smoothly
      const double s0 = (get(kProfile[k].s) - get(kProfile[k - 1].s)) / (kProfile[k].y - kProfile[k - 1].y);
      const double s1 = (get(kProfile[k + 1].s) - get(kProfile[k].s)) / (kProfile[k + 1].y - kProfile[k].y);
      return s0 * s1 <= 0 ? 0.0 : 2 / (1 / s0 + 1 / s1);  // harmonic mean: monotone (Fritsch-Butland)
    };
    const double p0 = get(a.s), p1 = get(b.s), m0 = slope(i) * h, m1 = slope(i + 1) * h;
    const double t2 = t * t, t3 = t2 * t;
    return (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * m0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * m1;
  };
  return {channel([](const Section& s) { return s.rx; }), channel([](const Section& s) { return s.rz_front; }),
          channel([](const Section& s) { return s.rz_back; }), channel([](const Section& s) { return s.zc; })};
}

// What a head-surface row is.
enum class RowKind { kSkin, kUpperContact, kPocket, kLowerContact };
struct Row {
  double y;         // base height
  double scale;     // cross-section scale (shrinks to the poles)
  Section section;  // before scaling
  RowKind kind;
  double pocket_s;  // 0 at the upper lip contact .. 1 at the lower one
};

// Point on a cross-section at angle a (0 = front, +pi/2 = subject's left, +x).
// The front half is a flatter superellipse, as faces are.
Eigen::Vector3d SectionPoint(const Section& s, double scale, double a, double y) {
  const double c = std::cos(a), sn = std::sin(a);
  const double p = 2.0 + 0.7 * Smoothstep(0.0, 1.0, c);  // exponent: 2 at the back, 2.7 at the front
  const double ex = 2.0 / p;
  const double x = s.rx * scale * (sn < 0 ? -1 : 1) * std::pow(std::abs(sn), ex);
  const double rz = (c >= 0 ? s.rz_front : s.rz_back) * scale;
  const double z = s.zc + rz * (c < 0 ? -1 : 1) * std::pow(std::abs(c), ex);
  return {x, y, z};
}

// Eye opening (almond) mask at (x, y) for the eye at side `sx` (+1 left, -1 right):
// 1 inside the lids, 0 outside, with a thin soft edge.
double AlmondMask(double x, double y, double sx) {
  const double u = (x - sx * kEyeX) / kEyeHalfWidth;
  const double lid = (y >= kEyeY ? kEyeUpper : kEyeLower) * (1 - u * u);
  if (std::abs(u) >= 1) return 0;
  const double v = (y - kEyeY) / std::max(lid, 1e-6);
  return Smoothstep(1.08, 0.88, std::abs(v)) * Smoothstep(1.0, 0.9, std::abs(u));
}

double MouthMask(double x) { return Smoothstep(kMouthHalfWidth, kMouthHalfWidth - 0.005, std::abs(x)); }

// Facial relief added along z on the front of the head, as a function of (x, y).
double FaceRelief(double x, double y) {
  double z = 0;
  // Nose: dorsum from the bridge to the tip, then a quick fall to the base.
  const double tip_y = -0.019, bridge_y = 0.036, base_y = -0.031;
  if (y < bridge_y + 0.01 && y > base_y - 0.01) {
    const double t = std::clamp((bridge_y - y) / (bridge_y - tip_y), 0.0, 1.15);
    double height = 0.004 + 0.020 * std::pow(std::min(t, 1.0), 1.25);
    if (y < tip_y) height *= Smoothstep(base_y - 0.002, tip_y, y);  // underside of the nose
    if (y > bridge_y) height *= Smoothstep(bridge_y + 0.01, bridge_y, y);
    const double width = 0.0055 + 0.0075 * std::min(t, 1.0);
    z += height * std::exp(-std::pow(std::abs(x) / width, 2.2));
    // Alae (nostril wings).
    z += 0.006 * (Gauss2(x - 0.0135, y + 0.025, 0.0045, 0.005) + Gauss2(x + 0.0135, y + 0.025, 0.0045, 0.005));
  }
  // Brow ridge and forehead fullness.
  z += 0.005 * Gauss2(x, y - 0.047, 0.05, 0.009);
  // Eye sockets: a broad hollow around each eye.
  for (double sx : {-1.0, 1.0}) z -= 0.006 * Gauss2(x - sx * kEyeX, y - kEyeY, 0.016, 0.011);
  // Cheekbones.
  for (double sx : {-1.0, 1.0}) z += 0.005 * Gauss2(x - sx * 0.047, y + 0.004, 0.014, 0.012);
  // Lips: upper and lower lip volumes, philtrum, and the corners set in.
  const double lip_w = std::exp(-std::pow(std::abs(x) / 0.024, 3.0));
  z += 0.0055 * lip_w * Gauss2(0, y - (kMouthY + 0.0055), 1, 0.0045);
  z += 0.0060 * lip_w * Gauss2(0, y - (kMouthY - 0.0065), 1, 0.0050);
  z += 0.0030 * Gauss2(x, y - (kMouthY + 0.018), 0.012, 0.008);
  for (double sx : {-1.0, 1.0}) z -= 0.0035 * Gauss2(x - sx * 0.027, y - kMouthY, 0.005, 0.006);
  // Chin.
  z += 0.007 * Gauss2(x, y + 0.080, 0.018, 0.011);
  return z;
}

// How much of the face relief applies at angle a: only on the front.
double FrontMask(double a) { return Smoothstep(0.25, 0.75, std::cos(a)); }

// Shape and expression components are displacement fields of the base point.
struct PointContext {
  Eigen::Vector3d p;  // base position (before any component)
  double a;           // angle around the head
  RowKind kind;
  double pocket_s;
  bool eyeball;     // eyeball vertices move rigidly with their centre
  double eye_side;  // +1 left, -1 right (eyeballs only)
};
using Field = std::function<Eigen::Vector3d(const PointContext&)>;

struct NamedField {
  const char* name;
  Field field;
};

// Rows at the lip line coincide outside the mouth, so every field must move
// them alike there; inside the mouth a field may treat the interior differently.
double InteriorScale(const PointContext& c, double inside) {
  if (c.kind == RowKind::kSkin || c.eyeball) return 1;
  const double m = MouthMask(c.p.x()) * FrontMask(c.a);
  return (1 - m) + m * inside;
}

double HeadMask(double y) { return Smoothstep(-0.125, -0.095, y); }  // head, not neck
double LowerFace(const PointContext& c) {
  return Smoothstep(-0.02, -0.05, c.p.y()) * HeadMask(c.p.y()) * Smoothstep(-0.2, 0.4, std::cos(c.a));
}

std::vector<NamedField> ShapeFields() {
  return {
      {"head_width", [](const PointContext& c) { return Eigen::Vector3d(0.06 * c.p.x() * HeadMask(c.p.y()), 0, 0); }},
      {"head_height",
       [](const PointContext& c) { return Eigen::Vector3d(0, 0.06 * std::max(0.0, c.p.y() + 0.02), 0); }},
      {"head_depth",
       [](const PointContext& c) { return Eigen::Vector3d(0, 0, 0.05 * (c.p.z() + 0.015) * HeadMask(c.p.y())); }},
      {"face_length",
       [](const PointContext& c) {
         return Eigen::Vector3d(
             0, 0.08 * std::min(0.0, c.p.y()) * HeadMask(c.p.y()) * Smoothstep(-0.3, 0.3, std::cos(c.a)), 0);
       }},
      {"nose_length",
       [](const PointContext& c) {
         const double f = FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() + 0.012, 0.012, 0.02);
         return Eigen::Vector3d(0, -0.002 * f, 0.006 * f);
       }},
      {"nose_width",
       [](const PointContext& c) {
         const double f =
             FrontMask(c.a) * Gauss2(0, c.p.y() + 0.02, 1, 0.014) * Smoothstep(0.03, 0.01, std::abs(c.p.x()));
         return Eigen::Vector3d(0.15 * c.p.x() * f, 0, 0);
       }},
      {"jaw_width", [](const PointContext& c) { return Eigen::Vector3d(0.08 * c.p.x() * LowerFace(c), 0, 0); }},
      {"chin_protrusion",
       [](const PointContext& c) {
         return Eigen::Vector3d(0, 0, 0.006 * FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() + 0.082, 0.022, 0.014));
       }},
      {"eye_spacing",
       [](const PointContext& c) {
         const double sx = c.eyeball ? c.eye_side : (c.p.x() < 0 ? -1 : 1);
         const double f =
             c.eyeball ? 1.0 : FrontMask(c.a) * Gauss2(c.p.x() - sx * kEyeX, c.p.y() - kEyeY, 0.018, 0.014);
         return Eigen::Vector3d(0.0025 * sx * f, 0, 0);
       }},
      {"cheek_fullness",
       [](const PointContext& c) {
         double f = 0;
         for (double sx : {-1.0, 1.0}) f += Gauss2(c.p.x() - sx * 0.048, c.p.y() + 0.03, 0.02, 0.022);
         f *= Smoothstep(-0.3, 0.5, std::cos(c.a)) * InteriorScale(c, 0.3);
         return Eigen::Vector3d(0.004 * f * (c.p.x() < 0 ? -1 : 1), 0, 0.003 * f);
       }},
      {"brow_ridge",
       [](const PointContext& c) {
         return Eigen::Vector3d(0, 0, 0.004 * FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() - 0.046, 0.045, 0.007));
       }},
      {"lip_fullness",
       [](const PointContext& c) {
         const double f = FrontMask(c.a) * std::exp(-std::pow(std::abs(c.p.x()) / 0.024, 3.0)) *
                          Gauss2(0, c.p.y() - kMouthY, 1, 0.009);
         return Eigen::Vector3d(0, 0, 0.004 * f * InteriorScale(c, c.kind == RowKind::kPocket ? 0.0 : 1.0));
       }},
  };
}

// Eye almond mask in the rest head (before any component), used by lids.
double LidMask(const PointContext& c, double side) {
  if (c.eyeball || c.kind != RowKind::kSkin) return 0;
  return AlmondMask(c.p.x(), c.p.y(), side) * FrontMask(c.a);
}

double MouthRegion(const PointContext& c, double sigma_y) {
  return FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() - kMouthY, 0.03, sigma_y);
}

std::vector<NamedField> ExpressionFields() {
  return {
      {"smile",
       [](const PointContext& c) {
         Eigen::Vector3d d = Eigen::Vector3d::Zero();
         if (c.eyeball) return d;
         for (double sx : {-1.0, 1.0}) {
           const double g = FrontMask(c.a) * Gauss2(c.p.x() - sx * 0.027, c.p.y() - kMouthY, 0.014, 0.013);
           d += g * Eigen::Vector3d(0.005 * sx, 0.007, -0.003);
           const double cheek = FrontMask(c.a) * Gauss2(c.p.x() - sx * 0.04, c.p.y() + 0.02, 0.015, 0.013);
           d += cheek * Eigen::Vector3d(0, 0.003, 0.002);
         }
         return d;
       }},
      {"pucker",
       [](const PointContext& c) {
         const double g = c.eyeball ? 0 : FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() - kMouthY, 0.022, 0.012);
         return Eigen::Vector3d(-0.35 * c.p.x() * g, 0,
                                0.009 * g * InteriorScale(c, c.kind == RowKind::kPocket ? 0.6 : 1.0));
       }},
      {"brow_raise",
       [](const PointContext& c) {
         const double g = c.eyeball ? 0 : FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() - 0.048, 0.05, 0.012);
         return Eigen::Vector3d(0, 0.006 * g, 0);
       }},
      {"brow_frown",
       [](const PointContext& c) {
         const double g = c.eyeball ? 0 : FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() - 0.044, 0.022, 0.01);
         return Eigen::Vector3d(-0.15 * c.p.x() * g, -0.004 * g, 0.0015 * g);
       }},
      {"blink_left",
       [](const PointContext& c) {
         const double m = LidMask(c, 1);
         return Eigen::Vector3d(0, -0.0015 * m * (c.p.y() > kEyeY ? 1 : -0.5), (kSocketDepth + 0.0015) * m);
       }},
      {"blink_right",
       [](const PointContext& c) {
         const double m = LidMask(c, -1);
         return Eigen::Vector3d(0, -0.0015 * m * (c.p.y() > kEyeY ? 1 : -0.5), (kSocketDepth + 0.0015) * m);
       }},
      {"squint",
       [](const PointContext& c) {
         const double m = (LidMask(c, 1) + LidMask(c, -1)) * (c.p.y() < kEyeY - 0.001 ? 1 : 0);
         double cheek = 0;
         for (double sx : {-1.0, 1.0}) cheek += Gauss2(c.p.x() - sx * kEyeX, c.p.y() - (kEyeY - 0.012), 0.014, 0.006);
         cheek *= c.eyeball ? 0 : FrontMask(c.a);
         return Eigen::Vector3d(0, 0.002 * cheek, (kSocketDepth + 0.0015) * m + 0.001 * cheek);
       }},
      {"cheek_puff",
       [](const PointContext& c) {
         double g = 0;
         for (double sx : {-1.0, 1.0}) g += Gauss2(c.p.x() - sx * 0.043, c.p.y() + 0.04, 0.016, 0.016);
         g *= c.eyeball
                  ? 0
                  : Smoothstep(-0.2, 0.5, std::cos(c.a)) * InteriorScale(c, c.kind == RowKind::kPocket ? 0.2 : 1.0);
         return Eigen::Vector3d(0.008 * g * (c.p.x() < 0 ? -1 : 1), 0, 0.004 * g);
       }},
      {"lips_part",
       [](const PointContext& c) {
         // Opens the lips without the jaw: the upper lip up, the lower lip down.
         if (c.eyeball) return Eigen::Vector3d::Zero().eval();
         const double m = MouthMask(c.p.x()) * FrontMask(c.a);
         double dir = 0;
         if (c.kind == RowKind::kPocket)
           dir = 1 - 2 * c.pocket_s;
         else if (c.kind == RowKind::kUpperContact)
           dir = 1;
         else if (c.kind == RowKind::kLowerContact)
           dir = -1;
         else
           dir = (c.p.y() > kMouthY ? 1 : -1) * Gauss2(0, c.p.y() - kMouthY, 1, 0.008);
         return Eigen::Vector3d(0, 0.004 * dir * m, 0);
       }},
      {"mouth_left",
       [](const PointContext& c) { return Eigen::Vector3d(c.eyeball ? 0 : 0.007 * MouthRegion(c, 0.012), 0, 0); }},
      {"mouth_right",
       [](const PointContext& c) { return Eigen::Vector3d(c.eyeball ? 0 : -0.007 * MouthRegion(c, 0.012), 0, 0); }},
      {"nose_wrinkle",
       [](const PointContext& c) {
         const double g = c.eyeball ? 0 : FrontMask(c.a) * Gauss2(c.p.x(), c.p.y() + 0.022, 0.02, 0.012);
         return Eigen::Vector3d(0, 0.003 * g, 0.001 * g);
       }},
      {"lips_press",
       [](const PointContext& c) {
         const double g = c.eyeball ? 0
                                    : InteriorScale(c, c.kind == RowKind::kPocket ? 0.0 : 1.0) * FrontMask(c.a) *
                                          std::exp(-std::pow(std::abs(c.p.x()) / 0.024, 3.0)) *
                                          Gauss2(0, c.p.y() - kMouthY, 1, 0.008);
         return Eigen::Vector3d(0, 0, -0.004 * g);
       }},
  };
}

struct Builder {
  BuiltinHeadOptions options;
  std::vector<Row> rows;
  std::vector<double> angles;              // per column
  std::vector<PointContext> points;        // every vertex, base context
  std::vector<Eigen::Vector2d> uv_points;  // one per uv vertex
  std::vector<Eigen::Vector3i> faces, uv_faces;
  int head_vertices = 0;
  int top_pole = -1, bottom_pole = -1;
  std::array<int, 2> eye_begin{}, eye_end{};

  int Grid(int row, int col) const { return top_pole + 1 + (row - 1) * static_cast<int>(angles.size()) + col; }

  void MakeRows() {
    auto add = [&](double y, double scale, RowKind kind = RowKind::kSkin, double s = 0) {
      rows.push_back({y, scale, ProfileAt(y), kind, s});
    };
    // Cranium cap: rows evenly spaced in angle so the pole is well shaped.
    const int cap_rows = 16;
    for (int i = 0; i < cap_rows; ++i) {
      const double phi = 0.5 * kPi * i / cap_rows;
      add(kCapBottom + (kTop - kCapBottom) * std::cos(phi), std::sin(phi));
    }
    // Face down to the lip line, ~2.2 mm apart.
    const int upper = 40;
    for (int i = 0; i < upper; ++i) add(kCapBottom + (kMouthY - kCapBottom) * i / upper, 1);
    add(kMouthY, 1, RowKind::kUpperContact);
    const int pocket = 8;
    for (int i = 1; i < pocket; ++i) add(kMouthY, 1, RowKind::kPocket, static_cast<double>(i) / pocket);
    add(kMouthY, 1, RowKind::kLowerContact);
    // Lower face and chin, then the neck.
    const double chin_end = -0.110;
    const int lower = 28;
    for (int i = 1; i <= lower; ++i) add(kMouthY + (chin_end - kMouthY) * i / lower, 1);
    const int neck = 10;
    for (int i = 1; i <= neck; ++i) add(chin_end + (kNeckBottom - chin_end) * i / neck, 1);
    // Rounded bottom of the neck.
    for (double k : {0.85, 0.6, 0.32}) add(kNeckBottom + (kBottom - kNeckBottom) * std::sqrt(1 - k * k), k);
    rows.erase(rows.begin());  // the top row (scale 0) is replaced by the pole vertex
  }

  void MakeColumns() {
    const int n = options.columns;
    // Denser at the front (where the face is) than at the back.
    for (int i = 0; i < n; ++i) {
      const double u = -kPi + 2 * kPi * i / n;
      angles.push_back(u - 0.45 * std::sin(u) + kPi * (u < 0 ? 0 : 0));
    }
    // u = -pi..pi maps to a = -pi..pi with a' = 1 - 0.45 cos(u): 0.55 at the front, 1.45 at the back.
  }

  Eigen::Vector3d SkinPoint(const Row& row, double a) const {
    Eigen::Vector3d p = SectionPoint(row.section, row.scale, a, row.y);
    const double fm = FrontMask(a);
    if (row.scale > 0.5) p.z() += fm * FaceRelief(p.x(), p.y());
    // Eye openings: deep almond recess behind which the eyeball sits.
    for (double sx : {-1.0, 1.0}) p.z() -= kSocketDepth * AlmondMask(p.x(), p.y(), sx) * fm;
    // Ears: a flap on each side with a bowl, slightly behind the jaw hinge.
    const double s = std::sin(a);
    if (std::abs(s) > 0.6 && row.scale > 0.8) {
      const double ez = -0.030, ey = 0.004;
      const double side_z = p.z();
      const double u = (side_z - ez) / 0.016, v = (p.y() - ey) / 0.031;
      const double r = std::sqrt(u * u + v * v);
      const double flap = 0.017 * Smoothstep(1.0, 0.7, r) - 0.006 * Smoothstep(0.55, 0.15, r) +
                          0.004 * Smoothstep(0.2, 0.0, std::abs(r - 0.8));
      p.x() += (s > 0 ? 1 : -1) * flap * Smoothstep(0.6, 0.9, std::abs(s)) * (u < 0 ? 1.0 : Smoothstep(1.0, 0.0, u));
    }
    return p;
  }

  void MakeHead() {
    const int c = static_cast<int>(angles.size());
    // Top pole.
    top_pole = 0;
    points.push_back({Eigen::Vector3d(0, kTop, ProfileAt(kCapBottom).zc), 0, RowKind::kSkin, 0, false, 0});
    for (const Row& row : rows) {
      for (int j = 0; j < c; ++j) {
        const double a = angles[j];
        PointContext pc{SkinPoint(row, a), a, row.kind, row.pocket_s, false, 0};
        if (row.kind != RowKind::kSkin) {
          const double m = MouthMask(pc.p.x()) * FrontMask(a);
          if (row.kind == RowKind::kUpperContact) pc.p.y() += 0.5 * kLipGap * m;
          if (row.kind == RowKind::kLowerContact) pc.p.y() -= 0.5 * kLipGap * m;
          if (row.kind == RowKind::kPocket) {
            const double s = row.pocket_s;
            // A flattened tube: back wall kPocketDepth behind the lips,
            // roof and floor a few mm apart so an open jaw shows a cavity.
            pc.p.y() += m * ((0.5 - s) * kLipGap + 0.003 * std::sin(kPi * s) * (0.5 - s) * 4);
            pc.p.z() -= m * kPocketDepth * std::pow(std::sin(kPi * s), 0.6);
          }
        }
        points.push_back(pc);
      }
    }
    bottom_pole = static_cast<int>(points.size());
    points.push_back({Eigen::Vector3d(0, kBottom, ProfileAt(kNeckBottom).zc), kPi, RowKind::kSkin, 0, false, 0});
    head_vertices = static_cast<int>(points.size());

    // Faces: fans at the poles, quads between rows; counter-clockwise from outside.
    const int r = static_cast<int>(rows.size());
    for (int j = 0; j < c; ++j) {
      const int jn = (j + 1) % c;
      faces.push_back({top_pole, Grid(1, j), Grid(1, jn)});
      for (int i = 1; i < r; ++i) {
        faces.push_back({Grid(i, j), Grid(i + 1, j), Grid(i + 1, jn)});
        faces.push_back({Grid(i, j), Grid(i + 1, jn), Grid(i, jn)});
      }
      faces.push_back({Grid(r, j), bottom_pole, Grid(r, jn)});
    }
    // UVs: the head occupies v in [0, 0.8]; the seam column is duplicated.
    const double v_span = 0.8;
    auto uv_grid = [&](int row, int col) { return 1 + (row - 1) * (c + 1) + col; };
    uv_points.push_back({0.5, 0.0});
    for (int i = 1; i <= r; ++i)
      for (int j = 0; j <= c; ++j) uv_points.push_back({static_cast<double>(j) / c, v_span * i / (r + 1)});
    const int uv_bottom = static_cast<int>(uv_points.size());
    uv_points.push_back({0.5, v_span});
    for (int j = 0; j < c; ++j) {
      uv_faces.push_back({0, uv_grid(1, j), uv_grid(1, j + 1)});
      for (int i = 1; i < r; ++i) {
        uv_faces.push_back({uv_grid(i, j), uv_grid(i + 1, j), uv_grid(i + 1, j + 1)});
        uv_faces.push_back({uv_grid(i, j), uv_grid(i + 1, j + 1), uv_grid(i, j + 1)});
      }
      uv_faces.push_back({uv_grid(r, j), uv_bottom, uv_grid(r, j + 1)});
    }
  }

  // Eyeball centre for side sx, placed so its front sits just behind the closed-lid skin.
  Eigen::Vector3d EyeCentre(double sx) const {
    const double x = sx * kEyeX, y = kEyeY;
    // Angle whose section point has this x near the eye line (solve by bisection).
    const Section s = ProfileAt(y);
    double lo = 0, hi = 0.5 * kPi * sx;
    if (sx < 0) std::swap(lo, hi);
    for (int it = 0; it < 50; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (SectionPoint(s, 1, mid, y).x() < x)
        lo = mid;
      else
        hi = mid;
    }
    const double a = 0.5 * (lo + hi);
    const double skin_z = SectionPoint(s, 1, a, y).z() + FrontMask(a) * FaceRelief(x, y);
    return {x, y, skin_z - 0.0022 - kEyeballRadius};
  }

  void MakeEyes() {
    const int rings = 14, segs = 20;
    for (int e = 0; e < 2; ++e) {
      const double sx = e == 0 ? 1.0 : -1.0;  // left eye (joint 3) first
      const Eigen::Vector3d centre = EyeCentre(sx);
      const int first = static_cast<int>(points.size());
      eye_begin[e] = first;
      const int uv_first = static_cast<int>(uv_points.size());
      const Eigen::Vector2d uv_centre(0.1 + 0.2 * e, 0.9);
      const double uv_radius = 0.09;
      // Front pole, rings by polar angle from the front, back pole.
      auto add = [&](double theta, double phi) {
        const Eigen::Vector3d d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
        points.push_back({centre + kEyeballRadius * d, 0, RowKind::kSkin, 0, true, sx});
        uv_points.push_back(uv_centre + uv_radius * theta / kPi * Eigen::Vector2d(std::cos(phi), -std::sin(phi)));
      };
      add(0, 0);
      for (int i = 1; i < rings; ++i)
        for (int j = 0; j < segs; ++j) add(kPi * i / rings, 2 * kPi * j / segs);
      add(kPi, 0);
      const int last = static_cast<int>(points.size()) - 1;
      eye_end[e] = last + 1;
      const size_t first_face = faces.size();
      auto ring = [&](int i, int j) { return first + 1 + (i - 1) * segs + (j % segs); };
      auto uv_ring = [&](int i, int j) { return uv_first + 1 + (i - 1) * segs + (j % segs); };
      for (int j = 0; j < segs; ++j) {
        faces.push_back({first, ring(1, j + 1), ring(1, j)});
        uv_faces.push_back({uv_first, uv_ring(1, j + 1), uv_ring(1, j)});
        for (int i = 1; i < rings - 1; ++i) {
          faces.push_back({ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)});
          faces.push_back({ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)});
          uv_faces.push_back({uv_ring(i, j), uv_ring(i, j + 1), uv_ring(i + 1, j + 1)});
          uv_faces.push_back({uv_ring(i, j), uv_ring(i + 1, j + 1), uv_ring(i + 1, j)});
        }
        faces.push_back({ring(rings - 1, j), ring(rings - 1, j + 1), last});
        uv_faces.push_back({uv_ring(rings - 1, j), uv_ring(rings - 1, j + 1), uv_first + 1 + (rings - 1) * segs});
      }
      // The loops above wind clockwise seen from outside; turn them around.
      for (size_t f = first_face; f < faces.size(); ++f) {
        std::swap(faces[f][1], faces[f][2]);
        std::swap(uv_faces[f][1], uv_faces[f][2]);
      }
    }
  }

  // Evaluates a field at every vertex; eyeballs move rigidly with their centre.
  Eigen::VectorXf Evaluate(const Field& field) const {
    Eigen::VectorXf d(3 * points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      PointContext pc = points[i];
      if (pc.eyeball) pc.p = EyeCentre(pc.eye_side);
      d.segment<3>(3 * i) = field(pc).cast<float>();
    }
    return d;
  }

  // Skinning weights per vertex (root, neck, jaw, left eye, right eye).
  Eigen::Matrix<float, 1, 5> Weights(const PointContext& pc) const {
    Eigen::Matrix<float, 1, 5> w = Eigen::Matrix<float, 1, 5>::Zero();
    if (pc.eyeball) {
      w[pc.eye_side > 0 ? kLeftEyeJoint : kRightEyeJoint] = 1;
      return w;
    }
    const double y = pc.p.y();
    const double root = Smoothstep(-0.118, -0.145, y);
    // The jaw carries the chin, lower lip and the lower half of the mouth interior;
    // it fades out toward the ears and down the neck, and a little into the cheeks.
    const double front = Smoothstep(-0.05, 0.45, std::cos(pc.a));
    const double m = MouthMask(pc.p.x()) * FrontMask(pc.a);
    double jaw = 0;
    if (pc.kind == RowKind::kPocket) {
      jaw = front * ((1 - m) + m * Smoothstep(0.35, 0.65, pc.pocket_s));
    } else if (pc.kind == RowKind::kLowerContact) {
      jaw = front;
    } else if (pc.kind == RowKind::kUpperContact) {
      jaw = front * (1 - m);
    } else if (y < kMouthY) {
      jaw = front * Smoothstep(-0.122, -0.100, y);
    } else {
      jaw = front * (1 - m) * Smoothstep(kMouthY + 0.022, kMouthY, y);
    }
    jaw *= (1 - root);
    w[kRootJoint] = static_cast<float>(root);
    w[kJawJoint] = static_cast<float>(jaw);
    w[kNeckJoint] = static_cast<float>(1 - root - jaw);
    return w;
  }

  int NearestFront(double x, double y, RowKind kind = RowKind::kSkin) const {
    int best = -1;
    double best_d = 1e9;
    for (int i = 0; i < head_vertices; ++i) {
      const auto& pc = points[i];
      if (pc.kind != kind || std::cos(pc.a) < 0.3) continue;
      const double d = std::hypot(pc.p.x() - x, pc.p.y() - y);
      if (d < best_d) best_d = d, best = i;
    }
    return best;
  }
  int NearestAngle(double a, double y) const {
    int best = -1;
    double best_d = 1e9;
    for (int i = 0; i < head_vertices; ++i) {
      const auto& pc = points[i];
      if (pc.kind != RowKind::kSkin) continue;
      const double d = std::hypot(0.08 * (pc.a - a), pc.p.y() - y);
      if (d < best_d) best_d = d, best = i;
    }
    return best;
  }

  std::vector<int> LandmarkVertices() const {
    std::vector<int> ids;
    // 0..16: jaw contour from the subject's right ear to the left, through the chin.
    for (int k = 0; k <= 16; ++k) {
      const double t = (k - 8) / 8.0;  // -1 .. 1
      const double a = 1.32 * t * std::pow(std::abs(t), 0.35);
      const double y = -0.092 + 0.095 * std::pow(std::abs(t), 1.8);
      ids.push_back(NearestAngle(a, y));
    }
    // 17..26: brows, outer to inner on the subject's right, inner to outer on the left.
    const double brow_x[5] = {-0.056, -0.046, -0.035, -0.024, -0.013};
    const double brow_y[5] = {0.040, 0.0465, 0.049, 0.048, 0.0445};
    for (int k = 0; k < 5; ++k) ids.push_back(NearestFront(brow_x[k], brow_y[k]));
    for (int k = 4; k >= 0; --k) ids.push_back(NearestFront(-brow_x[k], brow_y[k]));
    // 27..30: nose bridge to tip; 31..35: nostril base right to left.
    for (double y : {0.030, 0.014, -0.002, -0.018}) ids.push_back(NearestFront(0, y));
    const double nx[5] = {-0.013, -0.0065, 0, 0.0065, 0.013};
    const double ny[5] = {-0.0275, -0.0295, -0.031, -0.0295, -0.0275};
    for (int k = 0; k < 5; ++k) ids.push_back(NearestFront(nx[k], ny[k]));
    // 36..47: eyes on the lid edges. Right eye: outer corner, upper outer, upper
    // inner, inner corner, lower inner, lower outer; left eye mirrored.
    auto eye = [&](double sx) {
      const double u[6] = {-1, -0.35, 0.35, 1, 0.35, -0.35};
      const double up[6] = {0, 1, 1, 0, -1, -1};
      for (int k = 0; k < 6; ++k) {
        const double uu = sx < 0 ? u[k] : -u[k];  // toward the nose is +x on the right eye
        const double x = sx * kEyeX + uu * kEyeHalfWidth * 0.98 * (sx < 0 ? 1 : 1);
        const double lid = (up[k] > 0 ? kEyeUpper : kEyeLower) * (1 - u[k] * u[k]);
        ids.push_back(NearestFront(x, kEyeY + up[k] * lid * 1.02));
      }
    };
    eye(-1);
    // Left eye starts at its inner corner: reorder the mirrored sequence.
    {
      const size_t base = ids.size();
      eye(1);
      std::vector<int> l(ids.begin() + base, ids.end());
      ids.resize(base);
      // mirrored order is: outer(x+), upper outer, upper inner, inner, lower inner, lower outer
      const int order[6] = {3, 2, 1, 0, 5, 4};
      for (int k : order) ids.push_back(l[k]);
    }
    // 48..59: outer lips, from the right corner over the upper lip and back along the lower.
    const double ox[12] = {-0.025, -0.017, -0.007, 0, 0.007, 0.017, 0.025, 0.017, 0.008, 0, -0.008, -0.017};
    const double oy[12] = {0, 0.0085, 0.0115, 0.0100, 0.0115, 0.0085, 0, -0.0095, -0.0125, -0.013, -0.0125, -0.0095};
    for (int k = 0; k < 12; ++k) ids.push_back(NearestFront(ox[k], kMouthY + oy[k]));
    // 60..67: inner lips on the contact rows.
    ids.push_back(NearestFront(-0.022, kMouthY, RowKind::kUpperContact));
    for (double x : {-0.009, 0.0, 0.009}) ids.push_back(NearestFront(x, kMouthY, RowKind::kUpperContact));
    ids.push_back(NearestFront(0.022, kMouthY, RowKind::kUpperContact));
    for (double x : {0.009, 0.0, -0.009}) ids.push_back(NearestFront(x, kMouthY, RowKind::kLowerContact));
    return ids;
  }

  // Mean albedo and per-component albedo offsets (RGB) of a head vertex.
  void Albedo(const PointContext& pc, Eigen::Matrix<float, 3, 6>* out) const {
    const Eigen::Vector3d skin(0.80, 0.60, 0.50), lips(0.70, 0.38, 0.38), hair(0.20, 0.14, 0.10),
        mouth(0.32, 0.09, 0.09), teeth(0.90, 0.88, 0.80), brow(0.30, 0.21, 0.16);
    const double x = pc.p.x(), y = pc.p.y(), ca = std::cos(pc.a);
    double skin_w = 1, lip_w = 0, hair_w = 0, brow_w = 0;
    Eigen::Vector3d base = skin;
    if (pc.kind == RowKind::kPocket || pc.kind == RowKind::kUpperContact || pc.kind == RowKind::kLowerContact) {
      const double m = MouthMask(x) * FrontMask(pc.a);
      const double s = pc.kind == RowKind::kPocket ? pc.pocket_s : (pc.kind == RowKind::kUpperContact ? 0 : 1);
      const double edge = std::min(s, 1 - s);
      Eigen::Vector3d inner = edge < 0.13 ? lips : ((edge < 0.3 && std::abs(x) < 0.021) ? teeth : mouth);
      base = m * inner + (1 - m) * skin;
      lip_w = m * (edge < 0.13 ? 1 : 0);
      skin_w = 1 - m;
    } else {
      // Lips: between the lip line and an outline with a gentle cupid's bow.
      const double ax = std::abs(x) / 0.026;
      const double top = kMouthY + 0.011 * (1 - ax * ax) - 0.0015 * Gauss2(x, 0, 0.004, 1) + 0.0008;
      const double bottom = kMouthY - 0.0125 * (1 - ax * ax) - 0.0008;
      if (ax < 1 && ca > 0.3)
        lip_w = Smoothstep(top + 0.0012, top - 0.0012, y) * Smoothstep(bottom - 0.0012, bottom + 0.0012, y);
      // Brows along an arc above each eye.
      for (double sx : {-1.0, 1.0}) {
        const double u = (x - sx * 0.034) / 0.024;
        if (std::abs(u) < 1.15 && ca > 0.3) {
          const double arc = 0.0475 - 0.006 * u * u - 0.002 * u * sx;
          brow_w = std::max(brow_w, Smoothstep(0.0045, 0.002, std::abs(y - arc)) * Smoothstep(1.15, 0.9, std::abs(u)));
        }
      }
      // Hair: a short crop whose line is high at the front and low at the back.
      const double line = 0.064 * Smoothstep(-0.2, 0.6, ca) + (-0.055) * Smoothstep(0.0, -0.8, ca) +
                          0.028 * (1 - Smoothstep(-0.2, 0.6, ca) - Smoothstep(0.0, -0.8, ca));
      const bool behind_ear = ca < 0.05;
      hair_w = Smoothstep(line - 0.003, line + 0.004, y) * (behind_ear || y > 0.02 ? 1 : Smoothstep(0.0, 0.02, y));
      base = skin;
      // Nostrils and a little shading in the eye corners and ears.
      for (double sx : {-1.0, 1.0}) {
        const double n = Gauss2(x - sx * 0.0075, y + 0.0295, 0.0025, 0.0016) * (ca > 0.5);
        base = (1 - n) * base + n * Eigen::Vector3d(0.30, 0.16, 0.14);
      }
      base = (1 - lip_w) * base + lip_w * lips;
      base = (1 - brow_w) * base + brow_w * brow;
      base = (1 - hair_w) * base + hair_w * hair;
      skin_w = (1 - lip_w) * (1 - brow_w) * (1 - hair_w);
    }
    double cheeks = 0;
    for (double sx : {-1.0, 1.0}) cheeks += Gauss2(x - sx * 0.045, y + 0.02, 0.018, 0.016) * (ca > 0.3);
    out->col(0) = base.cast<float>();
    out->col(1) = (skin_w * Eigen::Vector3d(-0.22, -0.20, -0.17)).cast<float>();          // skin_tone: darker
    out->col(2) = (skin_w * cheeks * Eigen::Vector3d(0.05, -0.04, -0.03)).cast<float>();  // skin_redness
    out->col(3) = (lip_w * Eigen::Vector3d(0.08, -0.08, -0.03)).cast<float>();            // lip_color
    out->col(4) = ((hair_w + brow_w) * Eigen::Vector3d(0.30, 0.22, 0.12)).cast<float>();  // hair_color: lighter
    out->col(5).setZero();                                                                // eye_color
  }

  // Albedo of an eyeball at polar angle theta from its front pole.
  void EyeAlbedo(double theta, Eigen::Matrix<float, 3, 6>* out) const {
    const Eigen::Vector3d sclera(0.93, 0.91, 0.88), iris(0.36, 0.24, 0.14), pupil(0.03, 0.03, 0.03);
    const double iris_w = Smoothstep(0.50, 0.45, theta);
    const double pupil_w = Smoothstep(0.20, 0.17, theta);
    Eigen::Vector3d c = (1 - iris_w) * sclera + iris_w * iris * (0.75 + 0.5 * theta);
    c = (1 - pupil_w) * c + pupil_w * pupil;
    out->setZero();
    out->col(0) = c.cast<float>();
    out->col(5) = (iris_w * (1 - pupil_w) * Eigen::Vector3d(-0.12, 0.10, 0.30)).cast<float>();
  }

  // Paints the mean albedo and its basis into UV space.
  void PaintTexture(HeadModelData* d) const {
    const int size = options.texture_size, channels = 3 * 6;
    std::vector<float> tex(static_cast<size_t>(size) * size * channels, 0.f);
    std::vector<uint8_t> filled(static_cast<size_t>(size) * size, 0);
    std::vector<Eigen::Matrix<float, 3, 6>> vcol(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      if (!points[i].eyeball) Albedo(points[i], &vcol[i]);
    }
    auto put = [&](int x, int y, const Eigen::Matrix<float, 3, 6>& c) {
      float* t = &tex[(static_cast<size_t>(y) * size + x) * channels];
      for (int k = 0; k < 6; ++k)
        for (int ch = 0; ch < 3; ++ch) t[k * 3 + ch] = c(ch, k);
      filled[static_cast<size_t>(y) * size + x] = 1;
    };
    for (size_t f = 0; f < faces.size(); ++f) {
      if (points[faces[f][0]].eyeball) continue;
      Eigen::Vector2d p[3];
      for (int k = 0; k < 3; ++k) p[k] = uv_points[uv_faces[f][k]] * size - Eigen::Vector2d(0.5, 0.5);
      const double area = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
      if (std::abs(area) < 1e-12) continue;
      const int x0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
      const int x1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
      const int y0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
      const int y1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const Eigen::Vector2d q(x, y);
          double b[3];
          for (int k = 0; k < 3; ++k) {
            const Eigen::Vector2d& a = p[(k + 1) % 3];
            const Eigen::Vector2d& c = p[(k + 2) % 3];
            b[k] = ((c - a).x() * (q - a).y() - (c - a).y() * (q - a).x()) / area;
          }
          if (b[0] < -1e-6 || b[1] < -1e-6 || b[2] < -1e-6) continue;
          put(x, y, b[0] * vcol[faces[f][0]] + b[1] * vcol[faces[f][1]] + b[2] * vcol[faces[f][2]]);
        }
    }
    // Eyes: painted analytically in their discs (polar angle from the UV radius).
    for (int e = 0; e < 2; ++e) {
      const Eigen::Vector2d centre(0.1 + 0.2 * e, 0.9);
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
          const Eigen::Vector2d uv((x + 0.5) / size, (y + 0.5) / size);
          const double r = (uv - centre).norm() / 0.09;
          if (r > 1.02) continue;
          Eigen::Matrix<float, 3, 6> c;
          EyeAlbedo(std::min(r, 1.0) * kPi, &c);
          put(x, y, c);
        }
    }
    // Fill unpainted texels from painted neighbours so bilinear lookups at
    // chart borders never fetch black.
    for (int pass = 0; pass < 8; ++pass) {
      std::vector<uint8_t> next = filled;
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
          if (filled[static_cast<size_t>(y) * size + x]) continue;
          for (auto [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= size || ny >= size || !filled[static_cast<size_t>(ny) * size + nx]) continue;
            std::copy_n(&tex[(static_cast<size_t>(ny) * size + nx) * channels], channels,
                        &tex[(static_cast<size_t>(y) * size + x) * channels]);
            next[static_cast<size_t>(y) * size + x] = 1;
            break;
          }
        }
      filled.swap(next);
    }
    d->texture_height = d->texture_width = size;
    d->texture_mean.resize(static_cast<size_t>(size) * size * 3);
    d->texture_basis.resize(static_cast<Eigen::Index>(size) * size * 3, 5);
    for (size_t t = 0; t < static_cast<size_t>(size) * size; ++t)
      for (int ch = 0; ch < 3; ++ch) {
        d->texture_mean[3 * t + ch] = tex[t * channels + ch];
        for (int k = 0; k < 5; ++k) d->texture_basis(3 * t + ch, k) = tex[t * channels + 3 * (k + 1) + ch];
      }
    d->texture_names = {"skin_tone", "skin_redness", "lip_color", "hair_color", "eye_color"};
  }
};

}  // namespace

void BuiltinHeadOptions::Check() const {
  OptionsCheck c("BuiltinHeadOptions");
  c.InRange("columns", columns, 32, 512).InRange("texture_size", texture_size, 32, 4096);
  c.ThrowIfErrors();
}

HeadModel MakeBuiltinHead(const BuiltinHeadOptions& options) {
  options.Check();
  Builder b;
  b.options = options;
  b.MakeRows();
  b.MakeColumns();
  b.MakeHead();
  b.MakeEyes();

  HeadModelData d;
  d.name = "builtin";
  d.description =
      "headcast's procedural stand-in head, generated by code: NOT FLAME and not learned from scans. "
      "FLAME layout (5 joints, LBS), hand-designed named shape/expression fields, mouth interior and eyeballs.";
  const int n = static_cast<int>(b.points.size());
  d.v_template.resize(n, 3);
  for (int i = 0; i < n; ++i) d.v_template.row(i) = b.points[i].p.transpose().cast<float>();
  d.faces.resize(static_cast<Eigen::Index>(b.faces.size()), 3);
  for (size_t f = 0; f < b.faces.size(); ++f) d.faces.row(f) = b.faces[f].transpose();
  d.uvs.resize(static_cast<Eigen::Index>(b.uv_points.size()), 2);
  for (size_t i = 0; i < b.uv_points.size(); ++i) d.uvs.row(i) = b.uv_points[i].transpose().cast<float>();
  d.uv_faces.resize(static_cast<Eigen::Index>(b.uv_faces.size()), 3);
  for (size_t f = 0; f < b.uv_faces.size(); ++f) d.uv_faces.row(f) = b.uv_faces[f].transpose();

  const auto shapes = ShapeFields();
  d.shapedirs.resize(3 * n, static_cast<Eigen::Index>(shapes.size()));
  for (size_t k = 0; k < shapes.size(); ++k) {
    d.shapedirs.col(k) = b.Evaluate(shapes[k].field);
    d.shape_names.push_back(shapes[k].name);
  }
  const auto exprs = ExpressionFields();
  d.expressiondirs.resize(3 * n, static_cast<Eigen::Index>(exprs.size()));
  for (size_t k = 0; k < exprs.size(); ++k) {
    d.expressiondirs.col(k) = b.Evaluate(exprs[k].field);
    d.expression_names.push_back(exprs[k].name);
  }
  d.posedirs = Eigen::MatrixXf::Zero(3 * n, kNumPoseFeatures);  // no pose correctives

  d.weights.resize(n, kNumHeadJoints);
  for (int i = 0; i < n; ++i) d.weights.row(i) = b.Weights(b.points[i]);

  // Joints as averages of vertex sets, so they follow the shape components.
  d.j_regressor = Eigen::MatrixXf::Zero(kNumHeadJoints, n);
  auto ring_at = [&](double y) {
    std::vector<int> ids;
    size_t best = 0;
    for (size_t r = 0; r < b.rows.size(); ++r)
      if (std::abs(b.rows[r].y - y) < std::abs(b.rows[best].y - y)) best = r;
    for (size_t j = 0; j < b.angles.size(); ++j) ids.push_back(b.Grid(static_cast<int>(best) + 1, static_cast<int>(j)));
    return ids;
  };
  auto set_joint = [&](int joint, const std::vector<int>& ids) {
    for (int id : ids) d.j_regressor(joint, id) = 1.0f / ids.size();
  };
  set_joint(kRootJoint, ring_at(-0.150));
  set_joint(kNeckJoint, ring_at(-0.100));
  {
    // Jaw hinge: midpoint of two side points just below and in front of the ears.
    std::vector<int> hinge;
    for (double a : {1.45, -1.45}) {
      int best = -1;
      double bd = 1e9;
      for (int i = 0; i < b.head_vertices; ++i) {
        const auto& pc = b.points[i];
        if (pc.kind != RowKind::kSkin) continue;
        const double dd = std::hypot(0.08 * (pc.a - a), pc.p.y() + 0.022);
        if (dd < bd) bd = dd, best = i;
      }
      hinge.push_back(best);
    }
    set_joint(kJawJoint, hinge);
  }
  for (int e = 0; e < 2; ++e) {
    std::vector<int> ids;
    for (int i = b.eye_begin[e]; i < b.eye_end[e]; ++i) ids.push_back(i);
    set_joint(e == 0 ? kLeftEyeJoint : kRightEyeJoint, ids);
  }

  // Landmarks: fixed vertices, expressed as a face corner with barycentric (1, 0, 0).
  const std::vector<int> lmk = b.LandmarkVertices();
  d.lmk_faces = Eigen::VectorXi::Constant(kNumLandmarks, -1);
  d.lmk_bary = RowMatrixX3f::Zero(kNumLandmarks, 3);
  for (int l = 0; l < kNumLandmarks; ++l) {
    // Prefer a non-degenerate face (the mouth pocket has zero-area ones).
    for (bool allow_degenerate : {false, true}) {
      for (int f = 0; f < static_cast<int>(b.faces.size()) && d.lmk_faces[l] < 0; ++f) {
        const auto& face = b.faces[f];
        const int corner = face[0] == lmk[l] ? 0 : face[1] == lmk[l] ? 1 : face[2] == lmk[l] ? 2 : -1;
        if (corner < 0) continue;
        const Eigen::Vector3d e1 = b.points[face[1]].p - b.points[face[0]].p,
                              e2 = b.points[face[2]].p - b.points[face[0]].p;
        if (!allow_degenerate && e1.cross(e2).norm() < 1e-10) continue;
        d.lmk_faces[l] = f;
        d.lmk_bary(l, corner) = 1;
      }
    }
  }
  b.PaintTexture(&d);
  return HeadModel(std::move(d));
}

}  // namespace headcast
