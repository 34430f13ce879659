// The receiver's side of the protocol, free of any transport: each session's
// Hello checked (protocol version, bearer token, avatar, parameter layout,
// the session limit), Welcome or Reject, frames decoded into the session's
// jitter buffer, Stats sent back on their own schedule. A transport adapter
// (the gRPC server, an in-memory channel in tests) calls Serve once per
// incoming stream. Bad input ends at most the session that sent it.
#pragma once

#include <atomic>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
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
  // A stream that has not said Hello by then is closed: unauthenticated
  // clients must not hold server threads.
  double hello_timeout_s = 5;
  // A session that sends nothing (no frames, no Bye) this long is ended: a
  // stopped or vanished sender must not hold a slot. 0: never.
  double idle_timeout_s = 30;
  // When every slot is taken, a new sender displaces the session that has
  // been silent longest, if that one has sent nothing for this long: a
  // real sender does not wait out the idle timeout behind stopped ones. 0: never.
  double evict_silent_s = 5;
  void Check() const;
};

// Which live session the display shows. Sessions whose jitter buffer has
// nothing to show (a sender that stopped, a face out of view) are passed over
// for the next one in this order.
struct ShowPolicy {
  enum class Kind { kFirst, kLatest, kNamed };
  Kind kind = Kind::kFirst;  // first: the session that came first keeps the display (a call)
  std::string name;          // kNamed: this sender name first, then the others as kFirst
  // "first", "latest" or "name:SENDER"; throws std::invalid_argument otherwise.
  static ShowPolicy Parse(const std::string& text);
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
  double last_message_s = 0;  // receiver clock of the session's last message
};

// `sessions` (oldest first, as Sessions() gives them) in the order the display tries them.
std::vector<SessionView> DisplayOrder(std::vector<SessionView> sessions, const ShowPolicy& policy);

struct ServerCounters {
  uint64_t sessions_started = 0, sessions_rejected = 0, frames_received = 0, frames_bad = 0, bytes_received = 0;
  uint64_t hello_timeouts = 0, idle_timeouts = 0, evictions = 0;
  // Datagrams taken, and those refused: of no live session, not
  // authenticating, repeated or overtaken, oversized.
  uint64_t datagrams_received = 0, datagrams_refused = 0;
};

// How a session ended, for the transport to pass on (gRPC: the call's status).
enum class SessionEndCode {
  kOk,
  kCancelled,           // the stream closed before Hello
  kDeadlineExceeded,    // no Hello in time, or a session silent too long
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
  // ends that session with kInternal. What it uses must outlive the sessions:
  // they call it until the server has shut down (declare it before the server,
  // or shut the server down before it goes).
  void SetFrameObserver(std::function<void(const std::string& session_id, const FrameParams&)> observer);
  // Sends a datagram to a peer (as TakeDatagram was told it); false if it could not.
  using DatagramReply = std::function<bool(const std::string& peer, const std::string& datagram)>;
  // Offers senders that ask for it (Hello.datagrams) to send their frames as
  // datagrams to this UDP port (0, the default: none); Stats and key frame
  // requests then go back through `reply` to where the session's datagrams
  // come from. Set by the transport that owns the socket, before the first session.
  void EnableDatagrams(int port, DatagramReply reply);
  // One datagram from the transport's socket, from `peer`: opened with its
  // session's key, its frames decoded into that session. False (and counted)
  // when refused. Never throws; safe beside Serve.
  bool TakeDatagram(const std::string& datagram, const std::string& peer = {});
  // Render fps to report back in Stats (set by the render loop).
  void SetRenderFps(double fps);
  // Seconds on the receiver clock (steady, since construction).
  double Now() const;

 private:
  struct Session;
  SessionEnd Stream(Session& session, const CodecLayout& layout, double stats_interval_s, bool datagrams);
  // Decodes one Frames message into the session (its frames_mutex held);
  // returns what was wrong with it, if anything.
  std::string TakeFrames(Session& session, const v1::Frames& frames);
  SessionEnd Reject(DownlinkChannel& channel, int reason, const std::string& message, SessionEndCode code);
  void Watch();  // the watchdog: Hello deadlines and idle sessions
  ReceiverSessionOptions options_;
  std::map<std::string, AvatarEntry> avatars_;
  double t0_ = SteadyNowSeconds();
  mutable std::mutex mutex_;
  std::map<std::string, SessionView> sessions_;
  std::map<std::string, Session*> live_;               // the streams behind sessions_, for the watchdog
  std::map<DownlinkChannel*, double> awaiting_hello_;  // streams not yet past Hello, since when
  std::map<uint32_t, Session*> by_connection_;         // sessions that take datagrams, by connection id
  std::atomic<int> datagram_port_{0};
  DatagramReply datagram_reply_;
  std::atomic<uint64_t> datagrams_received_{0}, datagrams_refused_{0};
  std::condition_variable watch_cv_;
  bool stopping_ = false;
  ServerCounters counters_;
  std::atomic<double> render_fps_{0};
  std::atomic<uint64_t> next_id_{1};
  std::function<void(const std::string&, const FrameParams&)> observer_;
  std::thread watchdog_;  // last: started once everything it reads exists
};

}  // namespace headcast
