#include "training/create.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "common/core/image_io.h"
#include "common/core/options.h"
#include "common/core/shipped_models.h"
#include "common/core/timer.h"
#include "training/dataset.h"
#include "training/run_report.h"
#include "training/runs.h"

namespace headcast {
namespace fs = std::filesystem;

void CreateOptions::Check() const {
  OptionsCheck c("CreateOptions");
  c.That(!input.empty(), "input is required").That(!out.empty(), "out is required");
  c.InRange("iterations", iterations, 1, 1000000);
  c.That(resolution == 128 || resolution == 256 || resolution == 512, "resolution is 128, 256 or 512");
  c.NonNegative("max_frames", max_frames).InRange("test_frames", test_frames, 1, 100000);
  c.InRange("processes", processes, 1, 64).InRange("record_s", record_s, 0.0, 3600.0);
  c.That(stop_after.empty() || stop_after == "record" || stop_after == "prep" || stop_after == "fine-tune",
         "stop_after is record, prep or fine-tune");
  c.ThrowIfErrors();
  source.Check();
}

bool IsCameraInput(const std::string& input) {
  return input.rfind("/dev/video", 0) == 0 || input.rfind("v4l2:", 0) == 0;
}

namespace {

// Seconds a stage takes on two cores, to tell the user how long the whole run
// will be before it starts; corrected by what the finished stages took.
// Measured with bench/four_clips.sh (prep of ~590 frames in 92 s; 2000 steps
// at 256² in 830 s with two processes) and this command's own runs.
constexpr double kPrepSecondsPerFrame = 0.16;
constexpr double kStepSeconds256 = 0.42;     // two single-threaded ranks
constexpr double kOneProcessSlowdown = 1.8;  // one process with libtorch's threads
constexpr double kEvalSecondsPerFrame = 0.6;

struct Plan {
  std::string name;
  double predicted_s;
};

// The work folder's record of finished stages and the options they were made
// with (create.json, replaced atomically after every stage).
class CreateState {
 public:
  CreateState(const fs::path& dir, nlohmann::json settings) : path_(dir / "create.json") {
    state_ = {{"format", "headcast-create"}, {"settings", std::move(settings)}, {"stages", nlohmann::json::object()}};
  }
  bool Exists() const { return fs::exists(path_); }
  // Loads the record of an earlier run; refuses one made with other settings.
  void Resume() {
    nlohmann::json old;
    try {
      old = nlohmann::json::parse(std::ifstream(path_));
    } catch (const std::exception& e) {
      throw std::runtime_error(path_.string() + ": unreadable (" + e.what() + "); remove its folder to start again");
    }
    if (old.value("format", "") != "headcast-create")
      throw std::runtime_error(path_.string() + ": not a headcast-train create record");
    for (const auto& [key, value] : state_["settings"].items())
      if (old["settings"].value(key, nlohmann::json()) != value)
        throw std::runtime_error(path_.parent_path().string() + " was made with " + key + " = " +
                                 old["settings"].value(key, nlohmann::json()).dump() + ", not " + value.dump() +
                                 ": give the same options to resume, or remove the folder to start again");
    state_["stages"] = old["stages"];
  }
  bool Done(const std::string& stage) const { return state_["stages"].contains(stage); }
  const nlohmann::json& Stage(const std::string& stage) const { return state_["stages"].at(stage); }
  void Finish(const std::string& stage, double seconds, nlohmann::json report) {
    state_["stages"][stage] = {{"seconds", seconds}, {"report", std::move(report)}};
    const fs::path tmp = path_.string() + ".tmp";
    std::ofstream(tmp) << state_.dump(2) << "\n";
    fs::rename(tmp, path_);
  }

 private:
  fs::path path_;
  nlohmann::json state_;
};

std::string DefaultWorkDir(const std::string& out) {
  fs::path p(out);
  return (p.parent_path() / (p.stem().string() + ".create")).string();
}

// The input's frame count as far as it can be known before reading it all.
int EstimateFrames(const CreateOptions& o, const std::string& input) {
  int frames = 0;
  if (fs::is_directory(input)) {
    frames = static_cast<int>(ListImageFiles(input).size());
  } else if (fs::is_regular_file(input)) {
    try {
      frames = VideoReader(input).frame_count();
    } catch (const std::exception&) {
      frames = 0;  // prep will say what is wrong with it
    }
  }
  if (frames <= 0) frames = 600;
  return o.max_frames > 0 ? std::min(frames, o.max_frames) : frames;
}

// Fine-tune steps an interrupted run already made (its latest checkpoint).
int CheckpointedSteps(const fs::path& work) {
  std::ifstream latest(work / "checkpoints" / "LATEST");
  std::string name;
  if (!std::getline(latest, name) || name.rfind("step-", 0) != 0) return 0;
  try {
    return std::stoi(name.substr(5));
  } catch (const std::exception&) {
    return 0;  // a damaged name: the fine-tune itself will say so
  }
}

struct Models {
  std::string head_model, general;
};

Models ResolveModels(const CreateOptions& o) {
  Models m{o.head_model, o.general};
  if (m.head_model.empty()) {
    m.head_model = ShippedModelPath("ict_facekit.npz");
    if (m.general.empty()) m.general = ShippedModelPath("ict_general.hcavatar");
  } else if (m.general.empty()) {
    if (m.head_model != "builtin")
      throw std::invalid_argument("--head-model " + m.head_model +
                                  " needs --general: a general model pretrained for it (headcast-train pretrain "
                                  "--head-model " +
                                  m.head_model + " ...)");
    m.general = ShippedModelPath("builtin_general.hcavatar");
  }
  return m;
}

SubjectOptions MakeSubjectOptions(const CreateOptions& o, const Models& m, const fs::path& work) {
  SubjectOptions s;
  s.head_model = m.head_model;
  s.general = m.general;
  s.dataset = (work / "dataset").string();
  s.resolution = o.resolution;
  ApplySubjectDefaults(&s.config);
  s.fit.iterations = o.iterations;
  s.fit.weight_average = SubjectWeightAverage(o.iterations);
  // As bench/four_clips.sh: a fixed camera distance, no distance augmentation.
  s.fit.z_augmentation = 0;
  s.fit.checkpoint_dir = (work / "checkpoints").string();
  fs::create_directories(s.fit.checkpoint_dir);
  s.fit.resume = true;  // from the latest checkpoint, if an interrupted run left one
  s.fit.threads = o.threads;
  s.outputs.out = o.out;
  s.outputs.log_csv = (work / "loss.csv").string();
  s.outputs.eval_csv = (work / "eval.csv").string();
  s.outputs.eval_every = std::max(100, o.iterations / 5);
  s.outputs.plot_dir = (work / "plots").string();
  s.outputs.preview = (work / "preview.png").string();
  s.outputs.report = (work / "fine_tune.json").string();
  return s;
}

std::string Quoted(const std::string& s) { return s.find_first_of(" '\"$\\") == std::string::npos ? s : "'" + s + "'"; }

// What the figures and the summary show of the eval report.
nlohmann::json HeldOut(const nlohmann::json& eval) {
  nlohmann::json h = {{"frames", eval["eval"].value("frames", 0)},
                      {"psnr_db", eval["eval"].value("psnr_db", 0.0)},
                      {"ssim", eval["eval"].value("ssim", 0.0)}};
  if (eval.contains("expression_fidelity") && eval["expression_fidelity"].contains("result")) {
    const auto& r = eval["expression_fidelity"]["result"];
    if (r.contains("error_iod")) h["landmark_error_iod"] = r["error_iod"];
    if (r.contains("blink")) h["blink_correlation"] = r["blink"].value("correlation", 0.0);
  }
  return h;
}

}  // namespace

nlohmann::json RunCreate(const CreateOptions& options, const CreateHooks& hooks) {
  options.Check();
  const Models models = ResolveModels(options);
  const fs::path work = options.work_dir.empty() ? DefaultWorkDir(options.out) : options.work_dir;

  // The fine-tune's other ranks: the stages before have finished (rank 0 starts them after prep).
  if (options.distributed.rank > 0) {
    SubjectOptions s = MakeSubjectOptions(options, models, work);
    s.fit.distributed = options.distributed;
    RunSubject(s);
    return {};
  }

  const bool camera = IsCameraInput(options.input);
  if (!camera && !fs::exists(options.input))
    throw std::runtime_error(options.input + ": no such video file or image folder");
  const double record_s = options.record_s > 0 ? options.record_s : (camera ? 60.0 : 0.0);
  CreateState state(work, {{"input", options.input},
                           {"head_model", models.head_model},
                           {"general", models.general},
                           {"iterations", options.iterations},
                           {"resolution", options.resolution},
                           {"max_frames", options.max_frames},
                           {"test_frames", options.test_frames},
                           {"identity_from", options.identity_from},
                           {"shape_prior", options.shape_prior},
                           {"record_s", record_s}});
  if (state.Exists()) {
    if (!options.resume)
      throw std::runtime_error(work.string() + " holds an earlier create: --resume continues it, or remove it");
    state.Resume();
    spdlog::info("create: resuming in {}", work.string());
  }
  fs::create_directories(work);

  const std::string frames_input = record_s > 0 ? (work / "recording").string() : options.input;
  const int frames =
      record_s > 0 ? static_cast<int>(record_s * options.source.fps) : EstimateFrames(options, frames_input);
  const int used = options.max_frames > 0 ? std::min(frames, options.max_frames) : frames;
  const double step_s = kStepSeconds256 * std::pow(options.resolution / 256.0, 2) *
                        (options.processes > 1 ? 2.0 / std::min(options.processes, 2) : kOneProcessSlowdown);
  std::vector<Plan> plan;
  if (record_s > 0) plan.push_back({"record", record_s});
  plan.push_back({"prep", used * kPrepSecondsPerFrame});
  plan.push_back({"fine-tune", std::max(0, options.iterations - CheckpointedSteps(work)) * step_s});
  plan.push_back({"eval", std::min(options.test_frames, used / 6) * kEvalSecondsPerFrame});

  nlohmann::json minutes = nlohmann::json::object();
  double predicted_done = 0, actual_done = 0;
  auto left_s = [&](size_t from) {  // the rest of the plan, scaled by how the finished stages went
    double rest = 0;
    for (size_t i = from; i < plan.size(); ++i)
      if (!state.Done(plan[i].name)) rest += plan[i].predicted_s;
    const double pace = predicted_done > 0 ? std::clamp(actual_done / predicted_done, 0.5, 3.0) : 1.0;
    return rest * pace;
  };
  spdlog::info("create: {} -> {} (work in {}); about {} in all", options.input, options.out, work.string(),
               HumanDuration(left_s(0)));
  auto run_stage = [&](size_t i, const std::function<nlohmann::json()>& body) {
    const Plan& p = plan[i];
    if (state.Done(p.name)) {
      minutes[p.name] = state.Stage(p.name)["seconds"].get<double>() / 60;
      spdlog::info("create: [{}/{}] {}: done in an earlier run", i + 1, plan.size(), p.name);
      return;
    }
    spdlog::info("create: [{}/{}] {} (about {}; {} left in all)", i + 1, plan.size(), p.name,
                 HumanDuration(left_s(i) - left_s(i + 1)), HumanDuration(left_s(i)));
    Stopwatch watch;
    nlohmann::json report = body();
    const double seconds = watch.ElapsedSeconds();
    predicted_done += p.predicted_s;
    actual_done += seconds;
    state.Finish(p.name, seconds, std::move(report));
    minutes[p.name] = seconds / 60;
    spdlog::info("create: {} done in {}", p.name, HumanDuration(seconds));
  };
  auto stop_here = [&](const std::string& stage) {
    if (options.stop_after != stage) return false;
    spdlog::info("create: stopped after {} as asked; --resume continues", stage);
    return true;
  };

  size_t next = 0;
  nlohmann::json summary = {{"avatar", options.out}, {"work", work.string()}, {"head_model", models.head_model}};
  if (record_s > 0) {
    run_stage(next++, [&] {
      SourceOptions source = options.source;
      source.realtime = true;  // a file given --record plays as a camera would
      std::unique_ptr<FrameSource> reader = OpenFrameSource(options.input, source);
      GuidedRecordingOptions g;
      g.seconds = record_s;
      g.out_dir = frames_input;
      fs::remove_all(frames_input);
      spdlog::info("create: recording {} s from {}: follow the prompts", record_s, reader->Describe());
      const RecordingQuality q = RecordGuided(*reader, g, hooks.show);
      for (const std::string& problem : q.problems) spdlog::warn("recording: {}", problem);
      if (!q.ok() && !options.accept_recording)
        throw std::runtime_error("the recording would make a poor avatar (" + q.problems.front() +
                                 "); record again (remove " + work.string() +
                                 "), or --accept-recording to train on it anyway");
      return q.ToJson();
    });
    summary["recording"] = state.Stage("record")["report"];
    if (stop_here("record")) return summary;
  }

  run_stage(next++, [&] {
    PrepOptions p;
    p.input = frames_input;
    p.head_model = models.head_model;
    p.out_dir = (work / "dataset").string();
    p.resolutions = {options.resolution};
    p.test_frames = options.test_frames;
    p.test_share = 1.0 / 6;
    p.max_frames = options.max_frames;
    p.intrinsics = options.intrinsics;
    p.identity_from = options.identity_from;
    p.calibrate = options.identity_from.empty();
    if (options.shape_prior >= 0) p.shape_prior = options.shape_prior;
    p.source = options.source;
    if (record_s > 0) p.source.realtime = false;
    p.resume = true;  // reuse a finished tracking pass of an interrupted run
    nlohmann::json report = PrepareDataset(p);
    report.erase("frame_numbers");
    return report;
  });
  const nlohmann::json& prep = state.Stage("prep")["report"];
  summary["frames"] = {{"read", prep.value("frames_read", 0)},
                       {"fitted", prep.value("frames_fitted", 0)},
                       {"split", prep.value("split", nlohmann::json())}};
  if (stop_here("prep")) return summary;

  run_stage(next++, [&] {
    SubjectOptions s = MakeSubjectOptions(options, models, work);
    std::function<void()> wait_for_ranks;
    if (options.processes > 1 && hooks.start_ranks) wait_for_ranks = hooks.start_ranks(&s.fit);
    nlohmann::json report = RunSubject(s);
    if (wait_for_ranks) wait_for_ranks();
    return report;
  });
  if (stop_here("fine-tune")) return summary;

  run_stage(next++, [&] {
    EvalOptions e;
    e.head_model = models.head_model;
    e.avatar = options.out;
    e.dataset = (work / "dataset").string();
    e.out_dir = (work / "eval").string();
    e.orbit_frames = 30;
    e.landmarks = options.landmarks;
    return RunEval(e);
  });
  const nlohmann::json& eval = state.Stage("eval")["report"];
  summary["held_out"] = HeldOut(eval);
  summary["videos"] = {{"side_by_side", (work / "eval" / "side_by_side.mp4").string()},
                       {"orbit", (work / "eval" / "orbit.mp4").string()}};
  double total = 0;
  for (const auto& [stage, m] : minutes.items()) total += m.get<double>();
  minutes["total"] = total;
  summary["minutes"] = minutes;
  const std::string avatar = Quoted(options.out), model = Quoted(models.head_model);
  const std::string receiver = Quoted(SiblingProgram("headcast-receiver")) + " --head-model " + model +
                               " --avatar me=" + avatar + " --plaintext --allow-no-token";
  summary["use"] = {{"receiver", receiver},
                    {"sender", Quoted(SiblingProgram("headcast-sender")) + " --plaintext --head-model " + model +
                                   " --input /dev/video0 --identity-from " + avatar + " --avatar-id me"},
                    // docs/calls.md sets the virtual camera device up.
                    {"virtual_camera", receiver + " --display v4l2:/dev/video10"}};
  return summary;
}

std::string CreateSummaryText(const nlohmann::json& s) {
  std::string text = "avatar: " + s.value("avatar", std::string()) + "\n";
  char line[256];
  if (s.contains("frames")) {
    const auto& f = s["frames"];
    std::snprintf(line, sizeof(line), "frames: %d read, %d fitted; %d held out for the figures\n", f.value("read", 0),
                  f.value("fitted", 0),
                  f.contains("split") && f["split"].is_object() ? f["split"].value("test", 0) : 0);
    text += line;
  }
  if (s.contains("held_out")) {
    const auto& h = s["held_out"];
    std::snprintf(line, sizeof(line), "held-out frames: PSNR %.2f dB, SSIM %.3f", h.value("psnr_db", 0.0),
                  h.value("ssim", 0.0));
    text += line;
    if (h.contains("landmark_error_iod")) {
      std::snprintf(line, sizeof(line), ", landmark error %.3f of the eye distance",
                    h["landmark_error_iod"].value("all", 0.0));
      text += line;
    }
    text += "\n";
  }
  if (s.contains("videos")) text += "look at: " + s["videos"].value("side_by_side", std::string()) + "\n";
  if (s.contains("minutes")) {
    text += "minutes:";
    for (const auto& [stage, m] : s["minutes"].items()) {
      std::snprintf(line, sizeof(line), " %s %.1f", stage.c_str(), m.get<double>());
      text += line;
    }
    text += "\n";
  }
  if (s.contains("use")) {
    text += "use it:\n";
    for (const auto& [what, command] : s["use"].items()) text += "  " + command.get<std::string>() + "\n";
  }
  return text;
}

}  // namespace headcast
