// Benchmark suite "quality": the speed switches' quality/speed trade-offs, side
// by side in one run. Each variant of the avatar is trained the same way on
// synthetic renders of the built-in head (same data, same steps), then its
// PSNR on held-out renders and its inference time are measured.
#include "bench/bench.h"
#include "common/headmodel/builtin_head.h"
#include "training/avatar_fit.h"

namespace headcast::bench {

nlohmann::json RunQualitySuite(const BenchOptions& options) {
  const HeadModel model = MakeBuiltinHead();
  const int size = options.resolution;
  const SubjectParams base = DefaultSubject(model, size);
  SyntheticDataOptions data_options;
  data_options.image_size = size;
  data_options.neck_x_deg = data_options.neck_y_deg = data_options.neck_z_deg = 20;
  FitOptions fit;
  fit.iterations = options.repeats;
  fit.batch = 4;
  struct Variant {
    std::string name;
    AvatarConfig config;
  };
  std::vector<Variant> variants;
  AvatarConfig c = AvatarConfig::Default(size);
  variants.push_back({"mesh_guided_8spp (default)", c});
  c.samples_per_ray = 4;
  variants.push_back({"mesh_guided_4spp", c});
  c.samples_per_ray = 16;
  variants.push_back({"mesh_guided_16spp", c});
  c = AvatarConfig::Default(size);
  c.sampling = SamplingMode::kUniform;
  c.samples_per_ray = 32;
  variants.push_back({"uniform_32spp", c});

  nlohmann::json out;
  out["suite"] = "quality";
  out["what"] = "each variant trained identically on synthetic built-in-head renders; PSNR on 20 held-out renders";
  out["resolution"] = size;
  out["iterations"] = fit.iterations;
  out["batch"] = fit.batch;
  nlohmann::json rows = nlohmann::json::array();
  for (const Variant& v : variants) {
    SyntheticData data(model, data_options, base, 7);
    Avatar avatar = Avatar::CreateRandom(v.config, model, base, 3);
    const TrainResult r = FitOnSynthetic(avatar, model, data, fit);
    const EvalResult e = EvaluateOnSynthetic(avatar, model, data, 20);
    nlohmann::json row = {{"variant", v.name},
                          {"psnr_db", e.psnr_mean},
                          {"inference_ms_median", e.ms_median},
                          {"train_samples_per_s", r.samples_per_s},
                          {"final_loss", r.steps.back().loss}};
    if (&v == &variants.front()) {
      // The per-frame conditioning bias is exact: same weights, switch off, same PSNR, more time.
      AvatarConfig slow = v.config;
      slow.precompute_conditioning = false;
      Avatar copy = avatar.WithRuntimeSwitches(slow);
      const EvalResult s = EvaluateOnSynthetic(copy, model, data, 20);
      row["without_precomputed_conditioning"] = {{"psnr_db", s.psnr_mean}, {"inference_ms_median", s.ms_median}};
    }
    std::fprintf(stderr, "%s: %.2f dB, %.2f ms\n", v.name.c_str(), e.psnr_mean, e.ms_median);
    rows.push_back(row);
  }
  out["variants"] = rows;
  return out;
}

}  // namespace headcast::bench
