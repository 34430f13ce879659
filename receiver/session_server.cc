// The receiver's gRPC adapter.
#include "receiver/session_server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <thread>

#include "common/core/options.h"
#include "common/core/udp_socket.h"
#include "common/core/zip_archive.h"
#include "proto/datagram.h"
#include "proto/headcast.grpc.pb.h"
#include "proto/protocol.h"

namespace headcast {

void ReceiverServerOptions::Check() const {
  OptionsCheck c("receiver");
  std::string why;
  const bool parsed = ParseHostPort(listen, nullptr, &why);
  c.That(parsed, "listen: " + why);
  c.That(tls_cert.empty() == tls_key.empty(), "tls_cert and tls_key go together");
  c.ReadableFile("tls_cert", tls_cert).ReadableFile("tls_key", tls_key).ReadableFile("tls_client_ca", tls_client_ca);
  c.That(!plaintext || IsLoopbackAddress(listen),
         "plaintext is only allowed on a loopback address (got " + listen + "); configure TLS");
  c.That(plaintext || (!tls_cert.empty() && !tls_key.empty()),
         "TLS needs tls_cert and tls_key (or plaintext on loopback)");
  c.InRange("datagram_port", datagram_port, -1, 65535);
  c.That(!tokens.empty() || (allow_no_token && plaintext),
         "bearer tokens are required (allow_no_token only with plaintext on loopback)");
  c.ThrowIfErrors();
  ReceiverSessionOptions::Check();
}

namespace {

// A session's stream as the protocol's channel. The token comes from the
// "authorization: Bearer ..." metadata when the sender put it there.
class GrpcDownlinkChannel final : public DownlinkChannel {
 public:
  GrpcDownlinkChannel(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::Downlink, v1::Uplink>* stream)
      : context_(context), stream_(stream) {}
  bool Write(const v1::Downlink& m) override { return stream_->Write(m); }
  bool Read(v1::Uplink* m) override { return stream_->Read(m); }
  void CloseWrites() override {}  // the call's status closes the stream when the handler returns
  void Cancel() override { context_->TryCancel(); }
  std::string bearer_token() const override {
    const auto& metadata = context_->client_metadata();
    auto it = metadata.find("authorization");
    if (it == metadata.end()) return {};
    const std::string value(it->second.data(), it->second.size());
    return value.rfind("Bearer ", 0) == 0 ? value.substr(7) : std::string();
  }

 private:
  grpc::ServerContext* context_;
  grpc::ServerReaderWriter<v1::Downlink, v1::Uplink>* stream_;
};

grpc::StatusCode ToGrpc(SessionEndCode code) {
  switch (code) {
    case SessionEndCode::kOk:
      return grpc::StatusCode::OK;
    case SessionEndCode::kCancelled:
      return grpc::StatusCode::CANCELLED;
    case SessionEndCode::kDeadlineExceeded:
      return grpc::StatusCode::DEADLINE_EXCEEDED;
    case SessionEndCode::kInvalidArgument:
      return grpc::StatusCode::INVALID_ARGUMENT;
    case SessionEndCode::kFailedPrecondition:
      return grpc::StatusCode::FAILED_PRECONDITION;
    case SessionEndCode::kUnauthenticated:
      return grpc::StatusCode::UNAUTHENTICATED;
    case SessionEndCode::kNotFound:
      return grpc::StatusCode::NOT_FOUND;
    case SessionEndCode::kResourceExhausted:
      return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case SessionEndCode::kInternal:
      return grpc::StatusCode::INTERNAL;
  }
  return grpc::StatusCode::UNKNOWN;
}

}  // namespace

struct ReceiverServer::Impl final : public v1::Headcast::Service {
  explicit Impl(ReceiverSessions& s) : sessions(s) {}
  ReceiverSessions& sessions;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  std::optional<UdpSocket> udp;
  std::thread udp_thread;
  std::atomic<bool> udp_stop{false};

  grpc::Status Session(grpc::ServerContext* context,
                       grpc::ServerReaderWriter<v1::Downlink, v1::Uplink>* stream) override {
    GrpcDownlinkChannel channel(context, stream);
    const SessionEnd end = sessions.Serve(channel);
    return end.code == SessionEndCode::kOk ? grpc::Status::OK : grpc::Status(ToGrpc(end.code), end.message);
  }
};

ReceiverServer::ReceiverServer(ReceiverServerOptions options, std::map<std::string, AvatarEntry> avatars)
    : options_((options.Check(), std::move(options))),
      sessions_(options_, std::move(avatars)),
      impl_(std::make_unique<Impl>(sessions_)) {}

ReceiverServer::~ReceiverServer() { Shutdown(); }

void ReceiverServer::Start() {
  const auto& o = options_;
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
  // gRPC sets SO_REUSEPORT by default: a second receiver on the same port
  // would start, say "listening" and take half the senders. Refuse instead.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.RegisterService(impl_.get());
  // Each open stream holds one of gRPC's threads: bounded, so a flood of
  // streams that never say Hello (the watchdog closes them after
  // hello_timeout_s) cannot take the machine's threads; beyond the quota
  // gRPC answers RESOURCE_EXHAUSTED and a real sender retries.
  grpc::ResourceQuota quota("headcast-receiver");
  quota.SetMaxThreads(MaxServerThreads(o));
  builder.SetResourceQuota(quota);
  // Pings find half-open connections (a laptop asleep, a cut cable) the idle timeout would wait for.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 20000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 10000);
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
  if (o.datagrams) StartDatagrams();
}

void ReceiverServer::StartDatagrams() {
  const auto& o = options_;
  HostPort where;
  std::string why;
  ParseHostPort(o.listen, &where, &why);  // checked in Check()
  if (o.datagram_port >= 0) {
    impl_->udp = UdpSocket::Bind(where.host, o.datagram_port);
  } else {
    try {  // the gRPC port's number first: one number for a firewall rule
      impl_->udp = UdpSocket::Bind(where.host, impl_->port);
    } catch (const std::runtime_error& e) {
      spdlog::warn("receiver: {}; datagrams on another port", e.what());
      impl_->udp = UdpSocket::Bind(where.host, 0);
    }
  }
  const int udp_port = impl_->udp->port();
  // The socket outlives every session that may answer through it: Shutdown
  // joins this thread, and sessions end with the server before it is closed.
  sessions_.EnableDatagrams(udp_port, [udp = &*impl_->udp](const std::string& peer, const std::string& datagram) {
    return udp->SendTo(peer, datagram);
  });
  impl_->udp_thread = std::thread([this] {
    std::string datagram, peer;
    while (!impl_->udp_stop) {
      // Short waits: Shutdown is prompt without a wake-up socket.
      switch (impl_->udp->Receive(&datagram, kMaxDatagramBytes, 100, &peer)) {
        case UdpSocket::Received::kDatagram:
          sessions_.TakeDatagram(datagram, peer);
          break;
        case UdpSocket::Received::kTooLarge:
          sessions_.TakeDatagram({});  // counted as refused
          break;
        case UdpSocket::Received::kTimeout:
          break;
        case UdpSocket::Received::kError:
          std::this_thread::sleep_for(std::chrono::milliseconds(10));  // never a busy loop
          break;
      }
    }
  });
  spdlog::info("receiver takes frames as datagrams on UDP port {}", udp_port);
}

void ReceiverServer::Shutdown() {
  if (impl_ && impl_->udp_thread.joinable()) {
    impl_->udp_stop = true;
    impl_->udp_thread.join();
  }
  if (impl_ && impl_->server) {
    impl_->server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
    impl_->server->Wait();
    impl_->server.reset();
  }
}

int ReceiverServer::port() const { return impl_->port; }
int ReceiverServer::datagram_port() const { return impl_->udp ? impl_->udp->port() : 0; }

int MaxServerThreads(const ReceiverServerOptions& o) { return 2 * o.max_sessions + 16; }

}  // namespace headcast
