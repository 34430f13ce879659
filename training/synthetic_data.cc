// Synthetic training samples.
#include "training/synthetic_data.h"

#include <Eigen/Geometry>
#include <algorithm>

#include "common/core/options.h"

namespace headcast {

void SyntheticDataOptions::Check() const {
  OptionsCheck c("SyntheticDataOptions");
  c.InRange("image_size", image_size, 16, 2048).InRange("fov_y_deg", fov_y_deg, 1, 150);
  c.NonNegative("noise", noise).Positive("coefficient_limit", coefficient_limit);
  c.NonNegative("base_expression", base_expression).InRange("neck_x_deg", neck_x_deg, 0, 180);
  c.InRange("neck_y_deg", neck_y_deg, 0, 180).InRange("neck_z_deg", neck_z_deg, 0, 180);
  c.InRange("jaw_max_rad", jaw_max_rad, 0, 1).Positive("distance_min", distance_min);
  c.That(distance_max >= distance_min, "distance_max must be >= distance_min");
  c.NonNegative("light_jitter", light_jitter);
  c.ThrowIfErrors();
}

SyntheticData::SyntheticData(const HeadModel& model, const SyntheticDataOptions& options,
                             const SubjectParams& base_subject, uint64_t seed)
    : model_(model), options_(options), base_(base_subject), seed_(seed), rng_(seed) {
  options.Check();
}

SyntheticSample SyntheticData::Next() { return Make(rng_); }

SyntheticSample SyntheticData::At(uint64_t index) const {
  std::mt19937_64 rng(seed_ * 1000003ull + index + 17);
  return Make(rng);
}

SyntheticSample SyntheticData::Make(std::mt19937_64& rng) const {
  const auto& o = options_;
  std::uniform_real_distribution<double> u(-1, 1), u01(0, 1);
  auto noisy = [&](double base) {
    return static_cast<float>(std::clamp(base + o.noise * u(rng), -o.coefficient_limit, o.coefficient_limit));
  };
  SyntheticSample s;
  s.subject = base_;
  s.subject.intrinsics = PinholeCamera::FromFovY(o.image_size, o.image_size, o.fov_y_deg);
  if (o.vary_identity) {
    s.subject.shape = Eigen::VectorXf(model_.num_shape());
    for (int i = 0; i < model_.num_shape(); ++i)
      s.subject.shape[i] = noisy(i < base_.shape.size() ? base_.shape[i] : 0);
    s.subject.texture = Eigen::VectorXf(model_.num_texture());
    for (int i = 0; i < model_.num_texture(); ++i)
      s.subject.texture[i] = noisy(i < base_.texture.size() ? base_.texture[i] : 0);
  }
  for (float& l : s.subject.light) l *= static_cast<float>(1 + o.light_jitter * u(rng));
  FrameParams& f = s.frame;
  f.expression = Eigen::VectorXf(model_.num_expression());
  const HeadModelData& d = model_.data();
  for (int i = 0; i < model_.num_expression(); ++i) {
    f.expression[i] = noisy(o.base_expression * u(rng));
    // Blendshape models: only coefficients the tracker gives (its soft box), so
    // the general model learns the conditioning subjects will send.
    if (d.HasExpressionRange()) f.expression[i] = std::clamp(f.expression[i], d.expression_min, d.expression_max);
  }
  const double d2r = M_PI / 180;
  f.neck =
      Eigen::Vector3f(static_cast<float>(o.neck_x_deg * d2r * u(rng)), static_cast<float>(o.neck_y_deg * d2r * u(rng)),
                      static_cast<float>(o.neck_z_deg * d2r * u(rng)));
  if (model_.JointIsArticulated(kJawJoint)) f.jaw = Eigen::Vector3f(static_cast<float>(o.jaw_max_rad * u01(rng)), 0, 0);
  if (model_.JointIsArticulated(kLeftEyeJoint)) {
    const Eigen::Vector3f gaze(static_cast<float>(0.2 * u(rng)), static_cast<float>(0.3 * u(rng)), 0);
    f.left_eye = f.right_eye = gaze;
  }
  const double distance = o.distance_min + (o.distance_max - o.distance_min) * u01(rng);
  f.SetCamFromHead(FrontalCamFromHead(distance, o.camera_yaw_deg * u(rng), o.camera_pitch_deg * u(rng)));
  // Render it.
  const HeadIdentity id = model_.MakeIdentity(s.subject.shape.cast<double>());
  HeadModelOutput posed;
  model_.Forward(id, f.expression.cast<double>(), f.HeadPose(), &posed);
  HeadRenderOptions render;
  std::copy(s.subject.light.begin(), s.subject.light.end(), render.light.begin());
  const HeadRender r = RenderHead(model_, posed.vertices, f.CamFromHead(), s.subject.intrinsics,
                                  AlbedoTexture(model_, s.subject.texture.cast<double>()), render);
  s.image_bgr = r.image_bgr;
  s.mask = r.mask;
  return s;
}

}  // namespace headcast
