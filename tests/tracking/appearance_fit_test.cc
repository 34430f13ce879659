// Texture and light from frames with known geometry: renders of the built-in
// head with a known tau and lambda come back, and bad input is a status.
#include "common/tracking/appearance_fit.h"

#include <gtest/gtest.h>

#include <random>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"

namespace headcast {
namespace {

TEST(AppearanceFit, RecoversTextureAndLightFromRenders) {
  const HeadModel model = MakeBuiltinHead();
  ASSERT_TRUE(model.has_texture());
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd tau(model.num_texture());
  for (auto& t : tau) t = 0.6 * u(rng);
  HeadRenderOptions render;
  render.light = DefaultLighting();
  for (int c = 0; c < 3; ++c) {
    render.light[9 * c + 0] *= static_cast<float>(0.85 - 0.1 * c);  // warmer than white
    render.light[9 * c + 3] = 0.35f;                                // from the image's right
  }
  const PinholeCamera cam = PinholeCamera::FromFovY(320, 240, 40);
  std::vector<AppearanceSample> samples;
  for (double yaw : {-25.0, 0.0, 25.0}) {
    AppearanceSample s;
    s.params.expression = Eigen::VectorXf::Zero(model.num_expression());
    s.params.SetCamFromHead(FrontalCamFromHead(0.6, yaw, 0, model.rest_landmark_centroid()));
    s.camera = cam;
    HeadModelParams p;
    s.bgr = RenderHead(model, model.Forward(p).vertices, s.params.CamFromHead(), cam, AlbedoTexture(model, tau), render)
                .image_bgr;
    samples.push_back(s);
  }
  AppearanceFitOptions o;
  o.texture_prior = 1e-6;
  const AppearanceFit fit = FitAppearance(model, Eigen::VectorXd::Zero(model.num_shape()), samples, o);
  ASSERT_TRUE(fit.ok) << fit.problem;
  double light_error = 0, light_norm = 0;
  for (int i = 0; i < 27; ++i) {
    light_error = std::max(light_error, static_cast<double>(std::abs(fit.light[i] - render.light[i])));
    light_norm = std::max(light_norm, static_cast<double>(std::abs(render.light[i])));
  }
  std::printf("appearance: %d pixels, rms %.4f, |d tau| %.4f, |d lambda| %.4f of %.2f\n", fit.pixels, fit.rms,
              (fit.texture - tau).cwiseAbs().maxCoeff(), light_error, light_norm);
  EXPECT_LT(fit.rms, 0.01);  // 8-bit rounding and clipped albedo are what is left
  EXPECT_LT((fit.texture - tau).cwiseAbs().maxCoeff(), 0.05);
  EXPECT_LT(light_error, 0.05 * light_norm);
}

TEST(AppearanceFit, BadInputIsAStatus) {
  const HeadModel model = MakeBuiltinHead();
  AppearanceSample s;
  s.camera = PinholeCamera::FromFovY(320, 240, 40);
  s.bgr = cv::Mat(100, 100, CV_8UC3);
  EXPECT_FALSE(FitAppearance(model, Eigen::VectorXd::Zero(model.num_shape()), {s}).ok);
  s.bgr = cv::Mat(240, 320, CV_8UC3, cv::Scalar(0, 0, 0));
  s.params.cam_translation = Eigen::Vector3f(0, 0, -1);  // behind the camera: nothing to fit
  const AppearanceFit f = FitAppearance(model, Eigen::VectorXd::Zero(model.num_shape()), {s});
  EXPECT_FALSE(f.ok);
  EXPECT_NE(f.problem.find("head pixels"), std::string::npos) << f.problem;
}

}  // namespace
}  // namespace headcast
