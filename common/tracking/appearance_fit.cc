// Alternating linear least squares for texture and light.
#include "common/tracking/appearance_fit.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <opencv2/imgproc.hpp>

#include "common/core/options.h"
#include "common/headmodel/head_render.h"
#include "common/raster/rasterizer.h"

namespace headcast {

void AppearanceFitOptions::Check() const {
  OptionsCheck c("AppearanceFitOptions");
  c.InRange("alternations", alternations, 1, 10000).NonNegative("texture_prior", texture_prior);
  c.InRange("max_pixels_per_frame", max_pixels_per_frame, 100, 10000000).InRange("border_px", border_px, 0, 50);
  c.ThrowIfErrors();
}

namespace {

// One pixel's observation and the per-channel pieces of its prediction.
struct PixelTerms {
  Eigen::Vector3d observed;                        // RGB, 0..1
  Eigen::Matrix<double, 9, 1> sh;                  // SH basis at the normal
  Eigen::Vector3d mean_albedo;                     // RGB
  Eigen::Matrix<double, 3, Eigen::Dynamic> basis;  // RGB x T
};

}  // namespace

AppearanceFit FitAppearance(const HeadModel& model, const Eigen::VectorXd& shape,
                            const std::vector<AppearanceSample>& samples, const AppearanceFitOptions& o) {
  o.Check();
  AppearanceFit fit;
  const auto& d = model.data();
  const int T = model.has_texture() ? model.num_texture() : 0;
  // The mean albedo (unclipped: AlbedoTexture clips to [0, 1]) and each basis
  // column as textures, sampled per pixel by the rasteriser's UVs; a flat
  // albedo when the model has no texture model.
  std::vector<cv::Mat> textures;
  auto as_texture = [&](const float* values) {
    cv::Mat tex(d.texture_height, d.texture_width, CV_32FC3);
    std::copy(values, values + d.texture_mean.size(), tex.ptr<float>());
    return tex;
  };
  if (T > 0) {
    textures.push_back(as_texture(d.texture_mean.data()));
    for (int t = 0; t < T; ++t) {
      const Eigen::VectorXf column = d.texture_basis.col(t);
      textures.push_back(as_texture(column.data()));
    }
  } else {
    textures.push_back(AlbedoTexture(model));
  }
  const HeadIdentity identity = model.MakeIdentity(shape);
  std::vector<PixelTerms> pixels;
  for (const AppearanceSample& s : samples) {
    if (s.bgr.empty() || s.bgr.type() != CV_8UC3 || s.bgr.cols != s.camera.width || s.bgr.rows != s.camera.height) {
      fit.problem = "every sample needs an 8-bit BGR frame of its camera's size";
      return fit;
    }
    HeadModelOutput out;
    model.Forward(identity, s.params.expression.cast<double>(), s.params.HeadPose(), &out);
    RasterVertices v_cam;
    TransformToCamera(out.vertices, s.params.CamFromHead(), &v_cam);
    RasterBuffers buf;
    Rasterize(v_cam, d.faces, s.camera, RasterOptions{}, &buf);
    const cv::Mat normals = InterpolateVertexAttribute(buf, d.faces, model.VertexNormals(v_cam));
    std::vector<cv::Mat> sampled;
    for (const cv::Mat& tex : textures)
      sampled.push_back(T > 0 ? SampleTexture(buf, d.uv_faces, d.uvs, tex)
                              : cv::Mat(s.camera.height, s.camera.width, CV_32FC3, tex.at<cv::Vec3f>(0, 0)));
    cv::Mat use = buf.Mask();
    if (o.border_px > 0)
      cv::erode(use, use, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * o.border_px + 1, 2 * o.border_px + 1}));
    if (!s.mask.empty()) {
      if (s.mask.size() != use.size()) {
        fit.problem = "a mask does not match its frame's size";
        return fit;
      }
      use &= s.mask;
    }
    const int count = cv::countNonZero(use);
    const int stride = std::max(1, count / o.max_pixels_per_frame);
    int seen = 0;
    for (int y = 0; y < use.rows; ++y)
      for (int x = 0; x < use.cols; ++x) {
        if (!use.at<uchar>(y, x) || seen++ % stride) continue;
        Eigen::Vector3f n(normals.at<cv::Vec3f>(y, x)[0], normals.at<cv::Vec3f>(y, x)[1],
                          normals.at<cv::Vec3f>(y, x)[2]);
        if (n.norm() < 1e-6) continue;
        n.normalize();
        PixelTerms p;
        const cv::Vec3b c = s.bgr.at<cv::Vec3b>(y, x);
        // Clipped pixels (blown highlights, crushed shadows) say nothing linear.
        if (std::max({c[0], c[1], c[2]}) >= 254 || std::min({c[0], c[1], c[2]}) <= 1) continue;
        p.observed = Eigen::Vector3d(c[2], c[1], c[0]) / 255.0;
        const auto sh = ShBasis(n);
        for (int k = 0; k < 9; ++k) p.sh[k] = sh[k];
        const cv::Vec3f m = sampled[0].at<cv::Vec3f>(y, x);
        p.mean_albedo = Eigen::Vector3d(m[0], m[1], m[2]);
        p.basis.resize(3, T);
        for (int t = 0; t < T; ++t) {
          const cv::Vec3f b = sampled[t + 1].at<cv::Vec3f>(y, x);
          p.basis.col(t) = Eigen::Vector3d(b[0], b[1], b[2]);
        }
        pixels.push_back(std::move(p));
      }
  }
  fit.pixels = static_cast<int>(pixels.size());
  if (fit.pixels < 100) {
    fit.problem = "only " + std::to_string(fit.pixels) + " head pixels to fit the appearance on";
    return fit;
  }
  Eigen::VectorXd tau = Eigen::VectorXd::Zero(T);
  Eigen::Matrix<double, 3, 9> lambda = Eigen::Matrix<double, 3, 9>::Zero();
  auto albedo = [&](const PixelTerms& p) -> Eigen::Vector3d {
    if (T == 0) return p.mean_albedo;
    return p.mean_albedo + p.basis * tau;
  };
  auto rms_now = [&] {
    double ss = 0;
    for (const PixelTerms& p : pixels) {
      const Eigen::Vector3d a = albedo(p);
      for (int c = 0; c < 3; ++c) ss += std::pow(a[c] * lambda.row(c).dot(p.sh) - p.observed[c], 2);
    }
    return std::sqrt(ss / (3.0 * pixels.size()));
  };
  // Alternation crawls along the brightness trade between albedo and light, so
  // it runs until the error stops moving rather than a fixed few rounds.
  double previous = INFINITY;
  for (int round = 0; round < o.alternations; ++round) {
    // Light, per channel: I_c = a_c * (Y . lambda_c).
    for (int c = 0; c < 3; ++c) {
      Eigen::Matrix<double, 9, 9> A = Eigen::Matrix<double, 9, 9>::Zero();
      Eigen::Matrix<double, 9, 1> b = Eigen::Matrix<double, 9, 1>::Zero();
      for (const PixelTerms& p : pixels) {
        const Eigen::Matrix<double, 9, 1> row = albedo(p)[c] * p.sh;
        A.noalias() += row * row.transpose();
        b.noalias() += row * p.observed[c];
      }
      A.diagonal().array() += 1e-9 * pixels.size();
      lambda.row(c) = A.ldlt().solve(b).transpose();
    }
    if (T == 0) break;  // nothing else to fit: the light absorbs the flat albedo's scale
    // Texture: I_c = s_c * (m_c + B_c tau).
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(T, T);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(T);
    for (const PixelTerms& p : pixels)
      for (int c = 0; c < 3; ++c) {
        const double s = lambda.row(c).dot(p.sh);
        const Eigen::VectorXd row = s * p.basis.row(c).transpose();
        A.noalias() += row * row.transpose();
        b.noalias() += row * (p.observed[c] - s * p.mean_albedo[c]);
      }
    A.diagonal().array() += o.texture_prior * pixels.size();
    tau = A.ldlt().solve(b);
    const double now = rms_now();
    if (previous - now < 1e-6) break;
    previous = now;
  }
  fit.rms = rms_now();
  fit.texture = tau;
  for (int c = 0; c < 3; ++c)
    for (int k = 0; k < 9; ++k) fit.light[9 * c + k] = static_cast<float>(lambda(c, k));
  fit.ok = tau.allFinite() && lambda.allFinite();
  if (!fit.ok) fit.problem = "the appearance fit diverged";
  return fit;
}

}  // namespace headcast
