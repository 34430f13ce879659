// headcast-bench: runs one benchmark suite, prints its figures and how to reproduce them.
#include <CLI/CLI.hpp>
#include <fstream>
#include <iostream>
#include <thread>

#include "bench/bench.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"

namespace headcast::bench {

SampleStats TimeUs(const BenchOptions& options, const std::function<void()>& fn) {
  for (int i = 0; i < options.warmup; ++i) fn();
  SampleStats stats;
  for (int i = 0; i < options.repeats; ++i) {
    Stopwatch watch;
    fn();
    stats.Add(watch.ElapsedUs());
  }
  return stats;
}

void AddStats(nlohmann::json* out, const std::string& prefix, const SampleStats& s) {
  (*out)[prefix + "_median"] = s.Median();
  (*out)[prefix + "_p95"] = s.Percentile(95);
  (*out)[prefix + "_mean"] = s.Mean();
  (*out)[prefix + "_samples"] = s.count();
}

}  // namespace headcast::bench

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-bench: benchmark suites; each prints JSON with its figures"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  app.require_subcommand(1);
  bench::BenchOptions options;
  auto add_common = [&](CLI::App* sub) {
    sub->add_option("--json", options.json_path, "write the results to this JSON file");
    sub->add_option("--repeats", options.repeats, "timed runs per figure")->check(CLI::Range(1, 1000000));
    sub->add_option("--warmup", options.warmup, "untimed runs first")->check(CLI::Range(0, 1000000));
  };
  auto* headmodel = app.add_subcommand("headmodel", "head-model forward pass (Eigen, one frame)");
  auto* raster = app.add_subcommand("raster", "CPU rasteriser on a head mesh");
  auto* render = app.add_subcommand("render", "avatar synthesis (random-initialised default avatar)");
  add_common(headmodel);
  add_common(raster);
  auto* quality =
      app.add_subcommand("quality", "quality/speed trade-offs of the avatar's speed switches (trains variants)");
  add_common(render);
  add_common(quality);
  auto* codec = app.add_subcommand("codec", "parameter codec: bits per frame and added error");
  add_common(codec);
  auto* track = app.add_subcommand("track", "tracking cost per frame on a video (face tracker + fit)");
  add_common(track);
  track->add_option("--video", options.video, "video to track")->required();
  track->add_option("--head-model", options.head_model, "builtin or a model .npz");
  track->add_option("--avatar", options.avatar,
                    "an .hcavatar carrying a photometric anchor (prepared with one): also track as the sender does "
                    "with it, side by side");
  auto* outline = app.add_subcommand(
      "outline", "the sender's hair outline per frame: the whole head region cut against a band near the last outline");
  outline->add_option("--json", options.json_path, "write the results to this JSON file");
  outline->add_option("--video", options.video, "video to track")->required();
  outline->add_option("--avatar", options.avatar, "the .hcavatar the sender takes its camera and identity from")
      ->required();
  outline->add_option("--head-model", options.head_model, "builtin or a model .npz");
  outline->add_option("--frames", options.repeats, "the video's first N frames (0: all)")
      ->check(CLI::Range(0, 1000000));
  outline->add_option("--outline-band", options.outline_band, "the band's width, working pixels")
      ->check(CLI::Range(1, 200))
      ->capture_default_str();
  headmodel->add_option("--head-model", options.head_model, "also time this model .npz (builtin: only the built-in)");
  render->add_option("--head-model", options.head_model,
                     "builtin or a model .npz: the head the random avatars are made for (its expression count sets "
                     "the texture blendshapes' cost)");
  auto* meshfit = app.add_subcommand("meshfit", "head model fitted to synthetic scans: weights vs uniform, topologies");
  meshfit->add_option("--trials", options.repeats, "scans per figure")->check(CLI::Range(1, 1000));
  meshfit->add_option("--json", options.json_path, "write the results to this JSON file");
  meshfit->add_option("--head-model", options.head_model, "builtin or a model .npz");
  auto* rgbd = app.add_subcommand("rgbd", "RGB-D fit per frame on a rendered sequence: ms, accuracy, position error");
  rgbd->add_option("--frames", options.repeats, "frames per noise level")->check(CLI::Range(2, 100000));
  rgbd->add_option("--json", options.json_path, "write the results to this JSON file");
  auto* train = app.add_subcommand("train", "training throughput: pretraining and subject fine-tune, samples/s");
  train->add_option("--resolution", options.resolution, "output size")->check(CLI::IsMember({128, 256, 512}));
  train->add_option("--iterations", options.repeats, "timed steps (batch 4)")->check(CLI::Range(1, 100000));
  train->add_option("--head-model", options.head_model, "builtin or a model .npz");
  train->add_option("--data", options.dataset, "a prepared dataset (headcast-train prep) for the fine-tune figure");
  train->add_option("--json", options.json_path, "write the results to this JSON file");
  auto* refine = app.add_subcommand(
      "refine", "held-out frames' conditioning fitted through the avatar to their own pixels: the PSNR it gives back");
  refine->add_option("--avatar", options.refine.avatar, "an .hcavatar")->required();
  refine->add_option("--data", options.refine.dataset, "its person's prepared dataset (the held-out split is used)")
      ->required();
  refine->add_option("--head-model", options.head_model, "the model .npz the avatar was made with");
  refine->add_option("--every", options.refine.every, "per frame: every this many held-out frames");
  refine->add_option("--iterations", options.refine.iterations, "per frame: Adam steps from zero offsets");
  refine->add_option("--causal-every", options.refine.causal_every, "causal: refine on every this many frames");
  refine->add_option("--causal-iterations", options.refine.causal_iterations, "causal: steps each time");
  refine->add_option("--causal-until", options.refine.causal_until,
                     "causal: refine only on the first this many held-out frames, then keep the offsets (0: all)");
  refine->add_option("--lr", options.refine.refine.learning_rate, "Adam's rate");
  refine->add_option("--refine-size", options.refine.refine_size,
                     "the refinement draws this size (its offsets scored at the avatar's own; 0: the avatar's)");
  refine->add_option("--offset-weight", options.refine.refine.offset_weight, "weight of the offsets' sum of squares");
  refine->add_option("--codes", options.refine.refine.codes, "which codes take offsets")
      ->check(CLI::IsMember({"all", "expression", "joints", "lighting"}));
  refine->add_option("--write-frames", options.refine.frames_dir,
                     "per frame: the truth and the picture before and after, in DIR/before and DIR/after as eval "
                     "--write-frames writes them");
  refine->add_option("--threads", options.threads, "libtorch threads")->check(CLI::Range(1, 64));
  refine->add_option("--json", options.json_path, "write the results to this JSON file");
  codec->add_option("--recording", options.recording,
                    "a parameter recording (.hcrec) instead of the synthetic sequence");
  codec->add_option("--head-model", options.head_model, "builtin or the model .npz the recording was made with");
  codec->add_option("--avatar", options.avatar,
                    "an .hcavatar of that head model: also report the PSNR the codec costs");
  codec->add_option("--data", options.dataset,
                    "a prepared dataset (headcast-train prep) of the avatar's person: the cost on its held-out frames");
  codec->add_option("--resolution", options.resolution, "the dataset's crops to use")
      ->check(CLI::IsMember({128, 256, 512}));
  codec->add_option("--key-interval", options.key_interval, "a key frame at least this often, frames")
      ->check(CLI::Range(1, 100000));
  codec
      ->add_option("--quantisation-error", options.codec_error_m,
                   "quantisation: one step of a value moves no vertex more than this, metres")
      ->check(CLI::Range(1e-6, 1e-2));
  quality->add_option("--resolution", options.resolution, "output size")->check(CLI::IsMember({128, 256, 512}));
  quality->add_option("--iterations", options.repeats, "training steps per variant (batch 4)");
  render->add_option("--resolution", options.resolution, "output size")->check(CLI::IsMember({128, 256, 512}));
  render->add_option("--threads", options.threads, "libtorch threads")->check(CLI::Range(1, 64));
  render->add_flag("--compare-headnerf", options.compare_headnerf,
                   "also time a HeadNeRF-sized configuration (256 only)");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging("warn");
    if (train->parsed() && train->count("--iterations") == 0) options.repeats = 30;
    if (outline->parsed() && outline->count("--frames") == 0) options.repeats = 0;
    if (render->parsed() && options.compare_headnerf && options.resolution != 256)
      throw std::invalid_argument("--compare-headnerf is defined at --resolution 256 (HeadNeRF's 32x32 feature map)");
    nlohmann::json result = headmodel->parsed() ? bench::RunHeadModelSuite(options)
                            : raster->parsed()  ? bench::RunRasterSuite(options)
                            : render->parsed()  ? bench::RunRenderSuite(options)
                            : codec->parsed()   ? bench::RunCodecSuite(options)
                            : track->parsed()   ? bench::RunTrackSuite(options)
                            : meshfit->parsed() ? bench::RunMeshFitSuite(options)
                            : rgbd->parsed()    ? bench::RunRgbdSuite(options)
                            : train->parsed()   ? bench::RunTrainSuite(options)
                            : refine->parsed()  ? bench::RunRefineSuite(options)
                            : outline->parsed() ? bench::RunOutlineSuite(options)
                                                : bench::RunQualitySuite(options);
    std::string cmd = "build/bin/headcast-bench";
    for (int i = 1; i < argc; ++i) cmd += std::string(" ") + argv[i];
    result["command"] = cmd;
    result["machine"] = {{"hardware_threads", std::thread::hardware_concurrency()}};
    const std::string text = result.dump(2);
    std::cout << text << "\n";
    if (!options.json_path.empty()) {
      std::ofstream out(options.json_path);
      if (!out) throw std::runtime_error(options.json_path + ": cannot write");
      out << text << "\n";
    }
    std::cerr << "reproduce: " << cmd << "\n";  // stdout is the JSON alone
  } catch (const std::exception& e) {
    std::cerr << "headcast-bench: " << headcast::InFlagNames(app, e.what()) << "\n";
    return 1;
  }
  return 0;
}
