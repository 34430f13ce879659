// headcast-sender: streams head-model parameters to a receiver. Sources: a
// camera, video or image folder tracked live (--input: face tracker + head-model
// fit per frame), a parameter recording replayed in real time (--params), or
// the synthetic talking head.
#include <CLI/CLI.hpp>
#include <cmath>
#include <csignal>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "common/capture/capture_flags.h"
#include "common/capture/frame_source.h"
#include "common/capture/newest_frame_source.h"
#include "common/core/cli_flags.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/timer.h"
#include "common/core/version.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/protocol.h"
#include "proto/recording.h"
#include "sender/grpc_uplink.h"
#include "sender/live_tracker.h"
#include "sender/session_client.h"

namespace headcast {
namespace {

std::atomic<bool> g_stop{false};

struct SenderFlags {
  SenderOptions session;
  std::string log_level, head_model = "builtin", params, record, stats_json, components, token_file, frames_csv;
  int synthetic = 0, key_interval = 30;
  double duration = 0, error_m = 2e-4;
  bool loop = false;
  bool photometric_anchor = true;  // the avatar's, when --identity-from names one that carries it
  double health_check_s = 0;       // > 0: only ask the receiver's health, this long at most
  std::string input, identity_from, intrinsics, camera_size = "640x480";
  SourceOptions source;
  LiveTrackerOptions live;
  CLI::Option* stats_interval = nullptr;
  CLI::Option* key_interval_flag = nullptr;
  CLI::Option* error_flag = nullptr;
  CLI::Option* outline_flag = nullptr;
};

void AddFlags(CLI::App& app, SenderFlags& f) {
  AddConfigFile(app);
  SenderOptions& o = f.session;
  f.source.realtime = true;
  // The landmarks as found, as prep takes them for the avatar's training
  // frames: the live One-Euro filter lags and smooths blinks and lips away,
  // which costs the picture more than the jitter it removes
  // (bench/results/fidelity_ablation.md, session 49).
  f.live.tracker.face.filter = false;
  app.add_option("--log", f.log_level, "log level");
  app.add_option("--target", o.target, "receiver host:port")->capture_default_str();
  app.add_option("--avatar-id", o.avatar_id, "which of the receiver's avatars to drive")->capture_default_str();
  app.add_option("--token", o.token, "bearer token (visible to other users in ps: prefer --token-file)")
      ->excludes(app.add_option("--token-file", f.token_file, "file holding the bearer token (mode 0600)"));
  app.add_flag("--plaintext", o.plaintext, "no TLS (loopback targets only)");
  app.add_option("--tls-ca", o.tls_ca, "PEM CA of the receiver's certificate");
  app.add_option("--tls-cert", o.tls_client_cert, "PEM client certificate (if the receiver requires one)");
  app.add_option("--tls-key", o.tls_client_key, "PEM client key");
  app.add_option("--tls-server-name", o.tls_server_name, "name to check in the receiver's certificate");
  app.add_option("--head-model", f.head_model, "head model: builtin or .npz")->capture_default_str();
  app.add_option(
      "--input", f.input,
      "track this live: a camera (/dev/videoN), video, image folder, RGB-D folder (with associations.txt: the "
      "RGB-D fit) or zed:SOURCE (side-by-side stereo; needs --stereo-calibration)");
  app.add_option("--identity-from", f.identity_from,
                 "--input: the person's shape: the avatar's own (.hcavatar) or a PARAMS.json (headcast-fit-mesh)");
  app.add_option_function<std::string>(
         "--landmark-filter", [&f](const std::string& mode) { f.live.tracker.face.filter = mode == "causal"; },
         "--input: the landmarks over time: off (as found, as prep takes them; the default) or causal (One-Euro "
         "filtered: steadier, but a frame or two behind, and blinks and lips smoothed away)")
      ->check(CLI::IsMember({"off", "causal"}));
  app.add_option("--landmark-filter-hz", f.live.tracker.face.filter_min_cutoff,
                 "--input, --landmark-filter causal: the One-Euro filter at rest, Hz (higher: less lag, more jitter)")
      ->capture_default_str();
  app.add_option("--landmark-filter-beta", f.live.tracker.face.filter_beta,
                 "--input, --landmark-filter causal: the filter's cutoff rise per pixel a second of landmark speed")
      ->capture_default_str();
  app.add_flag("!--no-photometric-anchor", f.photometric_anchor,
               "--input: fit landmarks only, without holding the head's placement to the appearance the avatar's "
               "training frames were fitted to (the photometric anchor its file carries)");
  app.add_option("--intrinsics", f.intrinsics, "--input: camera fx,fy,cx,cy in pixels");
  app.add_option("--fov", f.live.fov_deg, "--input: vertical field of view when intrinsics are unknown")
      ->capture_default_str();
  app.add_option("--predictor", f.live.tracker.face.predictor_path, "--input: dlib 68-point shape predictor (.dat)")
      ->capture_default_str();
  app.add_flag("!--no-landmark-repair", f.live.tracker.face.repair.repair,
               "keep the shape predictor's brows and mouth where they jump against the flow from the previous "
               "frame (no repair; as the avatar's prep did)");
  f.live.outline = true;
  f.outline_flag = app.add_flag(
      "--outline,!--no-outline", f.live.outline,
      "--input: measure the top of the head's outline on each frame (the frame's head mask cut as the avatar's "
      "training masks were) and send it, so the receiver draws the hair's edge where the person's is. On by "
      "default when --identity-from names an avatar that records its camera, except on narrow links (--max-kbps "
      "below 32), where its bits would crowd out the face's; --outline asks for it there too. Costs a GrabCut a "
      "frame, cut on a worker thread beside the fit (outline_ms in --json: what a frame waits for after its fit)");
  app.add_flag("!--outline-on-tracking-thread", f.live.outline_beside_fit,
               "--outline: cut each frame's head mask on the tracking thread after its fit (each frame then "
               "waits a whole GrabCut after its fit)");
  app.add_option("--outline-mask-size", f.live.outline_mask.working_size,
                 "--input: the head mask the outline is measured on is segmented at about this many pixels across "
                 "(the training masks' by default; smaller is faster and coarser)")
      ->capture_default_str();
  app.add_option("--outline-mask-iterations", f.live.outline_mask.iterations,
                 "--input: GrabCut iterations of that mask (the training masks' by default)")
      ->capture_default_str();
  app.add_option("--outline-refit-every", f.live.outline_mask.refit_every,
                 "--input: that GrabCut learns its colour models on every Nth frame only; the frames between cut "
                 "once with the last ones (1: every frame learns its own, as the training masks did)")
      ->capture_default_str();
  app.add_option("--outline-band", f.live.outline_mask.band,
                 "--input: a frame cut with the last colour models is segmented only within this many pixels (of "
                 "the mask's working size) of the last frame's outline, moved with the face (0: the whole head "
                 "region; a frame after new models is cut whole)")
      ->capture_default_str();
  app.add_flag("!--no-gaze", f.live.tracker.face.locate_irises,
               "--input: do not locate the irises (the eyes look straight ahead)");
  AddCameraFlags(app, f.source, f.camera_size);
  AddDepthFlags(app, f.source);
  app.add_option("--calibration-frames", f.live.tracker.rgbd_identity_frames,
                 "--input with depth: frames whose fitted shapes give the identity (median), then frozen; live, "
                 "fitted beside tracking")
      ->capture_default_str();
  AddPacingFlag(app, &f.source.realtime, {}, {"--as-fast-as-possible"});
  app.add_option("--params", f.params, "replay this parameter recording (.hcrec)");
  app.add_option("--synthetic", f.synthetic, "send this many frames of the synthetic talking head (default source)");
  app.add_flag("--loop", f.loop, "replay the source forever");
  app.add_option("--fps", o.fps, "frame rate of the synthetic source")->capture_default_str();
  app.add_option("--expression-components", f.components, "comma-separated expression indices to send (default all)");
  f.error_flag = app.add_option("--quantisation-error", f.error_m,
                                "largest vertex error one quantisation step may cause, metres (default 0.0002; "
                                "0.0005 under a 32 kbit/s budget)");
  app.add_option("--max-batch", o.max_batch, "frames per message at most")->capture_default_str();
  app.add_flag("--freshest", o.freshest_only,
               "narrow links: each message carries only the newest frame, the receiver interpolates (lower latency, "
               "fewer parameter updates)");
  app.add_option("--min-send-interval", o.min_send_interval_s, "seconds between messages at least (narrow links)")
      ->capture_default_str();
  app.add_option("--max-kbps", o.max_kbps, "link budget on the wire, kbit/s (0: none); adapted down on backlog")
      ->capture_default_str();
  app.add_option("--datagrams", o.datagrams,
                 "frames as encrypted UDP datagrams when the receiver offers them: auto (under a 32 kbit/s budget), "
                 "on, off")
      ->capture_default_str();
  f.stats_interval = app.add_option("--stats-interval", o.stats_interval_s,
                                    "ask for receiver Stats this often, seconds (0: the receiver's choice; "
                                    "default 5 under a 32 kbit/s budget)");
  f.key_interval_flag =
      app.add_option("--key-interval", f.key_interval,
                     "a key frame at least every N frames (default 30; 10 s under a 32 kbit/s budget)");
  app.add_option("--queue", o.queue_frames, "frames queued at most (older ones are dropped)")->capture_default_str();
  app.add_option("--record", f.record, "also record the sent parameters (.hcrec)");
  app.add_option("--health-check", f.health_check_s,
                 "only ask the receiver at --target whether it is serving (gRPC health), waiting at most this many "
                 "seconds; exit 0 when it is (for Docker HEALTHCHECK, systemd, load balancers)")
      ->check(CLI::Range(0.1, 60.0));
  app.add_option("--frames-csv", f.frames_csv,
                 "--input: write sequence,input_frame per sent frame here (which input frame each one was tracked "
                 "from; headcast-train compare --frame-map)");
  app.add_option("--duration", f.duration, "stop after this many seconds (0: at the end of the source)");
  AddJsonFlag(app, &f.stats_json, "the sender's statistics at the end", {"--stats-json"});
}

std::vector<int> ParseComponents(const std::string& text) {
  std::vector<int> subset;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) {
    if (item.empty()) continue;
    size_t used = 0;
    int k = -1;
    try {
      k = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || k < 0)
      throw std::invalid_argument("--expression-components wants comma-separated indices, e.g. 0,1,2 (got '" + item +
                                  "')");
    subset.push_back(k);
  }
  return subset;
}

// Live: capture -> landmarks -> fit -> the session, frame by frame; each frame
// keeps its capture timestamp (the receiver measures glass-to-glass from it).
nlohmann::json StreamLive(SenderFlags& f, const HeadModel& model, SenderClient& client, RecordingWriter* recorder,
                          Stopwatch& clock) {
  ParseSize(f.camera_size, "--camera-size", &f.source.width, &f.source.height);
  if (!f.identity_from.empty()) {
    f.live.identity = ReadTrackingIdentity(f.identity_from, model);
    if (const std::optional<MatteRules> rules = ReadAvatarMatteRules(f.identity_from)) f.live.matte_rules = *rules;
    // The avatar learnt the codes of its training fits: the live fit makes them the same way.
    if (const std::optional<ExpressionFitSettings> fit = ReadAvatarExpressionFit(f.identity_from)) {
      fit->ApplyTo(&f.live.tracker.fit);
      spdlog::info("expression fit as the avatar's training frames: {}", fit->ToJson().dump());
    }
    if (f.photometric_anchor) f.live.anchor = ReadAvatarAnchorReference(f.identity_from);
    if (f.live.anchor)
      spdlog::info("photometric anchor: {} reference points from {}", f.live.anchor->referenced(), f.identity_from);
  }
  if (!f.intrinsics.empty()) f.live.camera = ParseIntrinsics(f.intrinsics, "--intrinsics");
  // The tracker first: a camera's clock (and a paced file's) starts at open,
  // and loading the landmark model must not make the first frames late.
  // A camera (or a paced file) keeps its rate while the RGB-D identity is
  // fitted beside it; read as fast as possible, the identity frames are
  // tracked in turn, the same every run.
  f.live.tracker.rgbd_identity_in_background = f.source.realtime;
  LiveTracker tracker(model, f.live);
  // Live (and paced) sources hand the tracker their newest frame: when it is
  // slower than the camera, frames are skipped rather than aged in a queue.
  std::unique_ptr<FrameSource> opened = OpenFrameSource(f.input, f.source);
  NewestFrameSource* newest = nullptr;
  if (f.source.realtime) {
    auto wrapped = std::make_unique<NewestFrameSource>(std::move(opened));
    newest = wrapped.get();
    opened = std::move(wrapped);
  }
  FrameSource* source = opened.get();
  clock.Restart();                  // the stream's time starts once the tracker is ready
  constexpr size_t kKept = 100000;  // a camera session may run for days
  SampleStats landmarks_ms(kKept), fit_ms(kKept), read_ms(kKept), depth_ms(kKept), frame_ms(kKept),
      tracking_frame_ms(kKept), provisional_frame_ms(kKept), anchor_ms(kKept), outline_ms(kKept);
  int read = 0, fitted = 0, skipped = 0, with_depth = 0, identity_frames = 0, anchored = 0, outlined = 0;
  std::optional<double> first_fit_s, identity_made_s;  // stream clock
  uint64_t sequence = 0;
  std::ofstream frames_csv;
  if (!f.frames_csv.empty()) {
    frames_csv.open(f.frames_csv);
    if (!frames_csv) throw std::runtime_error(f.frames_csv + ": cannot be written");
    frames_csv << "sequence,input_frame\n";
  }
  while (!g_stop && !client.counters().gave_up && (f.duration <= 0 || clock.ElapsedSeconds() < f.duration)) {
    CapturedFrame frame;
    std::string problem;
    Stopwatch read_watch;
    const ReadStatus st = source->Read(&frame, &problem);
    if (st == ReadStatus::kEnd) {
      if (!problem.empty()) throw std::runtime_error(f.input + ": " + problem);
      break;
    }
    if (st == ReadStatus::kSkipped) {
      ++skipped;
      spdlog::warn("{}", problem);
      continue;
    }
    read_ms.Add(read_watch.ElapsedMs());
    ++read;
    FrameParams p;
    const LiveTrackResult r = tracker.Process(frame, &p);
    landmarks_ms.Add(r.landmarks_ms);
    with_depth += r.with_depth;
    if (r.identity_frozen_now) {
      identity_made_s = clock.ElapsedSeconds();
      const Eigen::VectorXd& beta = tracker.identity();
      spdlog::info("RGB-D identity made at frame {} (shape {:.3f} {:.3f} {:.3f} ...)", read, beta[0],
                   beta.size() > 1 ? beta[1] : 0.0, beta.size() > 2 ? beta[2] : 0.0);
    }
    if (!r.fitted) continue;  // no face this frame: the receiver holds the last one
    if (!first_fit_s) first_fit_s = clock.ElapsedSeconds();
    fit_ms.Add(r.fit_ms);
    if (r.with_depth) depth_ms.Add(r.depth_ms);
    if (f.live.anchor && !r.with_depth) anchor_ms.Add(r.anchor_ms);
    anchored += r.anchored;
    if (!p.outline.empty()) {
      ++outlined;
      outline_ms.Add(r.outline_ms);
    }
    // Capture to parameters: from the capture stamp for live sources; for
    // files read as fast as possible, the work on this thread (decoding,
    // rectifying, landmarks, depth, fit, the outline's wait and measure).
    const double frame_to_params_ms =
        f.source.realtime ? 1e3 * (SteadyNowSeconds() - frame.capture_time_s) : read_watch.ElapsedMs();
    frame_ms.Add(frame_to_params_ms);
    // The first RGB-D frames fit the person's shape too (far slower), or live
    // are tracked while it is fitted beside them; after them, the tracking rate.
    if (r.identity_frame)
      ++identity_frames;
    else if (r.provisional_identity)
      provisional_frame_ms.Add(frame_to_params_ms);
    else
      tracking_frame_ms.Add(frame_to_params_ms);
    ++fitted;
    p.sequence = sequence++;
    p.capture_time_s = f.source.realtime ? frame.capture_time_s : SteadyNowSeconds();
    client.Submit(p);
    if (recorder) recorder->Write(p);
    if (frames_csv.is_open()) frames_csv << p.sequence << "," << frame.index << "\n";
  }
  auto median = [](const SampleStats& s) { return s.empty() ? 0.0 : s.Median(); };
  auto p95 = [](const SampleStats& s) { return s.empty() ? 0.0 : s.Percentile(95); };
  return {{"input", f.input},
          {"landmark_filter", f.live.tracker.face.filter ? "causal" : "off"},
          {"landmark_filter_hz", f.live.tracker.face.filter_min_cutoff},  // when causal
          {"landmark_filter_beta", f.live.tracker.face.filter_beta},
          {"expression_fit", ExpressionFitSettings::Of(f.live.tracker.fit).ToJson()},
          {"frames_read", read},
          {"frames_fitted", fitted},
          {"frames_unreadable", skipped},
          {"frames_with_depth", with_depth},
          {"frames_skipped_behind_tracker", newest ? newest->dropped() : 0},
          {"read_wait_ms_median", median(read_ms)},
          {"landmarks_ms_median", median(landmarks_ms)},
          {"landmarks_ms_p95", p95(landmarks_ms)},
          {"fit_ms_median", median(fit_ms)},
          {"fit_ms_p95", p95(fit_ms)},
          {"photometric_anchor", f.live.anchor.has_value()},
          {"frames_anchored", anchored},
          {"anchor_ms_median", median(anchor_ms)},
          {"frames_with_outline", outlined},
          {"outline_ms_median", median(outline_ms)},
          {"outline_ms_p95", p95(outline_ms)},
          {"depth_ms_median", median(depth_ms)},
          {"capture_to_params_ms_median", median(frame_ms)},
          {"capture_to_params_ms_p95", p95(frame_ms)},
          {"identity_frames", identity_frames},
          {"provisional_identity_frames", provisional_frame_ms.count()},
          {"provisional_capture_to_params_ms_median", median(provisional_frame_ms)},
          {"provisional_capture_to_params_ms_p95", p95(provisional_frame_ms)},
          {"identity_made_after_s",
           identity_made_s && first_fit_s ? nlohmann::json(*identity_made_s - *first_fit_s) : nlohmann::json()},
          {"tracking_capture_to_params_ms_median", median(tracking_frame_ms)},
          {"tracking_capture_to_params_ms_p95", p95(tracking_frame_ms)}};
}

// Replay: real-time pacing by capture timestamps; each frame stamped with the send-side clock.
void Replay(const SenderFlags& f, const std::vector<FrameParams>& frames, double fps, SenderClient& client,
            RecordingWriter* recorder, const Stopwatch& clock) {
  const double t0 = frames.front().capture_time_s, span = frames.back().capture_time_s - t0 + 1.0 / fps;
  uint64_t sequence = 0;
  for (size_t i = 0; !g_stop && !client.counters().gave_up; ++i) {
    if (i == frames.size()) {
      if (!f.loop) break;
      i = 0;
    }
    const double lap = std::floor(sequence / static_cast<double>(frames.size()));
    const double due = frames[i].capture_time_s - t0 + lap * span;
    if (f.duration > 0 && due > f.duration) break;
    const double wait = due - clock.ElapsedSeconds();
    if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
    FrameParams p = frames[i];
    p.sequence = sequence++;
    p.capture_time_s = SteadyNowSeconds();
    client.Submit(p);
    if (recorder) recorder->Write(p);
  }
}

nlohmann::json Report(const SenderCounters& c, double seconds) {
  return {{"frames_submitted", c.submitted},
          {"frames_sent", c.sent},
          {"frames_dropped", c.dropped},
          {"frames_invalid", c.invalid},
          {"messages", c.messages},
          {"payload_bytes", c.payload_bytes},
          {"payload_kbps", 8e-3 * c.payload_bytes / std::max(1e-3, seconds)},
          {"seconds", seconds},
          {"connects", c.connects},
          {"rejection", c.last_rejection},
          {"gave_up", c.gave_up},
          {"last_error", c.last_error},
          {"receiver_frames", c.receiver_frames},
          {"receiver_bad", c.receiver_bad},
          {"datagrams", c.datagrams},
          {"datagrams_unsent", c.datagrams_unsent},
          {"datagrams_active", c.datagrams_active},
          {"receiver_datagrams_lost", c.receiver_datagrams_lost},
          {"key_frame_requests", c.key_frame_requests},
          {"budget_kbps_final", c.budget_kbps}};
}

// Whether live frames measure and carry the hair's outline: asked for with
// --outline, or by default where it can be measured (the avatar records its
// camera: f.live.contract) and the link is not narrow.
void DecideOutline(SenderFlags& f) {
  if (!f.live.outline || f.input.empty() || f.outline_flag->count() > 0) return;
  const char* why = nullptr;
  if (f.session.max_kbps > 0 && f.session.max_kbps < kNarrowLinkKbps)
    why = "a narrow link (--outline sends it anyway)";
  else if (f.identity_from.empty())
    why = "no --identity-from avatar to take its camera from";
  else if (!f.live.contract)
    why = "the avatar records no camera";
  if (!why) return;
  f.live.outline = false;
  spdlog::info("the hair's outline is not sent: {}", why);
}

int Run(SenderFlags& f) {
  InitLogging(f.log_level);
  StopOnSignals(&g_stop);
  SenderOptions& o = f.session;
  if (f.health_check_s > 0) {
    const std::string status = CheckReceiverHealth(o, f.health_check_s);
    std::cout << status << "\n";
    return status == "SERVING" ? 0 : 1;
  }
  if (!f.token_file.empty()) {
    const std::vector<std::string> tokens = ReadTokenFile(f.token_file);
    if (tokens.size() != 1) throw std::runtime_error(f.token_file + ": a sender's token file holds one token");
    o.token = tokens.front();
  }
  const HeadModel model = LoadHeadModelSpec(f.head_model);
  std::vector<FrameParams> frames;
  RecordingInfo info;
  if (!f.params.empty()) {
    frames = ReadRecording(f.params, &info);
    if (!info.head_model_fingerprint.empty() && info.head_model_fingerprint != model.fingerprint())
      throw std::runtime_error(f.params + ": recorded with another head model ('" + info.head_model_name + "')");
    o.fps = info.fps;
  }
  if (o.max_kbps > 0 && o.max_kbps < kNarrowLinkKbps) {
    if (f.stats_interval->count() == 0) o.stats_interval_s = kNarrowLinkStatsInterval;
    if (f.key_interval_flag->count() == 0)
      f.key_interval = static_cast<int>(std::lround(kNarrowLinkKeySeconds * o.fps));
    if (f.error_flag->count() == 0) f.error_m = kNarrowLinkQuantisationError;
  }
  if (f.key_interval < 1) throw std::invalid_argument("--key-interval must be at least 1");
  // The avatar's camera: the live tracker's, and whether the outline can be measured.
  if (!f.input.empty() && !f.identity_from.empty()) f.live.contract = ReadAvatarCameraContract(f.identity_from);
  DecideOutline(f);
  // The outline's values travel when frames may carry one (a live outline, or a recording that may hold them).
  const int outline_bins = f.live.outline || !f.params.empty() ? OutlineOptions{}.bins : 0;
  const CodecLayout layout =
      CodecLayout::FromModel(model, f.error_m, ParseComponents(f.components), f.key_interval, true, outline_bins);
  if (f.params.empty() && f.input.empty()) {
    SyntheticMotionOptions motion;
    motion.fps = o.fps;
    for (int i = 0; i < (f.synthetic > 0 ? f.synthetic : 300); ++i)
      frames.push_back(SyntheticTalkingHead(model, i, motion));
  }
  if (frames.empty() && f.input.empty()) throw std::runtime_error("nothing to send");
  std::unique_ptr<RecordingWriter> recorder;
  if (!f.record.empty())
    recorder =
        std::make_unique<RecordingWriter>(f.record, MakeRecordingInfo(model, o.fps, info.subject, "headcast-sender"));
  SenderClient client(o, layout);
  client.Start();
  Stopwatch clock;
  nlohmann::json tracking;
  if (!f.input.empty())
    tracking = StreamLive(f, model, client, recorder.get(), clock);
  else
    Replay(f, frames, o.fps, client, recorder.get(), clock);
  if (!client.counters().gave_up) client.Flush(2.0);
  client.Stop(g_stop ? "interrupted" : "end of source");
  const SenderCounters c = client.counters();
  nlohmann::json report = Report(c, clock.ElapsedSeconds());
  if (!tracking.empty()) report["tracking"] = tracking;
  std::cout << report.dump(2) << "\n";
  if (!f.stats_json.empty()) std::ofstream(f.stats_json) << report.dump(2) << "\n";
  if (c.gave_up || c.connects == 0) {
    spdlog::error("{}: {}", c.gave_up ? "stopped" : "never streamed",
                  c.last_rejection.empty() ? c.last_error : c.last_rejection);
    return 2;
  }
  return 0;
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  CLI::App app{"headcast-sender: stream head-model parameters to a headcast receiver"};
  headcast::AddVersionFlag(app);
  headcast::SenderFlags flags;
  headcast::AddFlags(app, flags);
  return headcast::RunProgram(app, argc, argv, [&] { return headcast::Run(flags); });
}
