// The receiver's gRPC server.
#include "receiver/session_server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <optional>
#include <thread>

#include "common/codec/param_codec.h"
#include "common/core/options.h"
#include "common/core/timer.h"
#include "common/core/zip_archive.h"
#include "proto/convert.h"
#include "proto/headcast.grpc.pb.h"

namespace headcast {

void ReceiverServerOptions::Check() const {
  OptionsCheck c("ReceiverServerOptions");
  c.NotEmpty("listen", listen).InRange("max_sessions", max_sessions, 1, 10000);
  c.InRange("target_delay_s", target_delay_s, 0, 10).InRange("stats_interval_s", stats_interval_s, 0.05, 3600);
  c.That(!plaintext || IsLoopbackAddress(listen),
         "plaintext is only allowed on a loopback address (got " + listen + "); configure TLS");
  c.That(plaintext || (!tls_cert.empty() && !tls_key.empty()),
         "TLS needs tls_cert and tls_key (or plaintext on loopback)");
  c.That(!tokens.empty() || (allow_no_token && plaintext),
         "bearer tokens are required (allow_no_token only with plaintext on loopback)");
  c.ThrowIfErrors();
}

namespace {

// Constant-time comparison, so response times do not reveal a token's prefix.
bool SameToken(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  return diff == 0;
}

}  // namespace

struct ReceiverServer::Impl final : public v1::Headcast::Service {
  ReceiverServerOptions options;
  std::map<std::string, AvatarEntry> avatars;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  double t0 = SteadyNowSeconds();
  mutable std::mutex mutex;
  std::map<std::string, SessionView> sessions;
  ServerCounters counters;
  std::atomic<double> render_fps{0};
  std::atomic<uint64_t> next_id{1};
  std::function<void(const std::string&, const FrameParams&)> observer;

  double Now() const { return SteadyNowSeconds() - t0; }

  grpc::Status Reject(grpc::ServerReaderWriter<v1::Downlink, v1::Uplink>* stream, v1::Reject::Reason reason,
                      const std::string& message, grpc::StatusCode code) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      ++counters.sessions_rejected;  // before the reply, so whoever reads it sees the count
    }
    v1::Downlink d;
    d.mutable_reject()->set_reason(reason);
    d.mutable_reject()->set_message(message);
    stream->Write(d);
    spdlog::info("session rejected: {}", message);
    return grpc::Status(code, message);
  }

  grpc::Status Session(grpc::ServerContext* context,
                       grpc::ServerReaderWriter<v1::Downlink, v1::Uplink>* stream) override {
    v1::Uplink up;
    if (!stream->Read(&up)) return grpc::Status(grpc::StatusCode::CANCELLED, "stream closed before Hello");
    if (!up.has_hello())
      return Reject(stream, v1::Reject::PROTOCOL, "the stream must start with Hello",
                    grpc::StatusCode::INVALID_ARGUMENT);
    const v1::Hello& hello = up.hello();
    if (hello.protocol_version() != kProtocolVersion)
      return Reject(stream, v1::Reject::PROTOCOL_VERSION,
                    "protocol version " + std::to_string(hello.protocol_version()) +
                        " is not supported; this receiver speaks version " + std::to_string(kProtocolVersion),
                    grpc::StatusCode::FAILED_PRECONDITION);
    // NaN or negative asks fall back to our own interval; at most a minute.
    const double asked = std::isfinite(hello.stats_interval_s()) ? hello.stats_interval_s() : 0.0;
    const double stats_interval_s = std::clamp(asked, options.stats_interval_s, std::max(60.0, options.stats_interval_s));
    std::string token = hello.auth_token();
    const auto& metadata = context->client_metadata();
    auto it = metadata.find("authorization");
    if (it != metadata.end()) {
      const std::string value(it->second.data(), it->second.size());
      if (value.rfind("Bearer ", 0) == 0) token = value.substr(7);
    }
    if (!options.tokens.empty() || !options.allow_no_token) {
      if (token.empty())
        return Reject(stream, v1::Reject::UNAUTHENTICATED, "no bearer token", grpc::StatusCode::UNAUTHENTICATED);
      bool known = false;
      for (const auto& t : options.tokens) known |= SameToken(t, token);
      if (!known)
        return Reject(stream, v1::Reject::UNAUTHENTICATED, "wrong bearer token", grpc::StatusCode::UNAUTHENTICATED);
    }
    auto avatar = avatars.find(hello.avatar_id());
    if (avatar == avatars.end())
      return Reject(stream, v1::Reject::UNKNOWN_AVATAR, "no avatar '" + hello.avatar_id() + "' on this receiver",
                    grpc::StatusCode::NOT_FOUND);
    CodecLayout layout;
    std::string why;
    if (!FromProto(hello.layout(), &layout, &why))
      return Reject(stream, v1::Reject::BAD_LAYOUT, "bad parameter layout: " + why, grpc::StatusCode::INVALID_ARGUMENT);
    if (layout.num_expression != avatar->second.num_expression)
      return Reject(stream, v1::Reject::BAD_LAYOUT,
                    "layout has " + std::to_string(layout.num_expression) + " expression components, avatar '" +
                        hello.avatar_id() + "' has " + std::to_string(avatar->second.num_expression),
                    grpc::StatusCode::INVALID_ARGUMENT);
    SessionView view;
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (static_cast<int>(sessions.size()) >= options.max_sessions)
        return Reject(stream, v1::Reject::BUSY, "receiver busy (" + std::to_string(options.max_sessions) + " sessions)",
                      grpc::StatusCode::RESOURCE_EXHAUSTED);
      view.id = "s" + std::to_string(next_id++);
      view.avatar_id = hello.avatar_id();
      view.sender_name = hello.sender_name();
      JitterBufferOptions jb;
      jb.target_delay_s = options.target_delay_s;
      view.buffer = std::make_shared<JitterBuffer>(jb);
      view.started_s = Now();
      sessions[view.id] = view;
      ++counters.sessions_started;
    }
    spdlog::info("session {} started: avatar '{}', sender '{}'", view.id, view.avatar_id, view.sender_name);
    std::mutex write_mutex;  // gRPC allows one Write at a time per stream
    {
      v1::Downlink d;
      d.mutable_welcome()->set_protocol_version(kProtocolVersion);
      d.mutable_welcome()->set_session_id(view.id);
      d.mutable_welcome()->set_target_delay_s(options.target_delay_s);
      d.mutable_welcome()->set_stats_interval_s(stats_interval_s);
      std::lock_guard<std::mutex> lock(write_mutex);
      stream->Write(d);
    }
    // Stats go back from their own thread, so a silent sender still hears from us.
    std::mutex done_mutex;
    std::condition_variable done_cv;
    bool done = false;
    std::atomic<uint64_t> bad{0}, bytes{0}, decoded{0};
    std::mutex latency_mutex;
    SampleStats latency_ms;  // capture -> arrival, this stats interval
    std::thread stats_thread([&] {
      std::unique_lock<std::mutex> lock(done_mutex);
      double last_bytes = 0, last_t = Now();
      while (!done_cv.wait_for(lock, std::chrono::duration<double>(stats_interval_s), [&] { return done; })) {
        const JitterBufferStats js = view.buffer->stats();
        v1::Downlink d;
        auto* s = d.mutable_stats();
        s->set_frames_received(decoded);
        s->set_frames_lost(js.lost);
        s->set_frames_late(js.late);
        s->set_frames_bad(bad);
        s->set_render_fps(render_fps);
        {
          std::lock_guard<std::mutex> ll(latency_mutex);
          s->set_latency_ms_p50(latency_ms.empty() ? -1 : latency_ms.Median());
          s->set_latency_ms_p95(latency_ms.empty() ? -1 : latency_ms.Percentile(95));
          latency_ms = SampleStats();
        }
        const double now = Now();
        s->set_receive_kbps(8e-3 * (bytes - last_bytes) / std::max(1e-3, now - last_t));
        last_bytes = static_cast<double>(bytes);
        last_t = now;
        std::lock_guard<std::mutex> wl(write_mutex);
        stream->Write(d);
      }
    });
    ParamDecoder decoder(layout);
    std::vector<std::string> packets;
    const double origin = 0;
    while (stream->Read(&up)) {
      if (up.has_bye()) {
        spdlog::info("session {}: bye ({})", view.id, up.bye().reason());
        break;
      }
      if (!up.has_frames()) {
        ++bad;
        std::lock_guard<std::mutex> wl(write_mutex);
        v1::Downlink d;
        d.mutable_error()->set_message("expected Frames or Bye after Hello");
        stream->Write(d);
        continue;
      }
      bytes += up.frames().payload().size();
      std::string error;
      if (!UnpackPackets(up.frames().payload(), &packets, &error)) {
        ++bad;
      } else {
        std::optional<double> batch_shift;  // relative (decoded) -> sender's absolute clock
        for (const auto& packet : packets) {
          FrameParams f;
          if (!decoder.Decode(packet, &f, &error, origin) || !f.IsValid(&error)) {
            ++bad;
            continue;
          }
          if (up.frames().first_capture_time_s() > 0) {
            if (!batch_shift) batch_shift = up.frames().first_capture_time_s() - f.capture_time_s;
            f.capture_time_s += *batch_shift;
            // Same host (netlab, loopback tests): the clocks agree and arrival latency is meaningful.
            const double latency = SteadyNowSeconds() - f.capture_time_s;
            if (std::abs(latency) < 60) {
              std::lock_guard<std::mutex> lock(latency_mutex);
              latency_ms.Add(1e3 * latency);
            }
          }
          view.buffer->Push(f, Now());
          if (observer) observer(view.id, f);
          ++decoded;
        }
      }
      if (!error.empty()) {
        std::lock_guard<std::mutex> wl(write_mutex);
        v1::Downlink d;
        d.mutable_error()->set_message("bad frame: " + error);
        stream->Write(d);
      }
    }
    {
      std::lock_guard<std::mutex> lock(done_mutex);
      done = true;
    }
    done_cv.notify_all();
    stats_thread.join();
    {
      std::lock_guard<std::mutex> lock(mutex);
      sessions.erase(view.id);
      counters.frames_received += decoded;
      counters.frames_bad += bad;
      counters.bytes_received += bytes;
    }
    spdlog::info("session {} ended: {} frames, {} bad", view.id, decoded.load(), bad.load());
    return grpc::Status::OK;
  }
};

ReceiverServer::ReceiverServer(ReceiverServerOptions options, std::map<std::string, AvatarEntry> avatars)
    : impl_(std::make_unique<Impl>()) {
  options.Check();
  impl_->options = std::move(options);
  impl_->avatars = std::move(avatars);
}

ReceiverServer::~ReceiverServer() { Shutdown(); }

void ReceiverServer::Start() {
  const auto& o = impl_->options;
  std::shared_ptr<grpc::ServerCredentials> credentials;
  if (o.plaintext) {
    credentials = grpc::InsecureServerCredentials();
  } else {
    grpc::SslServerCredentialsOptions ssl(o.tls_client_ca.empty()
                                              ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                              : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
    ssl.pem_key_cert_pairs.push_back({ReadFileBytes(o.tls_key), ReadFileBytes(o.tls_cert)});
    if (!o.tls_client_ca.empty()) ssl.pem_root_certs = ReadFileBytes(o.tls_client_ca);
    credentials = grpc::SslServerCredentials(ssl);
  }
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(o.listen, credentials, &impl_->port);
  builder.RegisterService(impl_.get());
  // Let senders keep the stream alive with pings; answer them promptly.
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 5000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_BDP_PROBE, 0);  // its pings would dominate a narrow link
  // A large receive window: otherwise every small message earns a WINDOW_UPDATE,
  // and its TCP ACK costs the narrow uplink a packet per message.
  builder.AddChannelArgument(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 8 << 20);
  impl_->server = builder.BuildAndStart();
  if (!impl_->server || impl_->port == 0)
    throw std::runtime_error("receiver: cannot listen on " + o.listen + " (in use?)");
  spdlog::info("receiver listening on {} (port {}, {})", o.listen, impl_->port, o.plaintext ? "plaintext" : "TLS");
}

void ReceiverServer::Shutdown() {
  if (impl_ && impl_->server) {
    impl_->server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
    impl_->server->Wait();
    impl_->server.reset();
  }
}

int ReceiverServer::port() const { return impl_->port; }

std::vector<SessionView> ReceiverServer::Sessions() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  std::vector<SessionView> v;
  for (const auto& [id, s] : impl_->sessions) v.push_back(s);
  std::sort(v.begin(), v.end(), [](const SessionView& a, const SessionView& b) { return a.started_s < b.started_s; });
  return v;
}

ServerCounters ReceiverServer::counters() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->counters;
}

void ReceiverServer::SetFrameObserver(std::function<void(const std::string&, const FrameParams&)> observer) {
  impl_->observer = std::move(observer);
}

void ReceiverServer::SetRenderFps(double fps) { impl_->render_fps = fps; }
double ReceiverServer::Now() const { return impl_->Now(); }

}  // namespace headcast
