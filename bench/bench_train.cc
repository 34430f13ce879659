// Benchmark suite "train": training throughput (samples per second) of
// pretraining the general model and of a subject fine-tune at one resolution.
#include <optional>

#include "bench/bench.h"
#include "common/headmodel/head_model_io.h"
#include "training/avatar_fit.h"
#include "training/image_losses.h"
#include "training/runs.h"

namespace headcast::bench {

nlohmann::json RunTrainSuite(const BenchOptions& o) {
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  const AvatarConfig config = FitConfigToModel(AvatarConfig::Default(o.resolution), model);
  const SubjectParams subject = DefaultSubject(model, o.resolution);
  SyntheticDataOptions so;
  so.image_size = o.resolution;
  FitOptions fit;
  fit.iterations = o.repeats;
  fit.batch = 4;
  nlohmann::json out = {{"suite", "train"},   {"resolution", o.resolution},   {"head_model", model.data().name},
                        {"batch", fit.batch}, {"iterations", fit.iterations}, {"config", config.ToJson()}};
  auto timed = [&](Avatar& avatar, const TrainingData& data, const FitOptions& f) {
    FitOptions warm = f;
    warm.iterations = 2;  // first-call allocations are not throughput
    Avatar copy = avatar.WithRuntimeSwitches(avatar.config());
    TrainAvatar(copy, model, data, warm);
    return TrainAvatar(avatar, model, data, f);
  };
  // Pretraining: every parameter trained on renders of varied people.
  {
    SyntheticData data(model, so, subject, 1);
    Avatar avatar = Avatar::CreateRandom(config, model, subject, 1);
    const TrainResult r = timed(avatar, TrainingData{&data, {}}, fit);
    out["pretrain_samples_per_s"] = r.samples_per_s;
    out["pretrain_ms_per_step"] = 1e3 * r.seconds / fit.iterations;
  }
  // Fine-tune as `headcast-train subject` does (its frozen CNeRF layers and
  // region weights, beta/tau frozen); on a prepared dataset's frames when
  // given, else on the subject's own renders.
  {
    const SubjectOptions subject_defaults;
    so.vary_identity = false;
    SyntheticData data(model, so, subject, 2);
    std::optional<PreparedDataset> real;
    if (!o.dataset.empty()) real = PreparedDataset::Load(o.dataset, model, o.resolution);
    Avatar avatar = Avatar::CreateRandom(config, model, real ? real->subject() : subject, 1);
    FitOptions f = fit;
    f.freeze_identity = true;
    f.freeze_cnerf_layers = subject_defaults.freeze_layers;
    f.loss.regions = SubjectFitDefaults().loss.regions;
    f.mix = MixSchedule{0, std::max(1, fit.iterations), 0.0, 0.25};
    TrainingData samples{&data, {}};
    if (real) samples.real.push_back(&*real);
    const TrainResult r = timed(avatar, samples, f);
    out["finetune_samples_per_s"] = r.samples_per_s;
    out["finetune_ms_per_step"] = 1e3 * r.seconds / fit.iterations;
    out["finetune_data"] = real ? "prepared dataset " + o.dataset + " (real frames, 25 % renders falling to 0)"
                                : "the subject's own renders (no --data given)";
  }
  // The SSIM term's forward and backward pass on one output-sized image, the
  // separable window the training uses beside the 2D window, alternating.
  {
    torch::manual_seed(1);
    const torch::Tensor target = torch::rand({1, 3, o.resolution, o.resolution});
    SampleStats separable, full;
    for (int i = 0; i < 41; ++i) {
      for (const bool sep : {true, false}) {
        const torch::Tensor x = torch::rand({1, 3, o.resolution, o.resolution}).requires_grad_(true);
        Stopwatch watch;
        (sep ? Ssim(x, target) : SsimFullWindow(x, target)).backward();
        if (i > 0) (sep ? separable : full).Add(watch.ElapsedMs());  // the first is warm-up
      }
    }
    out["ssim_ms_median"] = separable.Median();
    out["ssim_full_window_ms_median"] = full.Median();
  }
  out["threads"] = torch::get_num_threads();
  return out;
}

}  // namespace headcast::bench
