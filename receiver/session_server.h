// The receiver's gRPC adapter: one bidirectional stream per session, each
// handed to ReceiverSessions (the transport-free protocol) through a
// DownlinkChannel over the stream. TLS (optionally mutual), keepalive, the thread
// quota and the listening address live here; everything the protocol says lives there.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "receiver/receiver_sessions.h"

namespace headcast {

struct ReceiverServerOptions : ReceiverSessionOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 picks a free one
  bool plaintext = false;                  // TLS off: only allowed when listening on loopback
  std::string tls_cert, tls_key;           // PEM files: server certificate chain and key
  std::string tls_client_ca;               // PEM: if set, clients must present a certificate signed by it
  // Take frames as UDP datagrams from senders that ask (proto DatagramOffer):
  // on `datagram_port` of the listening address; -1: the gRPC port's number
  // (any free port when that is taken), 0: any free port.
  bool datagrams = true;
  int datagram_port = -1;
  void Check() const;  // throws std::invalid_argument, e.g. plaintext on a non-loopback address
};

// gRPC's thread quota for the server: every session's stream, as many again
// for streams still before Hello, and gRPC's own pollers.
int MaxServerThreads(const ReceiverServerOptions& options);

class ReceiverServer {
 public:
  ReceiverServer(ReceiverServerOptions options, std::map<std::string, AvatarEntry> avatars);
  ~ReceiverServer();
  // Binds and serves in the background; throws if the address cannot be bound
  // or TLS files cannot be read.
  void Start();
  void Shutdown();
  int port() const;           // the bound port (after Start)
  int datagram_port() const;  // the bound UDP port (after Start; 0: no datagrams)

  // The sessions behind the server (what is streaming, counters, the frame observer).
  ReceiverSessions& sessions() { return sessions_; }
  const ReceiverSessions& sessions() const { return sessions_; }
  std::vector<SessionView> Sessions() const { return sessions_.Sessions(); }
  ServerCounters counters() const { return sessions_.counters(); }
  void SetFrameObserver(std::function<void(const std::string& session_id, const FrameParams&)> observer) {
    sessions_.SetFrameObserver(std::move(observer));
  }
  void SetRenderFps(double fps) { sessions_.SetRenderFps(fps); }
  double Now() const { return sessions_.Now(); }

 private:
  void StartDatagrams();
  struct Impl;
  ReceiverServerOptions options_;
  ReceiverSessions sessions_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
