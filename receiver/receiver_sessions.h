// The receiver's side of the protocol, free of any transport: each session's
// Hello checked (protocol version, bearer token, avatar, parameter layout,
// the session limit), Welcome or Reject, frames decoded into the session's
// jitter buffer, Stats sent back on their own schedule. A transport adapter
// (the gRPC server, an in-memory channel in tests) calls Serve once per
// incoming stream. Bad input ends at most the session that sent it.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "common/codec/param_codec.h"
#include "common/core/timer.h"
#include "proto/message_channel.h"
#include "receiver/jitter_buffer.h"

namespace headcast {

struct ReceiverSessionOptions {
  std::vector<std::string> tokens;  // accepted bearer tokens (required unless allow_no_token)
  bool allow_no_token = false;      // the transport decides where this is allowed (plaintext loopback)
  int max_sessions = 16;
  double target_delay_s = 0.1;    // jitter buffer delay, seconds
  double stats_interval_s = 1.0;  // how often Stats go back, seconds
  void Check() const;
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

// How a session ended, for the transport to pass on (gRPC: the call's status).
enum class SessionEndCode {
  kOk,
  kCancelled,           // the stream closed before Hello
  kInvalidArgument,     // not a Hello first, a bad layout
  kFailedPrecondition,  // another protocol version
  kUnauthenticated,     // no or a wrong bearer token
  kNotFound,            // no such avatar
  kResourceExhausted,   // the session limit
  kInternal,            // the receiver failed (e.g. the frame observer threw)
};
struct SessionEnd {
  SessionEndCode code = SessionEndCode::kOk;
  std::string message;
};

class ReceiverSessions {
 public:
  ReceiverSessions(ReceiverSessionOptions options, std::map<std::string, AvatarEntry> avatars);
  ~ReceiverSessions();

  // Runs one session on `channel` until the sender says Bye, the stream ends,
  // or the session is refused. Safe to call from many threads at once. Never
  // throws: a failure inside (the frame observer, say) ends this session.
  SessionEnd Serve(DownlinkChannel& channel);

  // Sessions currently streaming, oldest first.
  std::vector<SessionView> Sessions() const;
  ServerCounters counters() const;
  // Called with every decoded, valid frame (from the sessions' threads), e.g.
  // to record the stream. Set before the first session. An exception from it
  // ends that session with kInternal.
  void SetFrameObserver(std::function<void(const std::string& session_id, const FrameParams&)> observer);
  // Render fps to report back in Stats (set by the render loop).
  void SetRenderFps(double fps);
  // Seconds on the receiver clock (steady, since construction).
  double Now() const;

 private:
  struct Session;
  SessionEnd Stream(Session& session, const CodecLayout& layout, double stats_interval_s);
  SessionEnd Reject(DownlinkChannel& channel, int reason, const std::string& message, SessionEndCode code);
  ReceiverSessionOptions options_;
  std::map<std::string, AvatarEntry> avatars_;
  double t0_ = SteadyNowSeconds();
  mutable std::mutex mutex_;
  std::map<std::string, SessionView> sessions_;
  ServerCounters counters_;
  std::atomic<double> render_fps_{0};
  std::atomic<uint64_t> next_id_{1};
  std::function<void(const std::string&, const FrameParams&)> observer_;
};

}  // namespace headcast
