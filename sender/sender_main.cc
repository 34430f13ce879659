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
#include <thread>

#include "common/core/log.h"
#include "common/core/timer.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/recording.h"
#include "sender/capture/frame_source.h"
#include "sender/live_tracker.h"
#include "sender/session_client.h"

namespace {
std::atomic<bool> g_stop{false};
}

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-sender: stream head-model parameters to a headcast receiver"};
  app.set_config("--config", "", "read options from this file (TOML/INI: key = value)");
  SenderOptions o;
  std::string log_level, head_model_spec = "builtin", params, record, stats_json, components;
  int synthetic = 0, key_interval = 30;
  double duration = 0, error_m = 2e-4;
  bool loop = false;
  app.add_option("--log", log_level, "log level");
  app.add_option("--target", o.target, "receiver host:port")->capture_default_str();
  app.add_option("--avatar-id", o.avatar_id, "which of the receiver's avatars to drive")->capture_default_str();
  app.add_option("--token", o.token, "bearer token");
  app.add_flag("--plaintext", o.plaintext, "no TLS (loopback targets only)");
  app.add_option("--tls-ca", o.tls_ca, "PEM CA of the receiver's certificate");
  app.add_option("--tls-cert", o.tls_client_cert, "PEM client certificate (if the receiver requires one)");
  app.add_option("--tls-key", o.tls_client_key, "PEM client key");
  app.add_option("--tls-server-name", o.tls_server_name, "name to check in the receiver's certificate");
  app.add_option("--head-model", head_model_spec, "head model: builtin or .npz")->capture_default_str();
  std::string input, identity_from, intrinsics, camera_size = "640x480";
  SourceOptions source_options;
  source_options.realtime = true;
  LiveTrackerOptions live;
  app.add_option("--input", input, "track this camera (/dev/videoN), video or image folder live");
  app.add_option("--identity-from", identity_from,
                 "--input: the person's shape: the avatar's own (.hcavatar) or a PARAMS.json (headcast-fit-mesh)");
  app.add_option("--intrinsics", intrinsics, "--input: camera fx,fy,cx,cy in pixels");
  app.add_option("--fov", live.fov_deg, "--input: vertical field of view when intrinsics are unknown")
      ->capture_default_str();
  app.add_option("--predictor", live.predictor, "--input: dlib 68-point shape predictor (.dat)");
  app.add_option("--camera-size", camera_size, "--input cameras: WIDTHxHEIGHT to ask for")->capture_default_str();
  app.add_flag("!--as-fast-as-possible", source_options.realtime, "--input files: do not pace to their frame rate");
  app.add_option("--params", params, "replay this parameter recording (.hcrec)");
  app.add_option("--synthetic", synthetic, "send this many frames of the synthetic talking head (default source)");
  app.add_flag("--loop", loop, "replay the source forever");
  app.add_option("--fps", o.fps, "frame rate of the synthetic source")->capture_default_str();
  app.add_option("--expression-components", components, "comma-separated expression indices to send (default all)");
  app.add_option("--quantisation-error", error_m, "largest vertex error one quantisation step may cause, metres")
      ->capture_default_str();
  app.add_option("--max-batch", o.max_batch, "frames per message at most")->capture_default_str();
  app.add_option("--min-send-interval", o.min_send_interval_s, "seconds between messages at least (narrow links)")
      ->capture_default_str();
  app.add_option("--max-kbps", o.max_kbps, "link budget on the wire, kbit/s (0: none); adapted down on backlog")
      ->capture_default_str();
  auto* stats_opt = app.add_option("--stats-interval", o.stats_interval_s,
                                   "ask for receiver Stats this often, seconds (0: the receiver's choice; "
                                   "default 5 under a 32 kbit/s budget)");
  auto* key_opt = app.add_option("--key-interval", key_interval,
                                 "a key frame at least every N frames (default 30; 10 s under a 32 kbit/s budget)");
  app.add_option("--queue", o.queue_frames, "frames queued at most (older ones are dropped)")->capture_default_str();
  app.add_option("--record", record, "also record the sent parameters (.hcrec)");
  app.add_option("--duration", duration, "stop after this many seconds (0: at the end of the source)");
  app.add_option("--stats-json", stats_json, "write sender statistics here at the end");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    std::signal(SIGINT, [](int) { g_stop = true; });
    std::signal(SIGTERM, [](int) { g_stop = true; });
    const HeadModel model = LoadHeadModelSpec(head_model_spec);
    std::vector<int> subset;
    std::stringstream ss(components);
    for (std::string item; std::getline(ss, item, ',');)
      if (!item.empty()) subset.push_back(std::stoi(item));
    std::vector<FrameParams> frames;
    RecordingInfo info;
    if (!params.empty()) {
      frames = ReadRecording(params, &info);
      if (!info.head_model_fingerprint.empty() && info.head_model_fingerprint != model.fingerprint())
        throw std::runtime_error(params + ": recorded with another head model ('" + info.head_model_name + "')");
      o.fps = info.fps;
    }
    if (o.max_kbps > 0 && o.max_kbps < kNarrowLinkKbps) {
      if (stats_opt->count() == 0) o.stats_interval_s = kNarrowLinkStatsInterval;
      if (key_opt->count() == 0) key_interval = static_cast<int>(std::lround(kNarrowLinkKeySeconds * o.fps));
    }
    if (key_interval < 1) throw std::invalid_argument("--key-interval must be at least 1");
    const CodecLayout layout = CodecLayout::FromModel(model, error_m, subset, key_interval);
    if (params.empty() && input.empty()) {
      SyntheticMotionOptions motion;
      motion.fps = o.fps;
      for (int i = 0; i < (synthetic > 0 ? synthetic : 300); ++i)
        frames.push_back(SyntheticTalkingHead(model, i, motion));
    }
    if (frames.empty() && input.empty()) throw std::runtime_error("nothing to send");
    std::unique_ptr<RecordingWriter> recorder;
    if (!record.empty()) {
      info.head_model_name = model.data().name;
      info.head_model_fingerprint = model.fingerprint();
      info.num_expression = model.num_expression();
      info.fps = o.fps;
      info.source = "headcast-sender";
      recorder = std::make_unique<RecordingWriter>(record, info);
    }
    SenderClient client(o, layout);
    nlohmann::json tracking_report;
    Stopwatch clock;
    if (!input.empty()) {
      // Live: capture -> landmarks -> fit -> the session, frame by frame; each
      // frame keeps its capture timestamp (the receiver measures glass-to-glass from it).
      if (std::sscanf(camera_size.c_str(), "%dx%d", &source_options.width, &source_options.height) != 2)
        throw std::invalid_argument("--camera-size wants WIDTHxHEIGHT");
      if (!identity_from.empty()) live.identity = ReadTrackingIdentity(identity_from, model);
      if (!intrinsics.empty()) {
        PinholeCamera k;
        if (std::sscanf(intrinsics.c_str(), "%lf,%lf,%lf,%lf", &k.fx, &k.fy, &k.cx, &k.cy) != 4)
          throw std::invalid_argument("--intrinsics wants fx,fy,cx,cy in pixels");
        live.camera = k;
      }
      auto source = OpenFrameSource(input, source_options);
      LiveTracker tracker(model, live);
      client.Start();
      clock.Restart();
      SampleStats landmarks_ms, fit_ms, read_ms;
      int read = 0, fitted = 0, skipped = 0;
      uint64_t sequence = 0;
      while (!g_stop && (duration <= 0 || clock.ElapsedSeconds() < duration)) {
        CapturedFrame frame;
        std::string problem;
        Stopwatch read_watch;
        const ReadStatus st = source->Read(&frame, &problem);
        if (st == ReadStatus::kEnd) break;
        if (st == ReadStatus::kSkipped) {
          ++skipped;
          spdlog::warn("{}", problem);
          continue;
        }
        read_ms.Add(read_watch.ElapsedMs());
        ++read;
        FrameParams f;
        const LiveTrackResult r = tracker.Process(frame.bgr, frame.capture_time_s, frame.camera, &f);
        landmarks_ms.Add(r.landmarks_ms);
        if (!r.fitted) continue;  // no face this frame: the receiver holds the last one
        fit_ms.Add(r.fit_ms);
        ++fitted;
        f.sequence = sequence++;
        f.capture_time_s = source_options.realtime ? frame.capture_time_s : SteadyNowSeconds();
        client.Submit(f);
        if (recorder) recorder->Write(f);
      }
      tracking_report = {{"input", input},
                         {"frames_read", read},
                         {"frames_fitted", fitted},
                         {"frames_unreadable", skipped},
                         {"read_wait_ms_median", read_ms.empty() ? 0.0 : read_ms.Median()},
                         {"landmarks_ms_median", landmarks_ms.empty() ? 0.0 : landmarks_ms.Median()},
                         {"landmarks_ms_p95", landmarks_ms.empty() ? 0.0 : landmarks_ms.Percentile(95)},
                         {"fit_ms_median", fit_ms.empty() ? 0.0 : fit_ms.Median()},
                         {"fit_ms_p95", fit_ms.empty() ? 0.0 : fit_ms.Percentile(95)}};
    } else {
      client.Start();
      clock.Restart();
      // Real-time pacing by capture timestamps; each frame stamped with the send-side clock.
      const double t0 = frames.front().capture_time_s, span = frames.back().capture_time_s - t0 + 1.0 / o.fps;
      uint64_t sequence = 0;
      for (size_t i = 0; !g_stop; ++i) {
        if (i == frames.size()) {
          if (!loop) break;
          i = 0;
        }
        const double lap = std::floor(sequence / static_cast<double>(frames.size()));
        const double due = frames[i].capture_time_s - t0 + lap * span;
        if (duration > 0 && due > duration) break;
        const double wait = due - clock.ElapsedSeconds();
        if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
        FrameParams f = frames[i];
        f.sequence = sequence++;
        f.capture_time_s = SteadyNowSeconds();
        client.Submit(f);
        if (recorder) recorder->Write(f);
      }
    }
    client.Flush(2.0);
    client.Stop(g_stop ? "interrupted" : "end of source");
    const SenderCounters c = client.counters();
    nlohmann::json report = {{"frames_submitted", c.submitted},
                             {"frames_sent", c.sent},
                             {"frames_dropped", c.dropped},
                             {"frames_invalid", c.invalid},
                             {"messages", c.messages},
                             {"payload_bytes", c.payload_bytes},
                             {"payload_kbps", 8e-3 * c.payload_bytes / std::max(1e-3, clock.ElapsedSeconds())},
                             {"seconds", clock.ElapsedSeconds()},
                             {"connects", c.connects},
                             {"rejection", c.last_rejection},
                             {"last_error", c.last_error},
                             {"receiver_frames", c.receiver_frames},
                             {"receiver_bad", c.receiver_bad},
                             {"budget_kbps_final", c.budget_kbps}};
    if (!tracking_report.empty()) report["tracking"] = tracking_report;
    std::cout << report.dump(2) << "\n";
    if (!stats_json.empty()) std::ofstream(stats_json) << report.dump(2) << "\n";
    if (c.connects == 0) {
      spdlog::error("never streamed: {}", c.last_rejection.empty() ? c.last_error : c.last_rejection);
      return 2;
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
