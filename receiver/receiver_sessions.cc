// The receiver's sessions.
#include "receiver/receiver_sessions.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <optional>
#include <thread>

#include "common/codec/param_codec.h"
#include "common/core/log.h"
#include "common/core/options.h"
#include "proto/convert.h"
#include "proto/datagram.h"
#include "proto/protocol.h"

namespace headcast {

void ReceiverSessionOptions::Check() const {
  OptionsCheck c("receiver sessions");
  c.InRange("max_sessions", max_sessions, 1, 10000);
  c.InRange("target_delay_s", target_delay_s, 0, 10).InRange("stats_interval_s", stats_interval_s, 0.05, 3600);
  c.That(!tokens.empty() || allow_no_token, "bearer tokens are required (or allow_no_token)");
  c.InRange("hello_timeout_s", hello_timeout_s, 0.05, 600).InRange("idle_timeout_s", idle_timeout_s, 0, 86400);
  c.InRange("evict_silent_s", evict_silent_s, 0, 86400);
  c.ThrowIfErrors();
}

ShowPolicy ShowPolicy::Parse(const std::string& text) {
  ShowPolicy p;
  if (text == "first") {
    p.kind = Kind::kFirst;
  } else if (text == "latest") {
    p.kind = Kind::kLatest;
  } else if (text.rfind("name:", 0) == 0 && text.size() > 5) {
    p.kind = Kind::kNamed;
    p.name = text.substr(5);
  } else {
    throw std::invalid_argument("--show wants first, latest or name:SENDER (got '" + text + "')");
  }
  return p;
}

std::vector<SessionView> DisplayOrder(std::vector<SessionView> sessions, const ShowPolicy& policy) {
  switch (policy.kind) {
    case ShowPolicy::Kind::kFirst:
      break;
    case ShowPolicy::Kind::kLatest:
      std::reverse(sessions.begin(), sessions.end());
      break;
    case ShowPolicy::Kind::kNamed:
      std::stable_partition(sessions.begin(), sessions.end(),
                            [&](const SessionView& s) { return s.sender_name == policy.name; });
      break;
  }
  return sessions;
}

namespace {

// The most bytes of a peer's text a Reject or a log line repeats.
constexpr size_t kMaxEchoBytes = 300;

// Constant-time comparison, so response times do not reveal a token's prefix.
bool SameToken(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  return diff == 0;
}

}  // namespace

// One streaming session's state: what its stats thread and its reading loop share.
struct ReceiverSessions::Session {
  explicit Session(DownlinkChannel& c) : channel(c) {}
  DownlinkChannel& channel;
  SessionView view;
  std::mutex write_mutex;  // one Write at a time per stream
  std::atomic<uint64_t> bad{0}, bytes{0}, decoded{0};
  std::mutex latency_mutex;
  SampleStats latency_ms;  // capture -> arrival, this stats interval
  std::atomic<double> last_message_s{0};
  std::atomic<bool> idle_ended{false};  // the watchdog cancelled the stream, or a new sender displaced it
  bool displaced = false;               // the latter (under the sessions' mutex)

  // What decoding needs, one Frames message at a time whichever way it came
  // (the stream or a datagram): under frames_mutex.
  std::mutex frames_mutex;
  std::optional<ParamDecoder> decoder;
  std::optional<DatagramKey> datagram_key;  // set when the session takes datagrams
  DatagramOrder datagram_order;
  double last_key_request_s = -1;
  uint64_t last_sequence = 0;     // of the last frame decoded
  std::string failure;            // a failure while taking a datagram, which ends the session
  std::string datagram_peer;      // where the last authenticated datagram came from
  DatagramReply reply;            // sends a datagram back (set before datagrams are routed here)
  uint32_t downlink_counter = 0;  // under write_mutex
  std::atomic<uint64_t> datagrams{0}, datagrams_lost{0}, datagrams_refused{0};
  // Asks the session's downlink thread to send a KeyFrameRequest now.
  std::atomic<bool> want_key_frame{false};
  std::function<void()> poke_downlink;

  bool Write(const v1::Downlink& d) {
    std::lock_guard<std::mutex> lock(write_mutex);
    return channel.Write(d);
  }
  // Stats and key frame requests: as a datagram to where the session's
  // datagrams come from when there is such a place (a message on the stream
  // costs a narrow uplink its ACKs), else on the stream.
  void Send(const v1::Downlink& d) {
    std::string peer;
    if (datagram_key) {
      std::lock_guard<std::mutex> lock(frames_mutex);
      peer = datagram_peer;
    }
    if (!peer.empty() && reply) {
      std::lock_guard<std::mutex> lock(write_mutex);
      if (reply(peer,
                SealDatagram(*datagram_key, DatagramDirection::kDownlink, ++downlink_counter, d.SerializeAsString())))
        return;
    }
    Write(d);
  }
  void SendError(const std::string& message) {
    v1::Downlink d;
    d.mutable_error()->set_message(message);
    Write(d);
  }
};

namespace {

// The downlink thread of one session, owned: `periodic` every interval (Stats)
// and `poked` as soon as Poke() is called (a KeyFrameRequest), so that the
// threads which find a need never block on the stream's writes. It stops and
// is joined when this goes out of scope, however the session ends.
class DownlinkThread {
 public:
  template <typename Periodic, typename Poked>
  DownlinkThread(double interval_s, Periodic periodic, Poked poked)
      : thread_([this, interval_s, periodic, poked] {
          using Clock = std::chrono::steady_clock;
          const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(interval_s));
          auto next = Clock::now() + interval;
          std::unique_lock<std::mutex> lock(mutex_);
          while (!done_) {
            cv_.wait_until(lock, next, [&] { return done_ || poked_; });
            if (done_) break;
            const bool poke = poked_;
            poked_ = false;
            const bool due = Clock::now() >= next;
            if (due) next = Clock::now() + interval;
            lock.unlock();
            try {
              if (poke) poked();
              if (due) periodic();
            } catch (const std::exception& e) {
              spdlog::warn("downlink: {}", e.what());
            }
            lock.lock();
          }
        }) {}
  ~DownlinkThread() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  void Poke() {
    std::lock_guard<std::mutex> lock(mutex_);
    poked_ = true;
    cv_.notify_all();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false, poked_ = false;
  std::thread thread_;  // last: started once the members it uses exist
};

}  // namespace

ReceiverSessions::ReceiverSessions(ReceiverSessionOptions options, std::map<std::string, AvatarEntry> avatars)
    : options_((options.Check(), std::move(options))), avatars_(std::move(avatars)), watchdog_([this] { Watch(); }) {}

ReceiverSessions::~ReceiverSessions() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  watch_cv_.notify_all();
  watchdog_.join();
}

void ReceiverSessions::Watch() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!watch_cv_.wait_for(lock, std::chrono::milliseconds(100), [&] { return stopping_; })) {
    const double now = Now();
    for (auto it = awaiting_hello_.begin(); it != awaiting_hello_.end();) {
      if (now - it->second < options_.hello_timeout_s) {
        ++it;
        continue;
      }
      it->first->Cancel();  // its Serve sees the entry gone and says why
      ++counters_.hello_timeouts;
      it = awaiting_hello_.erase(it);
    }
    if (options_.idle_timeout_s <= 0) continue;
    for (auto& [id, session] : live_) {
      if (session->idle_ended || now - session->last_message_s < options_.idle_timeout_s) continue;
      session->idle_ended = true;
      ++counters_.idle_timeouts;
      session->channel.Cancel();
    }
  }
}

SessionEnd ReceiverSessions::Reject(DownlinkChannel& channel, int reason, const std::string& message,
                                    SessionEndCode code) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.sessions_rejected;  // before the reply, so whoever reads it sees the count
  }
  // What goes back and into the log is bounded: a huge Hello must not come back huge.
  const std::string bounded = Printable(message, kMaxEchoBytes);
  v1::Downlink d;
  d.mutable_reject()->set_reason(static_cast<v1::Reject::Reason>(reason));
  d.mutable_reject()->set_message(bounded);
  channel.Write(d);
  spdlog::info("session rejected: {}", bounded);
  return {code, bounded};
}

SessionEnd ReceiverSessions::Serve(DownlinkChannel& channel) {
  v1::Uplink up;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    awaiting_hello_[&channel] = Now();
  }
  const bool read = channel.Read(&up);
  bool timed_out = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    timed_out = awaiting_hello_.erase(&channel) == 0;  // the watchdog took it out and cancelled the stream
  }
  if (timed_out) {
    spdlog::info("stream closed: no Hello within {} s", options_.hello_timeout_s);
    return {SessionEndCode::kDeadlineExceeded, "no Hello within the deadline"};
  }
  if (!read) return {SessionEndCode::kCancelled, "stream closed before Hello"};
  if (!up.has_hello())
    return Reject(channel, v1::Reject::PROTOCOL, "the stream must start with Hello", SessionEndCode::kInvalidArgument);
  const v1::Hello& hello = up.hello();
  if (hello.protocol_version() != kProtocolVersion)
    return Reject(channel, v1::Reject::PROTOCOL_VERSION,
                  "protocol version " + std::to_string(hello.protocol_version()) +
                      " is not supported; this receiver speaks version " + std::to_string(kProtocolVersion),
                  SessionEndCode::kFailedPrecondition);
  // NaN or negative asks fall back to our own interval; at most a minute.
  const double asked = std::isfinite(hello.stats_interval_s()) ? hello.stats_interval_s() : 0.0;
  const double stats_interval_s =
      std::clamp(asked, options_.stats_interval_s, std::max(60.0, options_.stats_interval_s));
  const std::string transport_token = channel.bearer_token();
  const std::string token = transport_token.empty() ? hello.auth_token() : transport_token;
  if (!options_.tokens.empty() || !options_.allow_no_token) {
    if (token.empty())
      return Reject(channel, v1::Reject::UNAUTHENTICATED, "no bearer token", SessionEndCode::kUnauthenticated);
    bool known = false;
    for (const auto& t : options_.tokens) known |= SameToken(t, token);
    if (!known)
      return Reject(channel, v1::Reject::UNAUTHENTICATED, "wrong bearer token", SessionEndCode::kUnauthenticated);
  }
  auto avatar = avatars_.find(hello.avatar_id());
  if (avatar == avatars_.end())
    return Reject(channel, v1::Reject::UNKNOWN_AVATAR,
                  "no avatar '" + Printable(hello.avatar_id()) + "' on this receiver", SessionEndCode::kNotFound);
  CodecLayout layout;
  std::string why;
  if (!FromProto(hello.layout(), &layout, &why))
    return Reject(channel, v1::Reject::BAD_LAYOUT, "bad parameter layout: " + why, SessionEndCode::kInvalidArgument);
  if (layout.num_expression != avatar->second.num_expression)
    return Reject(channel, v1::Reject::BAD_LAYOUT,
                  "layout has " + std::to_string(layout.num_expression) + " expression components, avatar '" +
                      Printable(hello.avatar_id()) + "' has " + std::to_string(avatar->second.num_expression),
                  SessionEndCode::kInvalidArgument);
  // Same-sized expression bases of two models are still different bases.
  if (layout.head_model_fingerprint != avatar->second.head_model_fingerprint)
    return Reject(channel, v1::Reject::BAD_LAYOUT,
                  layout.head_model_fingerprint.empty()
                      ? "the layout names no head model (head_model_fingerprint); the sender is too old"
                      : "the sender fits head model " + Printable(layout.head_model_fingerprint) + ", avatar '" +
                            Printable(hello.avatar_id()) + "' belongs to " + avatar->second.head_model_fingerprint,
                  SessionEndCode::kInvalidArgument);
  Session session(channel);
  SessionView& view = session.view;
  bool busy = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    busy = static_cast<int>(sessions_.size()) >= options_.max_sessions;
    if (busy && options_.evict_silent_s > 0) {
      // The longest-silent session leaves the display and the count now; its
      // own Serve sees the cancelled stream, says why and cleans up.
      Session* silent = nullptr;
      for (auto& [id, s] : live_)
        if (sessions_.count(id) && !s->idle_ended && (!silent || s->last_message_s < silent->last_message_s))
          silent = s;
      if (silent && Now() - silent->last_message_s >= options_.evict_silent_s) {
        silent->idle_ended = true;
        silent->displaced = true;
        silent->channel.Cancel();
        sessions_.erase(silent->view.id);
        ++counters_.evictions;
        busy = false;
      }
    }
    if (!busy) {
      view.id = "s" + std::to_string(next_id_++);
      view.avatar_id = hello.avatar_id();
      view.sender_name = Printable(hello.sender_name());  // shown in the window's overlay too
      JitterBufferOptions jb;
      jb.target_delay_s = options_.target_delay_s;
      view.buffer = std::make_shared<JitterBuffer>(jb);
      view.started_s = Now();
      session.last_message_s = view.started_s;
      sessions_[view.id] = view;
      live_[view.id] = &session;
      ++counters_.sessions_started;
    }
  }
  // Refused outside the lock: Reject takes it again.
  if (busy)
    return Reject(channel, v1::Reject::BUSY, "receiver busy (" + std::to_string(options_.max_sessions) + " sessions)",
                  SessionEndCode::kResourceExhausted);
  // Both are safe to log: the avatar id is one of ours, the name was made printable above.
  spdlog::info("session {} started: avatar '{}', sender '{}'", view.id, view.avatar_id, view.sender_name);
  SessionEnd end;
  try {
    end = Stream(session, layout, stats_interval_s, hello.datagrams());
  } catch (const std::exception& e) {
    end = {SessionEndCode::kInternal, std::string("receiver failure: ") + e.what()};
  }
  {
    std::lock_guard<std::mutex> lock(session.frames_mutex);
    if (!session.failure.empty()) end = {SessionEndCode::kInternal, session.failure};
  }
  if (end.code == SessionEndCode::kInternal) {
    spdlog::error("session {}: {}", view.id, end.message);
    session.SendError(end.message);
  }
  if (session.idle_ended) {
    bool displaced = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      displaced = session.displaced;
    }
    end = {SessionEndCode::kDeadlineExceeded, "nothing received for " +
                                                  std::to_string(static_cast<int>(Now() - session.last_message_s)) +
                                                  " s" + (displaced ? "; the slot went to a new sender" : "")};
    spdlog::info("session {} ended: {}", view.id, end.message);
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    sessions_.erase(view.id);
    live_.erase(view.id);
    counters_.frames_received += session.decoded;
    counters_.frames_bad += session.bad;
    counters_.bytes_received += session.bytes;
  }
  spdlog::info("session {} ended: {} frames, {} bad", view.id, session.decoded.load(), session.bad.load());
  return end;
}

SessionEnd ReceiverSessions::Stream(Session& session, const CodecLayout& layout, double stats_interval_s,
                                    bool datagrams) {
  const SessionView& view = session.view;
  session.decoder.emplace(layout);
  // Stats go back from their own thread, so a silent sender still hears from us.
  double last_bytes = 0, last_t = Now();
  DownlinkThread downlink(
      stats_interval_s,
      [&] {
        const JitterBufferStats js = view.buffer->stats();
        v1::Downlink d;
        auto* s = d.mutable_stats();
        s->set_frames_received(session.decoded);
        s->set_frames_lost(js.lost);
        s->set_frames_late(js.late);
        s->set_frames_bad(session.bad);
        s->set_render_fps(render_fps_);
        {
          std::lock_guard<std::mutex> ll(session.latency_mutex);
          s->set_latency_ms_p50(session.latency_ms.empty() ? -1 : session.latency_ms.Median());
          s->set_latency_ms_p95(session.latency_ms.empty() ? -1 : session.latency_ms.Percentile(95));
          session.latency_ms = SampleStats();
        }
        const double now = Now();
        s->set_receive_kbps(8e-3 * (session.bytes - last_bytes) / std::max(1e-3, now - last_t));
        s->set_datagrams_received(session.datagrams);
        s->set_datagrams_lost(session.datagrams_lost);
        s->set_datagrams_refused(session.datagrams_refused);
        last_bytes = static_cast<double>(session.bytes);
        last_t = now;
        session.Send(d);
      },
      [&] {
        if (!session.want_key_frame.exchange(false)) return;
        v1::Downlink d;
        {
          std::lock_guard<std::mutex> lock(session.frames_mutex);
          d.mutable_key_frame_request()->set_last_sequence(session.last_sequence);
        }
        session.Send(d);
      });
  session.poke_downlink = [&downlink] { downlink.Poke(); };
  v1::Downlink welcome;
  welcome.mutable_welcome()->set_protocol_version(kProtocolVersion);
  welcome.mutable_welcome()->set_session_id(view.id);
  welcome.mutable_welcome()->set_target_delay_s(options_.target_delay_s);
  welcome.mutable_welcome()->set_stats_interval_s(stats_interval_s);
  // Datagrams are routed to the session from here until the guard below goes,
  // which happens before the downlink thread they poke.
  struct DatagramRoute {
    ReceiverSessions& sessions;
    Session& session;
    ~DatagramRoute() {
      if (!session.datagram_key) return;
      {
        std::lock_guard<std::mutex> lock(sessions.mutex_);
        sessions.by_connection_.erase(session.datagram_key->connection_id);
      }
      // A datagram taken before the erase may still be decoding: wait for it.
      std::lock_guard<std::mutex> wait(session.frames_mutex);
    }
  } route{*this, session};
  const int port = datagram_port_;
  if (datagrams && port > 0) {
    std::lock_guard<std::mutex> lock(mutex_);
    DatagramKey key;
    do key = DatagramKey::Random();
    while (by_connection_.count(key.connection_id));
    session.datagram_key = key;
    session.reply = datagram_reply_;
    by_connection_[key.connection_id] = &session;
    auto* offer = welcome.mutable_welcome()->mutable_datagrams();
    offer->set_port(static_cast<uint32_t>(port));
    offer->set_connection_id(key.connection_id);
    offer->set_key(key.key_bytes());
  }
  session.Write(welcome);
  v1::Uplink up;
  while (session.channel.Read(&up)) {
    session.last_message_s = Now();
    if (up.has_bye()) {
      spdlog::info("session {}: bye ({})", view.id, Printable(up.bye().reason()));
      break;
    }
    if (!up.has_frames()) {
      ++session.bad;
      session.SendError("expected Frames or Bye after Hello");
      continue;
    }
    std::string error;
    {
      std::lock_guard<std::mutex> lock(session.frames_mutex);
      error = TakeFrames(session, up.frames());
    }
    if (!error.empty()) session.SendError("bad frame: " + error);
  }
  return {};
}

std::string ReceiverSessions::TakeFrames(Session& session, const v1::Frames& frames) {
  const SessionView& view = session.view;
  ParamDecoder& decoder = *session.decoder;
  session.bytes += frames.payload().size();
  std::string error;
  std::vector<std::string> packets;
  const double first_capture = frames.first_capture_time_s();
  if (!UnpackPackets(frames.payload(), &packets, &error)) {
    ++session.bad;
  } else if (packets.size() != frames.count()) {
    error =
        "the message says " + std::to_string(frames.count()) + " frames and carries " + std::to_string(packets.size());
    ++session.bad;
  } else if (!std::isfinite(first_capture) || std::abs(first_capture) > 1e12) {
    // One absurd time would shift every later frame of the batch out of the jitter buffer's window.
    error = "first_capture_time_s is not a time";
    session.bad += packets.size();
  } else {
    std::optional<double> batch_shift;  // relative (decoded) -> sender's absolute clock
    for (const auto& packet : packets) {
      // After a lost datagram the deltas up to the next key frame have no
      // reference: passed over (the jitter buffer counts their numbers lost).
      const bool after_gap = session.datagram_key && decoder.waiting_for_key_frame();
      FrameParams f;
      std::string why;
      if (!decoder.Decode(packet, &f, &why) || !f.IsValid(&why)) {
        if (!after_gap) {
          ++session.bad;
          error = why;
        }
        continue;
      }
      if (first_capture > 0) {
        if (!batch_shift) batch_shift = first_capture - f.capture_time_s;
        f.capture_time_s += *batch_shift;
        // Same host (netlab, loopback tests): the clocks agree and arrival latency is meaningful.
        const double latency = SteadyNowSeconds() - f.capture_time_s;
        if (std::abs(latency) < 60) {
          std::lock_guard<std::mutex> lock(session.latency_mutex);
          session.latency_ms.Add(1e3 * latency);
        }
      }
      view.buffer->Push(f, Now());
      if (observer_) observer_(view.id, f);
      session.last_sequence = f.sequence;
      ++session.decoded;
    }
  }
  // A datagram session stuck behind a gap asks for a key frame, again now and
  // then (a request can be slower than the next datagrams, or lost with the link).
  if (session.datagram_key && decoder.waiting_for_key_frame() && session.poke_downlink &&
      (session.last_key_request_s < 0 || Now() - session.last_key_request_s > 0.5)) {
    session.last_key_request_s = Now();
    session.want_key_frame = true;
    session.poke_downlink();
  }
  return error;
}

void ReceiverSessions::EnableDatagrams(int port, DatagramReply reply) {
  std::lock_guard<std::mutex> lock(mutex_);
  datagram_reply_ = std::move(reply);
  datagram_port_ = port;
}

bool ReceiverSessions::TakeDatagram(const std::string& datagram, const std::string& peer) {
  uint32_t id = 0;
  if (!PeekDatagramConnection(datagram, DatagramDirection::kUplink, &id)) {
    ++datagrams_refused_;
    return false;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  auto it = by_connection_.find(id);
  if (it == by_connection_.end()) {
    ++datagrams_refused_;
    return false;
  }
  Session& session = *it->second;
  std::lock_guard<std::mutex> frames_lock(session.frames_mutex);
  lock.unlock();
  uint32_t counter = 0;
  uint64_t missing = 0;
  std::string plaintext, why;
  v1::Frames frames;
  if (!OpenDatagram(*session.datagram_key, DatagramDirection::kUplink, datagram, &counter, &plaintext, &why) ||
      session.datagram_order.Take(counter, &missing) == DatagramOrder::Verdict::kStale) {
    ++session.datagrams_refused;
    ++datagrams_refused_;
    return false;
  }
  // Authenticated and new: the sender's, whatever it carries; answers go
  // where it came from (a sender behind a NAT whose mapping changed included).
  session.last_message_s = Now();
  if (!peer.empty()) session.datagram_peer = peer;
  ++session.datagrams;
  ++datagrams_received_;
  if (missing > 0) {
    session.datagrams_lost += missing;
    session.decoder->AwaitKeyFrame();
  }
  if (!frames.ParseFromString(plaintext)) {
    ++session.bad;
    return true;
  }
  try {
    TakeFrames(session, frames);
  } catch (const std::exception& e) {
    // The frame observer failed: this session ends, as on the stream.
    session.failure = std::string("receiver failure: ") + e.what();
    session.channel.Cancel();
  }
  return true;
}

std::vector<SessionView> ReceiverSessions::Sessions() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<SessionView> v;
  for (const auto& [id, s] : sessions_) {
    v.push_back(s);
    v.back().last_message_s = live_.at(id)->last_message_s;
  }
  std::sort(v.begin(), v.end(), [](const SessionView& a, const SessionView& b) { return a.started_s < b.started_s; });
  return v;
}

ServerCounters ReceiverSessions::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  ServerCounters c = counters_;
  c.datagrams_received = datagrams_received_;
  c.datagrams_refused = datagrams_refused_;
  return c;
}

void ReceiverSessions::SetFrameObserver(std::function<void(const std::string&, const FrameParams&)> observer) {
  observer_ = std::move(observer);
}

void ReceiverSessions::SetRenderFps(double fps) { render_fps_ = fps; }
double ReceiverSessions::Now() const { return SteadyNowSeconds() - t0_; }

}  // namespace headcast
