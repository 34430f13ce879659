// headcast-receiver: serves sessions over gRPC and shows the first session's
// avatar (window, offscreen, video), optionally recording the received stream.
#include <CLI/CLI.hpp>
#include <csignal>
#include <fstream>
#include <iostream>

#include "common/avatar/avatar_renderer.h"
#include "common/core/log.h"
#include "common/core/timer.h"
#include "common/core/zip_archive.h"
#include "common/headmodel/head_model_io.h"
#include "proto/recording.h"
#include "receiver/render_loop.h"
#include "receiver/session_server.h"

namespace headcast {
namespace {

std::atomic<bool> g_stop{false};

// Parameters for the render loop from the oldest live session's jitter buffer.
class SessionSource : public FrameParamsSource {
 public:
  explicit SessionSource(ReceiverServer* server) : server_(server) {}
  std::optional<FrameParams> Next(double, bool* finished) override {
    *finished = g_stop;
    const auto sessions = server_->Sessions();
    if (sessions.empty()) return std::nullopt;
    return sessions.front().buffer->Sample(server_->Now());
  }

 private:
  ReceiverServer* server_;
};

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-receiver: receive head-model parameters over gRPC and show the avatar"};
  app.set_config("--config", "", "read options from this file (TOML/INI: key = value)");
  std::string log_level, head_model_spec = "builtin", display = "window", video, record, stats_json, token_file;
  std::vector<std::string> avatars_args, tokens;
  ReceiverServerOptions server_options;
  double render_fps = 30, duration = 0;
  int threads = 1;
  app.add_option("--log", log_level, "log level");
  app.add_option("--listen", server_options.listen, "host:port to listen on")->capture_default_str();
  app.add_option("--token", tokens, "accepted bearer token (repeatable)");
  app.add_option("--token-file", token_file, "file with accepted bearer tokens, one per line");
  app.add_flag("--plaintext", server_options.plaintext, "no TLS (loopback addresses only)");
  app.add_flag("--allow-no-token", server_options.allow_no_token,
               "accept senders without a token (plaintext loopback only)");
  app.add_option("--tls-cert", server_options.tls_cert, "PEM certificate chain");
  app.add_option("--tls-key", server_options.tls_key, "PEM private key");
  app.add_option("--tls-client-ca", server_options.tls_client_ca, "PEM CA: require client certificates signed by it");
  app.add_option("--max-sessions", server_options.max_sessions, "concurrent sessions at most")->capture_default_str();
  app.add_option("--target-delay", server_options.target_delay_s, "jitter-buffer delay, seconds")
      ->capture_default_str();
  app.add_option("--head-model", head_model_spec, "head model of the avatars: builtin or .npz")->capture_default_str();
  app.add_option("--avatar", avatars_args, "ID=PATH.hcavatar (repeatable); senders name the ID")->required();
  app.add_option("--display", display, "window, offscreen, video, none")->capture_default_str();
  app.add_option("--video", video, "also write what is shown to this MP4");
  app.add_option("--record", record, "record the first session's received parameters (.hcrec)");
  app.add_option("--render-fps", render_fps, "display rate")->capture_default_str();
  app.add_option("--threads", threads, "libtorch threads")->capture_default_str();
  app.add_option("--duration", duration, "stop after this many seconds (0: run until interrupted)");
  app.add_option("--stats-json", stats_json, "write render and server statistics here at the end");
  std::string latency_csv;
  app.add_option("--latency-csv", latency_csv,
                 "log every received frame: arrival time, session, sequence, capture-to-arrival ms (same-host clocks)");
  std::string display_csv;
  app.add_option("--display-csv", display_csv,
                 "log every shown frame: shown time, sequence, glass-to-glass ms (capture to shown, same-host clocks), "
                 "render ms");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    std::signal(SIGINT, [](int) { g_stop = true; });
    std::signal(SIGTERM, [](int) { g_stop = true; });
    if (!token_file.empty()) {
      std::istringstream in(ReadFileBytes(token_file));
      for (std::string line; std::getline(in, line);)
        if (!line.empty()) tokens.push_back(line);
    }
    server_options.tokens = tokens;
    auto model = std::make_shared<const HeadModel>(LoadHeadModelSpec(head_model_spec));
    std::map<std::string, AvatarEntry> catalog;
    std::optional<Avatar> shown;
    for (const std::string& arg : avatars_args) {
      const auto eq = arg.find('=');
      if (eq == std::string::npos) throw std::invalid_argument("--avatar wants ID=PATH, got '" + arg + "'");
      Avatar avatar = Avatar::Load(arg.substr(eq + 1), *model);
      catalog[arg.substr(0, eq)] = {model->fingerprint(), model->num_expression()};
      if (!shown) shown.emplace(std::move(avatar));
    }
    ReceiverServer server(server_options, catalog);
    std::unique_ptr<RecordingWriter> recorder;
    std::mutex record_mutex;
    std::string recorded_session;
    std::ofstream latency_log;
    if (!latency_csv.empty()) {
      latency_log.open(latency_csv);
      if (!latency_log) throw std::runtime_error(latency_csv + ": cannot write");
      latency_log << "arrival_s,session,sequence,latency_ms\n";
    }
    if (!record.empty() || !latency_csv.empty()) {
      RecordingInfo info;
      info.head_model_name = model->data().name;
      info.head_model_fingerprint = model->fingerprint();
      info.num_expression = model->num_expression();
      info.subject = shown->subject();
      info.source = "headcast-receiver (received stream)";
      if (!record.empty()) recorder = std::make_unique<RecordingWriter>(record, info);
      server.SetFrameObserver([&](const std::string& id, const FrameParams& f) {
        std::lock_guard<std::mutex> lock(record_mutex);
        if (recorded_session.empty()) recorded_session = id;
        if (recorder && id == recorded_session) recorder->Write(f);
        if (latency_log.is_open()) {
          const double now = SteadyNowSeconds();
          latency_log << std::fixed << now << "," << id << "," << f.sequence << "," << 1e3 * (now - f.capture_time_s)
                      << "\n";
        }
      });
    }
    server.Start();
    AvatarRendererOptions renderer_options;
    renderer_options.threads = threads;
    AvatarRenderer renderer(model, std::move(*shown), renderer_options);
    DisplayOptions display_options;
    display_options.kind = ParseDisplayKind(display);
    display_options.video_path = video;
    display_options.video_fps = render_fps;
    display_options.title = "headcast receiver";
    auto shown_display = MakeDisplay(display_options);
    RenderLoopOptions loop;
    loop.target_fps = render_fps;
    loop.max_seconds = duration;
    std::ofstream display_log;
    if (!display_csv.empty()) {
      display_log.open(display_csv);
      if (!display_log) throw std::runtime_error(display_csv + ": cannot write");
      display_log << "shown_s,sequence,glass_to_glass_ms,render_ms\n";
      loop.on_shown = [&](const FrameParams& f, double glass_ms, double render_ms) {
        display_log << std::fixed << SteadyNowSeconds() << "," << f.sequence << "," << glass_ms << "," << render_ms
                    << "\n";
      };
    }
    SessionSource source(&server);
    const RenderLoopStats stats = RunRenderLoop(renderer, source, *shown_display, loop, [&](DisplayOverlay* o) {
      server.SetRenderFps(o->fps);
      const auto sessions = server.Sessions();
      o->note = sessions.empty() ? "no session" : sessions.front().id + " " + sessions.front().sender_name;
    });
    server.Shutdown();
    if (recorder) recorder->Close();
    const ServerCounters c = server.counters();
    nlohmann::json report = {
        {"rendered", stats.rendered},
        {"fps", stats.fps()},
        {"render_ms_median", stats.render_ms.Median()},
        {"show_ms_median", stats.show_ms.Median()},
        {"glass_to_glass_ms_p50", stats.glass_to_glass_ms.empty() ? -1.0 : stats.glass_to_glass_ms.Median()},
        {"glass_to_glass_ms_p95", stats.glass_to_glass_ms.empty() ? -1.0 : stats.glass_to_glass_ms.Percentile(95)},
        {"sessions_started", c.sessions_started},
        {"sessions_rejected", c.sessions_rejected},
        {"frames_received", c.frames_received},
        {"frames_bad", c.frames_bad},
        {"payload_bytes_received", c.bytes_received}};
    std::cout << report.dump(2) << "\n";
    if (!stats_json.empty()) std::ofstream(stats_json) << report.dump(2) << "\n";
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
