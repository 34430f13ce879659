// headcast-avatar: create and inspect avatar files, make parameter recordings,
// and render an avatar from parameters — with novel views (orbit) and expression
// transfer — to a window, offscreen, or an MP4.
#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <fstream>
#include <iostream>

#include "common/avatar/avatar_renderer.h"
#include "common/core/cli_flags.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/recording.h"
#include "receiver/display/display_flags.h"
#include "receiver/render_loop.h"

namespace headcast {
namespace {

struct RenderArgs {
  std::string avatar, head_model = "builtin", params, transfer, stats_json;
  DisplayFlags display;
  int synthetic = 0, frames = 0, threads = 1;
  double orbit_deg = 0, fps = 30;
  bool transfer_pose = false, paced = true, no_overlay = false, channels_first = false, serial_stages = false;
};

std::vector<FrameParams> LoadFrames(const std::string& path, const HeadModel& model) {
  RecordingInfo info;
  std::vector<FrameParams> frames = ReadRecording(path, &info);
  if (!info.head_model_fingerprint.empty() && info.head_model_fingerprint != model.fingerprint())
    throw std::runtime_error(path + ": recorded with head model '" + info.head_model_name + "' (" +
                             info.head_model_fingerprint + "), not the loaded '" + model.data().name + "' (" +
                             model.fingerprint() + ")");
  if (frames.empty()) throw std::runtime_error(path + ": the recording has no frames");
  return frames;
}

// Rotates the camera around the head's vertical axis through `centre` (head frame).
RigidTransform Orbit(const RigidTransform& cam_from_head, const Eigen::Vector3d& centre, double angle_rad) {
  RigidTransform head_turn;
  head_turn.rotation = Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  head_turn.translation = centre - head_turn.rotation * centre;
  return cam_from_head * head_turn;
}

int Render(const RenderArgs& a) {
  auto model = std::make_shared<const HeadModel>(LoadHeadModelSpec(a.head_model));
  Avatar avatar = Avatar::Load(a.avatar, *model);
  std::vector<FrameParams> frames;
  if (!a.params.empty()) {
    frames = LoadFrames(a.params, *model);
  } else {
    const int n = a.synthetic > 0 ? a.synthetic : 150;
    for (int i = 0; i < n; ++i) frames.push_back(SyntheticTalkingHead(*model, i));
  }
  if (a.frames > 0 && static_cast<int>(frames.size()) > a.frames) frames.resize(a.frames);
  if (!a.transfer.empty()) {
    // Expression (and optionally pose) from another recording; camera and timing from this one.
    const std::vector<FrameParams> other = LoadFrames(a.transfer, *model);
    frames.resize(std::min(frames.size(), other.size()));
    for (size_t i = 0; i < frames.size(); ++i) {
      frames[i].expression = other[i].expression;
      if (a.transfer_pose) {
        frames[i].jaw = other[i].jaw;
        frames[i].neck = other[i].neck;
        frames[i].left_eye = other[i].left_eye;
        frames[i].right_eye = other[i].right_eye;
      }
    }
  }
  if (a.orbit_deg != 0) {
    const Eigen::Vector3d centre = model->rest_landmark_centroid() - Eigen::Vector3d(0, 0, 0.06);
    for (size_t i = 0; i < frames.size(); ++i) {
      const double angle = a.orbit_deg * M_PI / 180 * std::sin(2 * M_PI * i / std::max<size_t>(frames.size(), 1));
      frames[i].SetCamFromHead(Orbit(frames[i].CamFromHead(), centre, angle));
    }
  }
  AvatarRendererOptions renderer_options;
  renderer_options.threads = a.threads;
  renderer_options.channels_last = !a.channels_first;
  renderer_options.parallel_stages = !a.serial_stages;
  AvatarRenderer renderer(model, std::move(avatar), renderer_options);
  DisplayOptions display_options = MakeDisplayOptions(a.display, a.fps, "headcast — " + a.avatar);
  display_options.draw_overlay = !a.no_overlay;
  auto display = MakeDisplay(display_options);
  RenderLoopOptions loop;
  loop.target_fps = a.fps;
  loop.paced = a.paced;
  SequenceSource source(frames, loop.paced);
  const RenderLoopStats s = RunRenderLoop(renderer, source, *display, loop);
  nlohmann::json report = {{"frames_in", frames.size()},
                           {"rendered", s.rendered},
                           {"missed_ticks", s.missed_ticks},
                           {"refused", s.refused},
                           {"seconds", s.seconds},
                           {"fps", s.fps()},
                           {"render_ms_median", s.render_ms.Median()},
                           {"render_ms_p95", s.render_ms.Percentile(95)},
                           {"stage_ms_median",
                            {{"head_model", s.head_model_ms.Median()},
                             {"sample", s.sample_ms.Median()},
                             {"surface", s.surface_ms.Median()},
                             {"texture", s.texture_ms.Median()},
                             {"mlp", s.mlp_ms.Median()},
                             {"composite", s.composite_ms.Median()},
                             {"upsample", s.upsample_ms.Median()},
                             {"show", s.show_ms.Median()}}},
                           {"display", display->name()},
                           {"video", a.display.video}};
  // Standard output carries the frames when the display is the pipe.
  (display->name().rfind("pipe", 0) == 0 ? std::cerr : std::cout) << report.dump(2) << "\n";
  if (!a.stats_json.empty()) std::ofstream(a.stats_json) << report.dump(2) << "\n";
  return s.rendered > 0 ? 0 : 1;
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-avatar: avatar files, parameter recordings, and rendering (novel views, expression transfer)"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  app.require_subcommand(1);
  std::string log_level;
  app.add_option("--log", log_level, "log level: trace, debug, info, warn, error");

  auto* create =
      app.add_subcommand("create", "write a randomly initialised (untrained) avatar, for tests and benchmarks");
  std::string head_model = "builtin", out;
  int resolution = 256;
  uint64_t seed = 1;
  create->add_option("--head-model", head_model, "builtin or a model .npz")->capture_default_str();
  create->add_option("--resolution", resolution, "output size: 128, 256, 512")->check(CLI::IsMember({128, 256, 512}));
  create->add_option("--seed", seed, "random seed");
  create->add_option("--out", out, "output .hcavatar")->required();

  auto* info = app.add_subcommand("info", "print an avatar file's manifest");
  std::string info_path;
  info->add_option("avatar", info_path, ".hcavatar file")->required();

  auto* synth = app.add_subcommand("synth-params", "write a synthetic talking-head parameter recording");
  int synth_frames = 300;
  SyntheticMotionOptions motion;
  synth->add_option("--head-model", head_model, "builtin or a model .npz")->capture_default_str();
  synth->add_option("--frames", synth_frames, "frames")->check(CLI::Range(1, 1000000));
  synth->add_option("--fps", motion.fps, "frames per second");
  synth->add_option("--seed", motion.seed, "varies the motion");
  synth->add_option("--out", out, "output recording (.hcrec)")->required();

  auto* render = app.add_subcommand("render", "render an avatar from a parameter recording or synthetic motion");
  RenderArgs r;
  render->add_option("avatar", r.avatar, ".hcavatar file")->required();
  render->add_option("--head-model", r.head_model, "the head model the avatar was made for")->capture_default_str();
  render->add_option("--params", r.params, "parameter recording to play (default: synthetic motion)");
  render->add_option("--synthetic", r.synthetic, "frames of synthetic motion when no --params (default 150)");
  render->add_option("--transfer", r.transfer, "take the expression from this recording (expression transfer)");
  render->add_flag("--transfer-pose", r.transfer_pose, "with --transfer: also take jaw, neck and eye rotations");
  render->add_option("--orbit", r.orbit_deg, "novel views: swing the camera around the head by +-DEG degrees");
  AddDisplayFlags(*render, r.display);
  render->add_option("--fps", r.fps, "target frame rate")->capture_default_str();
  AddPacingFlag(*render, &r.paced, {}, {"--unpaced"});
  render->add_flag("--no-overlay", r.no_overlay, "do not draw fps/latency text");
  AddMaxFramesFlag(*render, &r.frames, "render at most this many frames", {"--frames"});
  render->add_option("--threads", r.threads, "libtorch threads")->capture_default_str();
  render->add_flag("--channels-first", r.channels_first,
                   "convolutions on images in libtorch's default layout (the same picture, slower: measurements)");
  render->add_flag("--serial-stages", r.serial_stages,
                   "with --threads 2: the head model and the raster one after the other, not beside the network (the "
                   "same picture, slower: measurements)");
  AddJsonFlag(*render, &r.stats_json, "the render statistics", {"--stats-json"});

  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    if (create->parsed()) {
      const HeadModel model = LoadHeadModelSpec(head_model);
      Avatar avatar =
          Avatar::CreateRandom(AvatarConfig::Default(resolution), model, DefaultSubject(model, resolution), seed);
      avatar.Save(out);
      std::cout << "wrote " << out << " (untrained, random weights; " << resolution << "x" << resolution << ")\n";
    } else if (info->parsed()) {
      std::cout << Avatar::ReadManifest(info_path).dump(2) << "\n";
    } else if (synth->parsed()) {
      motion.Check();
      const HeadModel model = LoadHeadModelSpec(head_model);
      RecordingInfo rec;
      rec.head_model_name = model.data().name;
      rec.head_model_fingerprint = model.fingerprint();
      rec.num_expression = model.num_expression();
      rec.fps = motion.fps;
      rec.subject = DefaultSubject(model, 256);
      rec.source = "synthetic talking head (headcast-avatar synth-params, seed " + std::to_string(motion.seed) + ")";
      RecordingWriter writer(out, rec);
      for (int i = 0; i < synth_frames; ++i) writer.Write(SyntheticTalkingHead(model, i, motion));
      writer.Close();
      std::cout << "wrote " << out << " (" << synth_frames << " frames at " << motion.fps << " fps)\n";
    } else if (render->parsed()) {
      return Render(r);
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", headcast::InFlagNames(app, e.what()));
    return 1;
  }
  return 0;
}
