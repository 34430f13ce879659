// The sender's gRPC adapter.
#include "sender/grpc_uplink.h"

#include <grpcpp/grpcpp.h>

#include "common/core/udp_socket.h"
#include "common/core/zip_archive.h"
#include "proto/datagram.h"
#include "proto/headcast.grpc.pb.h"
#include "proto/health.grpc.pb.h"
#include "proto/protocol.h"

namespace headcast {
namespace {

std::shared_ptr<grpc::Channel> MakeChannel(const SenderOptions& options) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, static_cast<int>(options.keepalive_s * 1000));
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 5000);
  args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  // No bandwidth-delay-product probing: its pings cost more than our frames on narrow links.
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  // Reconnect quickly after a receiver restart.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, static_cast<int>(options.reconnect_initial_s * 1000));
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, static_cast<int>(options.reconnect_initial_s * 1000));
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, static_cast<int>(options.reconnect_max_s * 1000));
  if (!options.tls_server_name.empty()) args.SetSslTargetNameOverride(options.tls_server_name);
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (options.plaintext) {
    credentials = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadFileBytes(options.tls_ca);
    if (!options.tls_client_cert.empty()) {
      ssl.pem_cert_chain = ReadFileBytes(options.tls_client_cert);
      ssl.pem_private_key = ReadFileBytes(options.tls_client_key);
    }
    credentials = grpc::SslCredentials(ssl);
  }
  return grpc::CreateCustomChannel(options.target, credentials, args);
}

class GrpcUplinkChannel final : public UplinkChannel {
 public:
  GrpcUplinkChannel(v1::Headcast::Stub& stub, const std::string& token) {
    if (!token.empty()) context_.AddMetadata("authorization", "Bearer " + token);
    stream_ = stub.Session(&context_);
  }
  ~GrpcUplinkChannel() override {
    if (!finished_) {
      context_.TryCancel();
      Finish();
    }
  }
  bool Write(const v1::Uplink& m) override { return stream_->Write(m); }
  bool Read(v1::Downlink* m) override { return stream_->Read(m); }
  void CloseWrites() override { stream_->WritesDone(); }
  void Cancel() override { context_.TryCancel(); }
  std::string Finish() override {
    finished_ = true;
    const grpc::Status status = stream_->Finish();
    return status.ok() ? std::string() : status.error_message();
  }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::Uplink, v1::Downlink>> stream_;
  bool finished_ = false;
};

class UdpDatagramPath final : public DatagramPath {
 public:
  explicit UdpDatagramPath(UdpSocket socket) : socket_(std::move(socket)) {}
  bool Send(const std::string& datagram) override { return socket_.Send(datagram); }
  bool Receive(std::string* datagram, int timeout_ms) override {
    return socket_.Receive(datagram, kMaxDatagramBytes, timeout_ms) == UdpSocket::Received::kDatagram;
  }

 private:
  UdpSocket socket_;
};

class GrpcUplinkConnector final : public UplinkConnector {
 public:
  explicit GrpcUplinkConnector(SenderOptions options) : options_(std::move(options)) {}
  std::unique_ptr<UplinkChannel> Open(std::string* error) override {
    if (!stub_) {
      try {  // one HTTP/2 channel for every attempt: gRPC reconnects it underneath
        channel_ = MakeChannel(options_);
        stub_ = v1::Headcast::NewStub(channel_);
      } catch (const std::exception& e) {
        *error = e.what();
        return nullptr;
      }
    }
    // A channel in back-off fails new calls at once, and gRPC's own retry
    // timer and ours can miss each other for seconds after the receiver is
    // back (a restart). Waiting for the channel (a bounded time, so Stop
    // stays prompt) lets the call start as soon as the connection is up.
    if (channel_->GetState(/*try_to_connect=*/true) != GRPC_CHANNEL_READY)
      channel_->WaitForConnected(std::chrono::system_clock::now() +
                                 std::chrono::milliseconds(static_cast<int>(1000 * options_.reconnect_max_s)));
    return std::make_unique<GrpcUplinkChannel>(*stub_, options_.token);
  }
  std::string Describe() const override { return options_.target; }
  // To the host the stream dialled: the receiver's UDP socket listens on the same address.
  std::unique_ptr<DatagramPath> OpenDatagrams(int port, std::string* error) override {
    HostPort target;
    if (!ParseHostPort(options_.target, &target, error)) return nullptr;
    try {
      return std::make_unique<UdpDatagramPath>(UdpSocket::Connect(target.host, port));
    } catch (const std::exception& e) {
      *error = e.what();
      return nullptr;
    }
  }

 private:
  SenderOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Headcast::Stub> stub_;
};

}  // namespace

std::unique_ptr<UplinkConnector> MakeGrpcUplinkConnector(const SenderOptions& options) {
  return std::make_unique<GrpcUplinkConnector>(options);
}

std::string CheckReceiverHealth(const SenderOptions& options, double timeout_s) {
  options.Check();
  auto stub = grpc::health::v1::Health::NewStub(MakeChannel(options));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
  grpc::health::v1::HealthCheckRequest request;
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&context, request, &response);
  if (!status.ok()) return "unreachable: " + status.error_message();
  return grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status());
}

}  // namespace headcast
