// The sender's sessions (transport-free; gRPC comes in through the connector).
#include "sender/session_client.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <functional>
#include <optional>
#include <thread>

#include "common/core/bounded_queue.h"
#include "common/core/options.h"
#include "common/core/timer.h"
#include "proto/convert.h"
#include "proto/datagram.h"
#include "proto/headcast.pb.h"
#include "proto/protocol.h"
#include "sender/grpc_uplink.h"

namespace headcast {

void SenderOptions::Check() const {
  OptionsCheck c("SenderOptions");
  c.NotEmpty("target", target).NotEmpty("avatar_id", avatar_id).Positive("fps", fps);
  c.InRange("queue_frames", queue_frames, 1, 100000).InRange("max_batch", max_batch, 1, kMaxPacketsPerMessage);
  c.NonNegative("min_send_interval_s", min_send_interval_s).Positive("reconnect_initial_s", reconnect_initial_s);
  c.That(reconnect_max_s >= reconnect_initial_s, "reconnect_max_s must be >= reconnect_initial_s");
  c.Positive("welcome_timeout_s", welcome_timeout_s).Positive("keepalive_s", keepalive_s);
  c.NonNegative("max_kbps", max_kbps).InRange("wire_overhead_bytes", wire_overhead_bytes, 0, 10000);
  c.InRange("downlink_overhead_bytes", downlink_overhead_bytes, 0, 10000)
      .InRange("session_start_bytes", session_start_bytes, 0, 1000000)
      .InRange("stats_interval_s", stats_interval_s, 0, 60);
  c.That(datagrams == "auto" || datagrams == "on" || datagrams == "off",
         "datagrams must be auto, on or off (got '" + datagrams + "')");
  c.InRange("datagram_overhead_bytes", datagram_overhead_bytes, 0, 10000);
  std::string why;
  const bool parsed = ParseHostPort(target, nullptr, &why);
  c.That(parsed, "target: " + why);
  // TLS files are checked here, before any thread or connection: a typo must
  // stop the program at once, with the file's name.
  c.That(tls_client_cert.empty() == tls_client_key.empty(), "tls_client_cert and tls_client_key go together");
  c.ReadableFile("tls_ca", tls_ca).ReadableFile("tls_client_cert", tls_client_cert);
  c.ReadableFile("tls_client_key", tls_client_key);
  c.That(!plaintext || IsLoopbackAddress(target),
         "plaintext is only allowed to a loopback target (got " + target + ")");
  c.That(plaintext || !tls_ca.empty(),
         "TLS needs tls_ca (the CA of the receiver's certificate), or plaintext on loopback");
  c.ThrowIfErrors();
}

bool SenderOptions::WantsDatagrams() const {
  return datagrams == "on" || (datagrams == "auto" && max_kbps > 0 && max_kbps < kNarrowLinkKbps);
}

namespace {
double Seconds() { return SteadyNowSeconds(); }

// One Frames message: the packets and the capture time of the first.
v1::Frames MakeFrames(const std::vector<std::string>& packets, double first_capture_s) {
  v1::Frames f;
  f.set_payload(PackPackets(packets));
  f.set_count(static_cast<uint32_t>(packets.size()));
  f.set_first_capture_time_s(first_capture_s);
  return f;
}

// A batch's packets in datagram-sized Frames messages, in order.
std::vector<v1::Frames> SplitForDatagrams(const std::vector<std::string>& packets,
                                          const std::vector<double>& capture_times) {
  std::vector<v1::Frames> out;
  std::vector<std::string> chunk;
  double chunk_capture = 0;
  auto flush = [&] {
    if (chunk.empty()) return;
    out.push_back(MakeFrames(chunk, chunk_capture));
    chunk.clear();
  };
  size_t bytes = 0;
  // The Frames fields around the payload: count, time, the payload's tag and length.
  constexpr size_t kFieldBytes = 24;
  for (size_t i = 0; i < packets.size(); ++i) {
    const size_t cost = packets[i].size() + 3;  // with its length prefix
    if (!chunk.empty() && bytes + cost + kFieldBytes > kMaxDatagramPlaintext) flush();
    if (chunk.empty()) {
      chunk_capture = capture_times[i];
      bytes = 0;
    }
    chunk.push_back(packets[i]);
    bytes += cost;
  }
  flush();
  return out;
}

// Stats and key frame requests that come back as datagrams, read on a thread
// of its own (beside the stream's reader) until destroyed; only what opens
// under the session's key, in order, reaches `take`.
class DatagramDownlinkReader {
 public:
  DatagramDownlinkReader(DatagramPath& path, const DatagramKey& key, std::function<void(const v1::Downlink&)> take)
      : thread_([this, &path, key, take] {
          DatagramOrder order;
          std::string bytes, plaintext, why;
          while (!stop_) {
            uint32_t counter = 0;
            v1::Downlink d;
            if (path.Receive(&bytes, 100) &&
                OpenDatagram(key, DatagramDirection::kDownlink, bytes, &counter, &plaintext, &why) &&
                order.Take(counter) != DatagramOrder::Verdict::kStale && d.ParseFromString(plaintext) &&
                (d.has_stats() || d.has_key_frame_request()))
              take(d);
          }
        }) {}
  ~DatagramDownlinkReader() {
    stop_ = true;
    thread_.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::thread thread_;  // last: started once stop_ exists
};
}  // namespace

struct SenderClient::Impl {
  SenderOptions options;
  CodecLayout layout;
  std::unique_ptr<UplinkConnector> connector;
  BoundedQueue<FrameParams> queue;
  std::thread worker;
  std::atomic<bool> stop{false};
  std::string bye_reason = "done";
  mutable std::mutex mutex;
  mutable std::condition_variable cv;
  SenderCounters counters;
  std::atomic<double> budget_kbps{0};
  std::atomic<int> downlink_debt_bytes{0};  // uplink cost of downlink messages, not yet charged

  uint64_t sent_before_session = 0;
  v1::Reject::Reason session_rejection = v1::Reject::UNSPECIFIED;  // this session's Reject, if any
  v1::DatagramOffer offer;                                         // this session's Welcome offer, if any
  std::atomic<bool> key_frame_wanted{false};                       // the receiver asked for one
  // Datagrams sent this session, and when the first went: if the receiver's
  // Stats say none arrived a while later (a firewall), frames go back to the stream.
  uint64_t session_datagrams = 0;
  double first_datagram_s = -1;
  uint64_t stats_datagrams_received = 0, stats_datagrams_lost = 0;  // as the last Stats said
  std::atomic<bool> datagrams_blocked{false};

  Impl(SenderOptions o, CodecLayout l, std::unique_ptr<UplinkConnector> c)
      : options(std::move(o)), layout(std::move(l)), connector(std::move(c)), queue(options.queue_frames) {
    budget_kbps = options.max_kbps;
    counters.budget_kbps = options.max_kbps;
  }

  void SetError(const std::string& e) {
    std::lock_guard<std::mutex> lock(mutex);
    counters.last_error = e;
  }

  // Stats, KeyFrameRequest and Error, from the stream or a datagram (mutex held).
  void TakeDownlink(const v1::Downlink& d, bool on_stream) {
    if (d.has_stats()) {
      if (options.max_kbps > 0) {
        // A message on the stream costs the uplink its ACKs; a datagram nothing.
        if (on_stream) downlink_debt_bytes += options.downlink_overhead_bytes;
        // Frames sent but not yet decoded by the receiver: a backlog in the
        // network. More than ~0.3 s of frames: back off; otherwise recover.
        // Datagrams the network lost never arrive, so for them the backlog is
        // the datagrams neither received nor known lost, in frames.
        const double session_sent = static_cast<double>(counters.sent - sent_before_session);
        const double backlog =
            counters.datagrams_active && session_datagrams > 0
                ? (static_cast<double>(session_datagrams) - static_cast<double>(d.stats().datagrams_received()) -
                   static_cast<double>(d.stats().datagrams_lost())) *
                      session_sent / static_cast<double>(session_datagrams)
                : session_sent - static_cast<double>(d.stats().frames_received());
        // Datagrams are not queued but dropped where a link is overrun: more
        // than 5 % of them lost since the last Stats is congestion too (a few
        // lost on a noisy radio link are not).
        const uint64_t lost = d.stats().datagrams_lost() - std::min(d.stats().datagrams_lost(), stats_datagrams_lost);
        const uint64_t received =
            d.stats().datagrams_received() - std::min(d.stats().datagrams_received(), stats_datagrams_received);
        stats_datagrams_lost = d.stats().datagrams_lost();
        stats_datagrams_received = d.stats().datagrams_received();
        const bool lossy = lost > 0 && 20 * lost > lost + received;
        const double budget = budget_kbps.load();
        budget_kbps = backlog > 0.3 * options.fps || lossy ? std::max(1.0, budget * 0.7)
                                                           : std::min(options.max_kbps, budget * 1.05);
        counters.budget_kbps = budget_kbps;
      }
      counters.receiver_render_fps = d.stats().render_fps();
      counters.receiver_kbps = d.stats().receive_kbps();
      counters.receiver_frames = d.stats().frames_received();
      counters.receiver_bad = d.stats().frames_bad();
      counters.receiver_lost = d.stats().frames_lost();
      counters.receiver_late = d.stats().frames_late();
      counters.receiver_datagrams_lost = d.stats().datagrams_lost();
      if (counters.datagrams_active && d.stats().datagrams_received() == 0 && session_datagrams >= 3 &&
          first_datagram_s >= 0 && Seconds() - first_datagram_s > 2) {
        datagrams_blocked = true;
        key_frame_wanted = true;  // the stream's decoder must not follow a broken chain
      }
    } else if (d.has_key_frame_request()) {
      ++counters.key_frame_requests;
      key_frame_wanted = true;
    } else if (d.has_error()) {
      counters.last_error = d.error().message();
    }
  }

  // The datagram path the receiver offered in this session's Welcome, when the
  // options want one and it opens (with its key in *key); nullptr (and a
  // warning saying why) otherwise.
  std::unique_ptr<DatagramPath> OpenDatagramPath(DatagramKey* key) {
    if (!options.WantsDatagrams()) return nullptr;
    v1::DatagramOffer o;
    {
      std::lock_guard<std::mutex> lock(mutex);
      o = offer;
    }
    std::string why;
    std::unique_ptr<DatagramPath> path;
    if (o.port() == 0) {
      why = "the receiver offers none";
    } else if (o.port() > 65535) {
      why = "port " + std::to_string(o.port()) + " out of range";
    } else if (DatagramKey::FromBytes(o.connection_id(), o.key(), key, &why)) {
      path = connector->OpenDatagrams(static_cast<int>(o.port()), &why);
    }
    if (path)
      spdlog::info("sender: frames go as datagrams to UDP port {}", o.port());
    else
      spdlog::warn("sender: no datagrams ({}); frames go on the stream", why);
    std::lock_guard<std::mutex> lock(mutex);
    counters.datagrams_active = path != nullptr;
    return path;
  }

  // One session: returns when the stream breaks or we stop.
  void RunSession(UplinkChannel& stream) {
    const double session_start = Seconds();
    v1::Uplink hello;
    hello.mutable_hello()->set_protocol_version(kProtocolVersion);
    hello.mutable_hello()->set_avatar_id(options.avatar_id);
    hello.mutable_hello()->set_sender_name(options.sender_name);
    hello.mutable_hello()->set_stats_interval_s(options.stats_interval_s);
    hello.mutable_hello()->set_datagrams(options.WantsDatagrams());
    offer.Clear();
    session_datagrams = 0;
    first_datagram_s = -1;
    stats_datagrams_received = stats_datagrams_lost = 0;
    datagrams_blocked = false;
    key_frame_wanted = false;
    ToProto(layout, options.fps, hello.mutable_hello()->mutable_layout());
    session_rejection = v1::Reject::UNSPECIFIED;
    if (!stream.Write(hello)) {
      // The transport's status says why (refused, TLS verification, name): pass it on.
      stream.Cancel();
      const std::string why = stream.Finish();
      SetError("cannot reach the receiver at " + connector->Describe() + (why.empty() ? "" : ": " + why));
      return;
    }
    // Wait for Welcome or Reject (with a deadline: a silent receiver must not hang us).
    std::atomic<int> welcomed{0};  // 0 waiting, 1 welcomed, -1 refused/closed
    // The reader is owned: joined on every path, an exception included (the
    // guard cancels the stream first, so its Read returns).
    std::thread reader([&] {
      v1::Downlink d;
      while (stream.Read(&d)) {
        std::lock_guard<std::mutex> lock(mutex);
        if (d.has_welcome()) {
          offer = d.welcome().datagrams();
          welcomed = 1;
          ++counters.connects;  // counted here: a session may end before the sending side looks
          counters.streaming = true;
          cv.notify_all();
        } else if (d.has_reject()) {
          counters.last_rejection = v1::Reject::Reason_Name(d.reject().reason()) + ": " + d.reject().message();
          counters.last_error = counters.last_rejection;
          session_rejection = d.reject().reason();
          ++counters.rejections;
          welcomed = -1;
          cv.notify_all();
        } else {
          TakeDownlink(d, /*on_stream=*/true);
        }
      }
      std::lock_guard<std::mutex> lock(mutex);
      welcomed = -1;  // refused, or the stream ended: the send loop stops too
      counters.streaming = false;
      cv.notify_all();
    });
    struct JoinReader {
      UplinkChannel& stream;
      std::thread& reader;
      void Join() {
        if (!reader.joinable()) return;
        stream.Cancel();
        reader.join();
      }
      ~JoinReader() { Join(); }
    } join_reader{stream, reader};
    {
      std::unique_lock<std::mutex> lock(mutex);
      cv.wait_for(lock, std::chrono::duration<double>(options.welcome_timeout_s),
                  [&] { return welcomed != 0 || stop; });
    }
    if (welcomed == 1) spdlog::info("sender: streaming to {} (avatar '{}')", connector->Describe(), options.avatar_id);
    // Frames as datagrams when both ends want them; otherwise on the stream.
    DatagramKey key;
    std::unique_ptr<DatagramPath> path = welcomed == 1 ? OpenDatagramPath(&key) : nullptr;
    std::optional<DatagramDownlinkReader> datagram_reader;
    if (path)
      datagram_reader.emplace(*path, key, [this](const v1::Downlink& d) {
        std::lock_guard<std::mutex> lock(mutex);
        TakeDownlink(d, /*on_stream=*/false);
      });
    bool send_datagrams = path != nullptr;
    uint32_t datagram_counter = 0;
    ParamEncoder encoder(layout);  // a fresh chain per session: the first frame is a key frame
    {
      std::lock_guard<std::mutex> lock(mutex);
      sent_before_session = counters.sent;
    }
    // Capture times travel relative to the session's first frame (whole ms).
    std::optional<double> origin;
    double last_send = 0;
    // The budget starts in debt by the session's start-up (see session_start_bytes).
    double tokens = -static_cast<double>(options.session_start_bytes + options.wire_overhead_bytes +
                                         static_cast<int>(hello.ByteSizeLong())),
           token_time = session_start;
    bool first_message = true;
    while (welcomed == 1 && !stop) {
      auto first = queue.Pop(std::chrono::milliseconds(50));
      if (!first) continue;
      if (options.min_send_interval_s > 0) {
        const double wait = last_send + options.min_send_interval_s - Seconds();
        if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
      }
      if (options.max_kbps > 0) {
        // Token bucket in bytes, allowed to go into debt: wait until the last
        // message's real cost has been paid off at the budget rate.
        for (;;) {
          const double now = Seconds();
          const double budget = budget_kbps.load();
          tokens =
              std::min(tokens + (now - token_time) * budget * 125.0, static_cast<double>(options.wire_overhead_bytes));
          token_time = now;
          tokens -= downlink_debt_bytes.exchange(0);
          if (tokens >= 0 || stop) break;
          std::this_thread::sleep_for(std::chrono::duration<double>(-tokens / (budget * 125.0)));
        }
      }
      // Paced to a budget, a session's first message carries the newest frame
      // only: frames from before the link was ready would arrive late and show
      // nothing new.
      if (options.freshest_only || (first_message && options.max_kbps > 0)) {
        uint64_t skipped = 0;
        while (auto newer = queue.TryPop()) {
          first = std::move(newer);
          ++skipped;
        }
        if (skipped) {
          std::lock_guard<std::mutex> lock(mutex);
          counters.dropped += skipped;
        }
      }
      if (send_datagrams && datagrams_blocked) {
        spdlog::warn("sender: the receiver got none of {} datagrams (UDP blocked?); frames go on the stream",
                     session_datagrams);
        send_datagrams = false;
        std::lock_guard<std::mutex> lock(mutex);
        counters.datagrams_active = false;
      }
      if (key_frame_wanted.exchange(false)) encoder.ForceKeyFrame();
      if (!origin) origin = first->capture_time_s;
      std::vector<std::string> packets;
      std::vector<double> capture_times;
      packets.push_back(encoder.Encode(*first, *origin));
      capture_times.push_back(first->capture_time_s);
      while (!options.freshest_only && static_cast<int>(packets.size()) < options.max_batch) {
        auto more = queue.TryPop();
        if (!more) break;
        packets.push_back(encoder.Encode(*more, *origin));
        capture_times.push_back(more->capture_time_s);
      }
      first_message = false;
      last_send = Seconds();
      bool ok = true;
      uint64_t messages = 0, payload_bytes = 0, unsent = 0;
      if (send_datagrams) {
        // Each datagram stands alone on the wire; one the system refuses is
        // lost like one the network drops, and the receiver asks for a key frame.
        for (const v1::Frames& f : SplitForDatagrams(packets, capture_times)) {
          if (!path->Send(SealDatagram(key, DatagramDirection::kUplink, ++datagram_counter, f.SerializeAsString())))
            ++unsent;
          ++messages;
          payload_bytes += f.payload().size();
          if (options.max_kbps > 0) tokens -= options.datagram_overhead_bytes + f.payload().size();
        }
      } else {
        v1::Uplink up;
        *up.mutable_frames() = MakeFrames(packets, capture_times.front());
        messages = 1;
        payload_bytes = up.frames().payload().size();
        if (options.max_kbps > 0) tokens -= options.wire_overhead_bytes + payload_bytes;
        ok = stream.Write(up);
      }
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (ok) {
          counters.sent += packets.size();
          counters.messages += messages;
          counters.payload_bytes += payload_bytes;
          if (send_datagrams) {
            counters.datagrams += messages;
            counters.datagrams_unsent += unsent;
            session_datagrams += messages;
            if (first_datagram_s < 0) first_datagram_s = last_send;
          }
        }
        cv.notify_all();
      }
      if (!ok) {
        SetError("stream to " + connector->Describe() + " broke");
        break;
      }
    }
    if (welcomed == 1 && stop) {
      v1::Uplink bye;
      bye.mutable_bye()->set_reason(bye_reason);
      stream.Write(bye);
    }
    stream.CloseWrites();
    join_reader.Join();
    const std::string ended = stream.Finish();
    // After a Reject the call's status (CANCELLED, ...) would only hide the reason.
    if (!ended.empty() && !stop && session_rejection == v1::Reject::UNSPECIFIED) SetError(ended);
  }

  void GiveUp(const std::string& why) {
    spdlog::error("sender: {}; not retrying", why);
    std::lock_guard<std::mutex> lock(mutex);
    counters.gave_up = true;
    counters.streaming = false;
    cv.notify_all();
  }

  void Run() {
    double backoff = options.reconnect_initial_s;
    while (!stop) {
      const double started = Seconds();
      std::string error;
      std::unique_ptr<UplinkChannel> channel = connector->Open(&error);
      if (!channel) {
        SetError(error);
        GiveUp(error);
        return;
      }
      RunSession(*channel);
      channel.reset();
      if (stop) break;
      // Only a busy receiver may let us in later; every other refusal stands.
      if (session_rejection != v1::Reject::UNSPECIFIED && session_rejection != v1::Reject::BUSY) {
        GiveUp("the receiver refused the session: " + counters.last_rejection);
        return;
      }
      {
        std::lock_guard<std::mutex> lock(mutex);
        counters.streaming = false;
      }
      if (Seconds() - started > 2 * options.reconnect_max_s) backoff = options.reconnect_initial_s;  // it had worked
      spdlog::warn("sender: session ended ({}); retrying in {:.1f} s", counters.last_error, backoff);
      std::unique_lock<std::mutex> lock(mutex);
      cv.wait_for(lock, std::chrono::duration<double>(backoff), [&] { return stop.load(); });
      backoff = std::min(options.reconnect_max_s, backoff * 2);
    }
  }
};

SenderClient::SenderClient(SenderOptions options, CodecLayout layout)
    : SenderClient(options, std::move(layout), MakeGrpcUplinkConnector((options.Check(), options))) {}

SenderClient::SenderClient(SenderOptions options, CodecLayout layout, std::unique_ptr<UplinkConnector> connector) {
  options.Check();
  layout.Check();
  if (!connector) throw std::invalid_argument("SenderClient: no connector");
  impl_ = std::make_unique<Impl>(std::move(options), std::move(layout), std::move(connector));
}

SenderClient::~SenderClient() { Stop("sender closed"); }

void SenderClient::Start() {
  if (impl_->worker.joinable()) return;
  // Nothing may leave the worker as an exception (it would end the process):
  // a failure is recorded and ends the streaming.
  impl_->worker = std::thread([this] {
    try {
      impl_->Run();
    } catch (const std::exception& e) {
      impl_->SetError(std::string("sender stopped: ") + e.what());
      spdlog::error("sender stopped: {}", e.what());
      std::lock_guard<std::mutex> lock(impl_->mutex);
      impl_->counters.streaming = false;
      impl_->cv.notify_all();
    }
  });
}

void SenderClient::Submit(const FrameParams& frame) {
  std::string why;
  if (!frame.IsValid(&why)) {  // NaN or out-of-range parameters never reach the encoder
    std::lock_guard<std::mutex> lock(impl_->mutex);
    ++impl_->counters.invalid;
    impl_->counters.last_error = "frame " + std::to_string(frame.sequence) + " not sent: " + why;
    return;
  }
  const bool dropped = impl_->queue.Push(frame);
  std::lock_guard<std::mutex> lock(impl_->mutex);
  ++impl_->counters.submitted;
  if (dropped) ++impl_->counters.dropped;
}

void SenderClient::Stop(const std::string& reason) {
  if (!impl_) return;
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->bye_reason = reason;
    impl_->stop = true;
    impl_->cv.notify_all();
  }
  if (impl_->worker.joinable()) impl_->worker.join();
}

SenderCounters SenderClient::counters() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->counters;
}

bool SenderClient::WaitStreaming(double timeout_s) const {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  return impl_->cv.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return impl_->counters.streaming; });
}

bool SenderClient::Flush(double timeout_s) const {
  const double deadline = Seconds() + timeout_s;
  while (Seconds() < deadline) {
    {
      std::lock_guard<std::mutex> lock(impl_->mutex);
      const auto& c = impl_->counters;
      if (impl_->queue.size() == 0 && c.sent + c.dropped >= c.submitted) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

}  // namespace headcast
