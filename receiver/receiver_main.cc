// headcast-receiver: serves sessions over gRPC and shows one session's avatar
// (--show chooses which; window, offscreen, video), optionally recording the
// received stream.
#include <CLI/CLI.hpp>
#include <csignal>
#include <fstream>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>

#include "common/avatar/avatar_backend.h"
#include "common/core/cli_flags.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/service_notify.h"
#include "common/core/timer.h"
#include "common/core/version.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/head_model_io.h"
#include "proto/protocol.h"
#include "proto/recording.h"
#include "receiver/display/display_flags.h"
#include "receiver/render_loop.h"
#include "receiver/session_server.h"

namespace headcast {
namespace {

std::atomic<bool> g_stop{false};

struct ReceiverFlags {
  std::string log_level, head_model_spec = "builtin", record, stats_json, token_file;
  DisplayFlags display;
  std::string show = "first";
  std::string latency_csv, display_csv;
  std::vector<std::string> avatars, tokens;
  ReceiverServerOptions server;
  double render_fps = 30, duration = 0;
  int threads = 1;
};

void AddFlags(CLI::App& app, ReceiverFlags& f) {
  AddConfigFile(app);
  ReceiverServerOptions& s = f.server;
  app.add_option("--log", f.log_level, "log level");
  app.add_option("--listen", s.listen, "host:port to listen on")->capture_default_str();
  app.add_option("--token", f.tokens, "accepted bearer token (repeatable)");
  app.add_option("--token-file", f.token_file,
                 "file with accepted bearer tokens, one per line (# comments; at least 16 characters each)");
  app.add_flag("--plaintext", s.plaintext, "no TLS (loopback addresses only)");
  app.add_flag("--allow-no-token", s.allow_no_token, "accept senders without a token (plaintext loopback only)");
  app.add_option("--tls-cert", s.tls_cert, "PEM certificate chain");
  app.add_option("--tls-key", s.tls_key, "PEM private key");
  app.add_option("--tls-client-ca", s.tls_client_ca, "PEM CA: require client certificates signed by it");
  app.add_option("--max-sessions", s.max_sessions, "concurrent sessions at most")->capture_default_str();
  app.add_option("--target-delay", s.target_delay_s, "jitter-buffer delay, seconds")->capture_default_str();
  app.add_option("--show", f.show,
                 "which session is shown: first (the earliest keeps the display), latest (a new one takes over) or "
                 "name:SENDER; sessions with nothing to show are passed over")
      ->capture_default_str();
  app.add_option("--hello-timeout", s.hello_timeout_s, "close streams that have not said Hello after this long, s")
      ->capture_default_str();
  app.add_option("--idle-timeout", s.idle_timeout_s, "end sessions that sent nothing this long, s (0: never)")
      ->capture_default_str();
  app.add_option("--evict-silent", s.evict_silent_s,
                 "when full, a new sender displaces the longest-silent session if silent this long, s (0: never)")
      ->capture_default_str();
  app.add_option("--datagram-port", s.datagram_port,
                 "UDP port for frames sent as datagrams (-1: the --listen port's number, 0: any free port)")
      ->capture_default_str();
  app.add_flag("!--no-datagrams", s.datagrams, "take frames on the gRPC stream only (offer no UDP port)");
  app.add_option("--head-model", f.head_model_spec, "head model of the avatars: builtin or .npz")
      ->capture_default_str();
  app.add_option("--avatar", f.avatars, "ID=PATH.hcavatar (repeatable); senders name the ID")->required();
  AddDisplayFlags(app, f.display);
  app.add_option("--record", f.record, "record the first session's received parameters (.hcrec)");
  app.add_option("--render-fps", f.render_fps, "display rate")->capture_default_str();
  app.add_option("--threads", f.threads, "libtorch threads")->capture_default_str();
  app.add_option("--duration", f.duration, "stop after this many seconds (0: run until interrupted)");
  AddJsonFlag(app, &f.stats_json, "render and server statistics at the end", {"--stats-json"});
  app.add_option("--latency-csv", f.latency_csv,
                 "log every received frame: arrival time, session, sequence, capture-to-arrival ms (same-host clocks)");
  app.add_option("--display-csv", f.display_csv,
                 "log every shown frame: shown time, sequence, glass-to-glass ms (capture to shown, same-host clocks), "
                 "render ms");
}

// What the sessions' threads write as frames arrive: the first session's
// parameters (--record) and every frame's arrival latency (--latency-csv).
class StreamTaps {
 public:
  StreamTaps(const ReceiverFlags& f, const HeadModel& model, const SubjectParams& subject) {
    if (!f.latency_csv.empty()) {
      latency_log_.open(f.latency_csv);
      if (!latency_log_) throw std::runtime_error(f.latency_csv + ": cannot write");
      latency_log_ << "arrival_s,session,sequence,latency_ms\n";
    }
    if (!f.record.empty())
      recorder_ = std::make_unique<RecordingWriter>(
          f.record, MakeRecordingInfo(model, 30, subject, "headcast-receiver (received stream)"));
  }
  bool active() const { return recorder_ || latency_log_.is_open(); }
  void operator()(const std::string& id, const FrameParams& f) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (recorded_session_.empty()) recorded_session_ = id;
    if (recorder_ && id == recorded_session_) recorder_->Write(f);
    if (latency_log_.is_open()) {
      const double now = SteadyNowSeconds();
      latency_log_ << std::fixed << now << "," << id << "," << f.sequence << "," << 1e3 * (now - f.capture_time_s)
                   << "\n";
    }
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (recorder_) recorder_->Close();
  }

 private:
  std::mutex mutex_;
  std::unique_ptr<RecordingWriter> recorder_;
  std::string recorded_session_;
  std::ofstream latency_log_;
};

nlohmann::json Report(const RenderLoopStats& stats, const ServerCounters& c) {
  return {{"rendered", stats.rendered},
          {"fps", stats.fps()},
          {"render_ms_median", stats.render_ms.Median()},
          {"show_ms_median", stats.show_ms.Median()},
          {"glass_to_glass_ms_p50", stats.glass_to_glass_ms.empty() ? -1.0 : stats.glass_to_glass_ms.Median()},
          {"glass_to_glass_ms_p95", stats.glass_to_glass_ms.empty() ? -1.0 : stats.glass_to_glass_ms.Percentile(95)},
          {"sessions_started", c.sessions_started},
          {"sessions_rejected", c.sessions_rejected},
          {"hello_timeouts", c.hello_timeouts},
          {"idle_timeouts", c.idle_timeouts},
          {"evictions", c.evictions},
          {"frames_received", c.frames_received},
          {"frames_bad", c.frames_bad},
          {"payload_bytes_received", c.bytes_received},
          {"datagrams_received", c.datagrams_received},
          {"datagrams_refused", c.datagrams_refused}};
}

int Run(ReceiverFlags& f) {
  InitLogging(f.log_level);
  StopOnSignals(&g_stop);
  if (!f.token_file.empty())
    for (const std::string& t : ReadTokenFile(f.token_file)) f.tokens.push_back(t);
  f.server.tokens = f.tokens;
  auto model = std::make_shared<const HeadModel>(LoadHeadModelSpec(f.head_model_spec));
  AvatarBackendOptions backend_options;
  backend_options.threads = f.threads;
  const ShowPolicy show = ShowPolicy::Parse(f.show);
  // Every avatar is opened (and so checked) at start; each session is drawn with the one it names.
  std::map<std::string, AvatarEntry> catalog;
  std::map<std::string, std::unique_ptr<AvatarBackend>> avatars;
  for (const std::string& arg : f.avatars) {
    const auto eq = arg.find('=');
    if (eq == std::string::npos || eq == 0) throw std::invalid_argument("--avatar wants ID=PATH, got '" + arg + "'");
    const std::string id = arg.substr(0, eq);
    if (avatars.count(id)) throw std::invalid_argument("--avatar: the id '" + id + "' is given twice");
    avatars[id] = OpenAvatarBackend(arg.substr(eq + 1), model, backend_options);
    catalog[id] = {model->fingerprint(), model->num_expression()};
  }
  ReceiverServer server(f.server, catalog);
  StreamTaps taps(f, *model, avatars.begin()->second->subject());
  // The server stops before the taps go, however this ends: sessions hand
  // frames to the taps until then (Shutdown waits for them; a second call is nothing).
  struct ShutdownFirst {
    ReceiverServer& server;
    ~ShutdownFirst() { server.Shutdown(); }
  } shutdown_first{server};
  if (taps.active()) server.SetFrameObserver([&](const std::string& id, const FrameParams& p) { taps(id, p); });
  server.Start();
  // Under systemd (Type=notify): ready once listening; the watchdog hears
  // from every render tick, so a stuck loop gets the service restarted.
  const ServiceNotifier service;
  service.Notify("READY=1");
  Stopwatch since_ping;
  auto display = MakeDisplay(MakeDisplayOptions(f.display, f.render_fps, "headcast receiver"));
  RenderLoopOptions loop;
  loop.target_fps = f.render_fps;
  loop.max_seconds = f.duration;
  std::ofstream display_log;
  if (!f.display_csv.empty()) {
    display_log.open(f.display_csv);
    if (!display_log) throw std::runtime_error(f.display_csv + ": cannot write");
    display_log << "shown_s,sequence,glass_to_glass_ms,render_ms\n";
  }
  SessionFrameSource source(server.sessions(), show, &g_stop);
  loop.on_tick = [&] {
    if (service.watchdog_interval_s() <= 0 || since_ping.ElapsedSeconds() < service.watchdog_interval_s()) return;
    service.Notify("WATCHDOG=1");
    since_ping.Restart();
  };
  std::map<std::string, int> shown_senders;  // frames shown per sender name (the first 100 names)
  loop.on_shown = [&](const FrameParams& p, double glass_ms, double render_ms) {
    const std::string name = source.shown().sender_name;
    if (shown_senders.size() < 100 || shown_senders.count(name)) ++shown_senders[name];
    if (display_log.is_open())
      display_log << std::fixed << SteadyNowSeconds() << "," << p.sequence << "," << glass_ms << "," << render_ms
                  << "\n";
  };
  const auto pick = [&]() -> AvatarBackend& { return *avatars.at(source.shown().avatar_id); };
  const RenderLoopStats stats = RunRenderLoop(pick, source, *display, loop, [&](DisplayOverlay* o) {
    server.SetRenderFps(o->fps);
    const SessionView shown = source.shown();
    o->note = shown.id + " " + shown.sender_name + " (" + shown.avatar_id + ")";
  });
  server.Shutdown();
  taps.Close();
  nlohmann::json report = Report(stats, server.counters());
  report["shown_senders"] = shown_senders;
  // Standard output carries the frames when the display is the pipe.
  (display->name().rfind("pipe", 0) == 0 ? std::cerr : std::cout) << report.dump(2) << "\n";
  if (!f.stats_json.empty()) std::ofstream(f.stats_json) << report.dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  CLI::App app{"headcast-receiver: receive head-model parameters over gRPC and show the avatar"};
  headcast::AddVersionFlag(app);
  headcast::ReceiverFlags flags;
  headcast::AddFlags(app, flags);
  return headcast::RunProgram(app, argc, argv, [&] { return headcast::Run(flags); });
}
