// headcast-bench: shared pieces of the benchmark suites.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "common/core/timer.h"
#include "training/refine_options.h"

namespace headcast::bench {

// refine: the held-out frames' conditioning fitted through the avatar.
struct RefineBenchOptions {
  std::string avatar;          // .hcavatar
  std::string dataset;         // its person's prepared dataset (the held-out split)
  int every = 10;              // per frame: every this many held-out frames
  int iterations = 40;         // per frame: Adam steps from zero offsets
  int causal_every = 10;       // causal: refine on every this many frames
  int causal_iterations = 10;  // causal: steps each time
  // causal: refine only on the first this many held-out frames, then keep the
  // offsets (a calibration at the start of a call); 0: on all of them.
  int causal_until = 0;
  int refine_size = 0;     // the refinement's picture size (0: the avatar's own)
  std::string frames_dir;  // per frame: DIR/before, DIR/after as eval writes frames ("" = none)
  RefineOptions refine;
  void Check() const;
};

struct BenchOptions {
  int repeats = 200;                   // timed runs per measurement
  int warmup = 20;                     // untimed runs first
  std::string json_path;               // where to write results ("" = stdout only)
  int resolution = 256;                // render: output size
  int threads = 2;                     // render: libtorch threads
  bool compare_headnerf = false;       // render: also run the HeadNeRF-sized configuration
  std::string avatar;                  // codec: measure the PSNR the codec costs with this avatar
  std::string video;                   // track: the video to track
  std::string head_model = "builtin";  // track, train, render, ...: head model (builtin or .npz)
  std::string dataset;                 // train: a prepared dataset for the fine-tune figure; codec: its test split
  std::string recording;               // codec: a recording instead of the synthetic sequence
  int key_interval = 30;               // codec: key-frame interval
  double codec_error_m = 2e-4;         // codec: the quantisation's vertex error per step
  RefineBenchOptions refine;
  int outline_band = 8;  // outline: the band's width (HeadMaskOptions::band)
};

// Times `fn` (after warm-up) and returns microseconds per call.
SampleStats TimeUs(const BenchOptions& options, const std::function<void()>& fn);

// Adds median/p95/mean of `stats` under `prefix` (e.g. "forward_us").
void AddStats(nlohmann::json* out, const std::string& prefix, const SampleStats& stats);

nlohmann::json RunHeadModelSuite(const BenchOptions& options);
nlohmann::json RunRasterSuite(const BenchOptions& options);
nlohmann::json RunRenderSuite(const BenchOptions& options);
nlohmann::json RunQualitySuite(const BenchOptions& options);
nlohmann::json RunCodecSuite(const BenchOptions& options);
nlohmann::json RunTrackSuite(const BenchOptions& options);
nlohmann::json RunMeshFitSuite(const BenchOptions& options);
nlohmann::json RunRgbdSuite(const BenchOptions& options);
nlohmann::json RunTrainSuite(const BenchOptions& options);
nlohmann::json RunRefineSuite(const BenchOptions& options);
nlohmann::json RunOutlineSuite(const BenchOptions& options);

}  // namespace headcast::bench
