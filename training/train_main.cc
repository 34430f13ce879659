// headcast-train: builds avatars. So far: `pretrain`, fitting the networks to
// synthetic head-model renders made on the fly (METHOD §5, synthetic part only;
// real-image mixing, the perceptual term, learnable offsets and the p(n)
// schedule belong to the training issue and are not here yet). Checkpoints and
// resume: --checkpoint-dir, --resume.
#include <CLI/CLI.hpp>
#include <fstream>
#include <iostream>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/timer.h"
#include "common/headmodel/head_model_io.h"
#include "training/avatar_fit.h"

namespace headcast {
namespace {

struct PretrainArgs {
  std::string head_model = "builtin", out, log_csv, preview, init;
  int resolution = 128, eval = 20;
  double neck_deg = 20;
  FitOptions fit;
  AvatarConfig config;
};

// Ground truth | avatar for a few held-out samples, stacked.
cv::Mat Preview(Avatar& avatar, const HeadModel& model, const SyntheticData& data, int count) {
  std::vector<cv::Mat> rows;
  for (int i = 0; i < count; ++i) {
    const SyntheticSample s = data.At((uint64_t{1} << 41) + i);  // neither training nor evaluation
    cv::Mat row;
    cv::hconcat(s.image_bgr, RenderSampleBgr(avatar, model, s), row);
    rows.push_back(row);
  }
  cv::Mat sheet;
  cv::vconcat(rows, sheet);
  return sheet;
}

int Pretrain(PretrainArgs& a) {
  const HeadModel model = LoadHeadModelSpec(a.head_model);
  a.config.output_size = a.resolution;
  a.config.num_shape = std::min(a.config.num_shape, model.num_shape());
  a.config.num_expression = std::min(a.config.num_expression, model.num_expression());
  a.config.num_texture = std::min(a.config.num_texture, model.num_texture());
  const SubjectParams base = DefaultSubject(model, a.resolution);
  Avatar avatar =
      a.init.empty() ? Avatar::CreateRandom(a.config, model, base, a.fit.seed) : Avatar::Load(a.init, model);
  SyntheticDataOptions data_options;
  data_options.image_size = a.resolution;
  data_options.neck_x_deg = data_options.neck_z_deg = a.neck_deg;
  data_options.neck_y_deg = a.neck_deg;
  SyntheticData data(model, data_options, base, a.fit.seed + 100);
  std::ofstream log;
  if (!a.log_csv.empty()) {
    // A resumed run appends: the curve continues where the checkpoint left it.
    const bool append = a.fit.resume && std::ifstream(a.log_csv).good();
    log.open(a.log_csv, append ? std::ios::app : std::ios::trunc);
    if (!log) throw std::runtime_error(a.log_csv + ": cannot write");
    if (!append) log << "step,loss\n";
  }
  Stopwatch watch;
  int first_step = -1;
  const FitResult fit = FitOnSynthetic(avatar, model, data, a.fit, [&](int step, float loss) {
    if (first_step < 0) {
      first_step = step;  // after a resume, not 0
      if (log.is_open() && a.fit.resume) {
        // Rows written after the checkpoint by the interrupted run are redone: drop them.
        log.close();
        std::ifstream in(a.log_csv);
        std::string line, kept;
        while (std::getline(in, line))
          if (line.rfind("step", 0) == 0 || std::atoi(line.c_str()) < first_step) kept += line + "\n";
        in.close();
        std::ofstream(a.log_csv, std::ios::trunc) << (kept.empty() ? "step,loss\n" : kept);
        log.open(a.log_csv, std::ios::app);
      }
    }
    if (log.is_open()) log << step << "," << loss << std::endl;  // flushed: a kill loses no logged step

    if (step % 50 == 0 || step + 1 == a.fit.iterations) {
      const double done = (step + 1.0 - first_step) / (a.fit.iterations - first_step);
      std::fprintf(stderr, "\rstep %d/%d  loss %.5f  %.0f s, ETA %.0f s   ", step + 1, a.fit.iterations, loss,
                   watch.ElapsedSeconds(), watch.ElapsedSeconds() * (1 - done) / std::max(done, 1e-9));
    }
  });
  std::fprintf(stderr, "\n");
  const EvalResult eval = EvaluateOnSynthetic(avatar, model, data, a.eval);
  avatar.training_summary() = {{"trained", true},
                               {"stage", "pretrain (synthetic renders of the head model only)"},
                               {"head_model", model.data().name},
                               {"iterations", a.fit.iterations},
                               {"batch", a.fit.batch},
                               {"learning_rate", a.fit.learning_rate},
                               {"seconds", fit.seconds},
                               {"samples_per_s", fit.samples_per_s},
                               {"final_loss", fit.loss.empty() ? 0.f : fit.loss.back()},
                               {"eval_psnr_db", eval.psnr_mean},
                               {"eval_samples", eval.count}};
  cv::Mat preview = Preview(avatar, model, data, 4);
  avatar.Save(a.out, preview);
  if (!a.preview.empty()) WriteImage(a.preview, preview);
  std::cout << avatar.training_summary().dump(2) << "\nwrote " << a.out << "\n";
  return 0;
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-train: build avatars"};
  app.require_subcommand(1);
  std::string log_level;
  app.add_option("--log", log_level, "log level");
  auto* pretrain = app.add_subcommand("pretrain", "fit an avatar's networks to synthetic head-model renders");
  PretrainArgs a;
  pretrain->add_option("--head-model", a.head_model, "builtin or a model .npz")->capture_default_str();
  pretrain->add_option("--resolution", a.resolution, "output size")->check(CLI::IsMember({128, 256, 512}));
  pretrain->add_option("--iterations", a.fit.iterations, "optimiser steps")->capture_default_str();
  pretrain->add_option("--batch", a.fit.batch, "samples per step")->capture_default_str();
  pretrain->add_option("--lr", a.fit.learning_rate, "Adam learning rate")->capture_default_str();
  pretrain->add_option("--seed", a.fit.seed, "random seed");
  pretrain->add_option("--neck-deg", a.neck_deg, "neck rotations drawn in +-DEG (METHOD uses up to 80)")
      ->capture_default_str();
  pretrain->add_option("--samples-per-ray", a.config.samples_per_ray, "CNeRF samples per ray")->capture_default_str();
  pretrain->add_option("--init", a.init, "continue from this .hcavatar");
  pretrain->add_option("--eval", a.eval, "held-out samples for the PSNR figure")->capture_default_str();
  pretrain->add_option("--log-csv", a.log_csv, "write the loss per step here");
  pretrain->add_option("--preview", a.preview, "write ground truth | avatar for 4 held-out samples (PNG)");
  pretrain->add_option("--out", a.out, "output .hcavatar")->required();
  pretrain->add_option("--checkpoint-dir", a.fit.checkpoint_dir, "checkpoint here (atomically) every --checkpoint-every steps");
  pretrain->add_option("--checkpoint-every", a.fit.checkpoint_every, "steps between checkpoints")->capture_default_str();
  pretrain->add_flag("--resume", a.fit.resume, "continue from the latest checkpoint in --checkpoint-dir, if any");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    if (pretrain->parsed()) return Pretrain(a);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
