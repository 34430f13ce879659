// The receiver's gRPC server: one bidirectional stream per session, Hello
// checked (protocol version, avatar, bearer token, parameter layout), frames
// decoded into each session's jitter buffer, Stats sent back. Bad input ends
// at most the session that sent it; the server keeps serving the others.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "proto/protocol.h"
#include "receiver/jitter_buffer.h"

namespace headcast {

struct ReceiverServerOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 picks a free one
  std::vector<std::string> tokens;         // accepted bearer tokens (required unless allow_no_token)
  bool allow_no_token = false;             // only with plaintext on loopback
  bool plaintext = false;                  // TLS off: only allowed when listening on loopback
  std::string tls_cert, tls_key;           // PEM files: server certificate chain and key
  std::string tls_client_ca;               // PEM: if set, clients must present a certificate signed by it
  int max_sessions = 16;
  double target_delay_s = 0.1;    // jitter buffer delay
  double stats_interval_s = 1.0;  // how often Stats go back, seconds
  void Check() const;             // throws std::invalid_argument, e.g. plaintext on a non-loopback address
};

// What an avatar id stands for, to validate layouts.
struct AvatarEntry {
  std::string head_model_fingerprint;
  int num_expression = 0;
};

// A live session, as the render side sees it.
struct SessionView {
  std::string id, avatar_id, sender_name;
  std::shared_ptr<JitterBuffer> buffer;
  double started_s = 0;
};

struct ServerCounters {
  uint64_t sessions_started = 0, sessions_rejected = 0, frames_received = 0, frames_bad = 0, bytes_received = 0;
};

class ReceiverServer {
 public:
  ReceiverServer(ReceiverServerOptions options, std::map<std::string, AvatarEntry> avatars);
  ~ReceiverServer();
  // Binds and serves in the background; throws if the address cannot be bound
  // or TLS files cannot be read.
  void Start();
  void Shutdown();
  int port() const;  // the bound port (after Start)

  // Sessions currently streaming, oldest first.
  std::vector<SessionView> Sessions() const;
  ServerCounters counters() const;
  // Called with every decoded, valid frame (from gRPC threads), e.g. to record
  // the stream or to test it. Set before Start.
  void SetFrameObserver(std::function<void(const std::string& session_id, const FrameParams&)> observer);
  // Render fps to report back in Stats (set by the render loop).
  void SetRenderFps(double fps);
  // Seconds on the receiver clock the server uses (steady, since start).
  double Now() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
