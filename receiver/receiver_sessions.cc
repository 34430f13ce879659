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

  bool Write(const v1::Downlink& d) {
    std::lock_guard<std::mutex> lock(write_mutex);
    return channel.Write(d);
  }
  void SendError(const std::string& message) {
    v1::Downlink d;
    d.mutable_error()->set_message(message);
    Write(d);
  }
};

namespace {

// The Stats thread of one session, owned: it stops and is joined when this
// goes out of scope, however the session ends.
class StatsThread {
 public:
  template <typename Body>
  StatsThread(double interval_s, Body body)
      : thread_([this, interval_s, body] {
          std::unique_lock<std::mutex> lock(mutex_);
          while (!cv_.wait_for(lock, std::chrono::duration<double>(interval_s), [&] { return done_; })) {
            lock.unlock();
            try {
              body();
            } catch (const std::exception& e) {
              spdlog::warn("stats: {}", e.what());
            }
            lock.lock();
          }
        }) {}
  ~StatsThread() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false;
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
    end = Stream(session, layout, stats_interval_s);
  } catch (const std::exception& e) {
    end = {SessionEndCode::kInternal, std::string("receiver failure: ") + e.what()};
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

SessionEnd ReceiverSessions::Stream(Session& session, const CodecLayout& layout, double stats_interval_s) {
  const SessionView& view = session.view;
  {
    v1::Downlink d;
    d.mutable_welcome()->set_protocol_version(kProtocolVersion);
    d.mutable_welcome()->set_session_id(view.id);
    d.mutable_welcome()->set_target_delay_s(options_.target_delay_s);
    d.mutable_welcome()->set_stats_interval_s(stats_interval_s);
    session.Write(d);
  }
  // Stats go back from their own thread, so a silent sender still hears from us.
  double last_bytes = 0, last_t = Now();
  StatsThread stats(stats_interval_s, [&] {
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
    last_bytes = static_cast<double>(session.bytes);
    last_t = now;
    session.Write(d);
  });
  ParamDecoder decoder(layout);
  std::vector<std::string> packets;
  const double origin = 0;
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
    session.bytes += up.frames().payload().size();
    std::string error;
    const double first_capture = up.frames().first_capture_time_s();
    if (!UnpackPackets(up.frames().payload(), &packets, &error)) {
      ++session.bad;
    } else if (packets.size() != up.frames().count()) {
      error = "the message says " + std::to_string(up.frames().count()) + " frames and carries " +
              std::to_string(packets.size());
      ++session.bad;
    } else if (!std::isfinite(first_capture) || std::abs(first_capture) > 1e12) {
      // One absurd time would shift every later frame of the batch out of the jitter buffer's window.
      error = "first_capture_time_s is not a time";
      session.bad += packets.size();
    } else {
      std::optional<double> batch_shift;  // relative (decoded) -> sender's absolute clock
      for (const auto& packet : packets) {
        FrameParams f;
        if (!decoder.Decode(packet, &f, &error, origin) || !f.IsValid(&error)) {
          ++session.bad;
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
        ++session.decoded;
      }
    }
    if (!error.empty()) session.SendError("bad frame: " + error);
  }
  return {};
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
  return counters_;
}

void ReceiverSessions::SetFrameObserver(std::function<void(const std::string&, const FrameParams&)> observer) {
  observer_ = std::move(observer);
}

void ReceiverSessions::SetRenderFps(double fps) { render_fps_ = fps; }
double ReceiverSessions::Now() const { return SteadyNowSeconds() - t0_; }

}  // namespace headcast
