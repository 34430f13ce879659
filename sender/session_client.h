// The sender's side of the protocol, free of any transport: Hello/Welcome,
// frames coded and sent as produced, several per message when the link is
// narrow, paced to a link budget, the oldest dropped when backlogged (latency
// never builds), reconnection with back-off. Each connection attempt opens a
// channel through an UplinkConnector: gRPC by default (sender/grpc_uplink.h),
// an in-memory channel in tests.
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include "common/codec/param_codec.h"
#include "common/headmodel/params.h"
#include "proto/message_channel.h"

namespace headcast {

struct SenderOptions {
  std::string target = "127.0.0.1:50051";  // receiver host:port
  std::string avatar_id = "default";
  std::string token;  // bearer token (sent as "authorization" metadata)
  std::string sender_name = "headcast-sender";
  bool plaintext = false;                       // only allowed for a loopback target
  std::string tls_ca;                           // PEM: CA that signed the receiver's certificate
  std::string tls_client_cert, tls_client_key;  // PEM: optional client certificate
  std::string tls_server_name;                  // override the name checked in the certificate
  double fps = 30;                              // capture rate, for the layout
  int queue_frames = 16;                        // frames waiting at most; older ones are dropped
  int max_batch = 16;                           // frames per message at most
  // Each message carries only the newest frame; those that waited behind it
  // are dropped (the receiver interpolates between what arrives). On a link
  // too narrow for every frame this trades parameter rate for latency: a
  // frame waits for the link, never for a batch to fill.
  bool freshest_only = false;
  double min_send_interval_s = 0;  // wait at least this long between messages (narrow links)
  // Link budget in kbit/s on the wire (0: none). Messages are paced to it, so
  // frames batch up (and the oldest are dropped) instead of queueing in the
  // network; it is lowered when the receiver reports a backlog and recovers slowly.
  double max_kbps = 0;
  // Bytes per message on the wire beyond the payload: the message's framing
  // (Ethernet, IP, TCP, TLS, HTTP/2, gRPC, proto) and the TCP ACK the sender
  // returns for the receiver's per-message HTTP/2 WINDOW_UPDATE (bench/DEFAULTS.md).
  int wire_overhead_bytes = 205;
  // Uplink bytes each downlink message (Stats) costs: the TCP ACK plus the HTTP/2
  // WINDOW_UPDATE gRPC answers with and its ACK (bench/DEFAULTS.md).
  int downlink_overhead_bytes = 180;
  // Uplink bytes a session costs on the wire before its Hello: the TCP and
  // TLS handshakes, the HTTP/2 preface and settings, the call's headers
  // (bench/DEFAULTS.md). Charged to the link budget with the Hello, so that on
  // a narrow link the first frames wait for the link instead of queueing
  // behind the start-up in the network for seconds.
  int session_start_bytes = 1400;
  // Frames as UDP datagrams when the receiver offers them (proto
  // DatagramOffer): "auto" on narrow links (a budget below kNarrowLinkKbps),
  // "on" always, "off" never. The stream stays for Hello, Stats and Bye.
  std::string datagrams = "auto";
  // Bytes per datagram on the wire beyond the payload: Ethernet, IP and UDP
  // headers, the datagram's header and tag, the Frames fields (bench/DEFAULTS.md).
  int datagram_overhead_bytes = 80;
  // How often we want Stats, seconds (0: the receiver's choice). Narrow links
  // ask for fewer: see NarrowLinkDefaults().
  double stats_interval_s = 0;
  double reconnect_initial_s = 0.1, reconnect_max_s = 1.0;  // back-off between attempts
  double welcome_timeout_s = 3;                             // Hello -> Welcome deadline
  double keepalive_s = 10;                                  // HTTP/2 ping interval while idle
  void Check() const;
  bool WantsDatagrams() const;  // what `datagrams` means for this budget
};

// Below this budget (kbit/s) the sender defaults to the narrow-link settings:
// Stats every kNarrowLinkStatsInterval seconds and a key frame every
// kNarrowLinkKeySeconds (TCP loses no message, so key frames only serve
// recovery, and each costs ~28 B more than a delta frame).
constexpr double kNarrowLinkKbps = 32;
constexpr double kNarrowLinkStatsInterval = 5;
constexpr double kNarrowLinkKeySeconds = 10;
// ... and quantises more coarsely: one step moves no vertex more than 0.5 mm
// (against 0.2 mm): real tracks then fit a narrow link, at a cost through the
// avatar measured in bench/results/narrow_links.md.
constexpr double kNarrowLinkQuantisationError = 5e-4;

struct SenderCounters {
  uint64_t submitted = 0, sent = 0, dropped = 0, invalid = 0, messages = 0, payload_bytes = 0, connects = 0,
           rejections = 0;
  bool streaming = false;  // welcomed and streaming now
  // Stopped trying: the receiver refused us for a reason that retrying cannot
  // heal (token, avatar, versions, layout), or the configuration is unusable.
  bool gave_up = false;
  std::string last_rejection;  // the receiver's reason, if it refused us
  std::string last_error;      // the last receiver Error or transport problem
  double receiver_render_fps = 0, receiver_kbps = 0;
  double budget_kbps = 0;  // the current pacing budget (max_kbps after adaptation)
  uint64_t receiver_frames = 0, receiver_bad = 0, receiver_lost = 0, receiver_late = 0;
  // Messages sent as datagrams (also in `messages`), those the system refused
  // to send, the receiver's count of datagrams lost and its key frame requests.
  uint64_t datagrams = 0, datagrams_unsent = 0, receiver_datagrams_lost = 0, key_frame_requests = 0;
  bool datagrams_active = false;  // this session's frames go as datagrams
};

// One session's datagram path to the receiver: sends sealed datagrams, never blocks.
class DatagramPath {
 public:
  virtual ~DatagramPath() = default;
  // False when the datagram could not be handed to the network (it is lost).
  virtual bool Send(const std::string& datagram) = 0;
  // Waits up to timeout_ms for a datagram from the receiver; false if none came.
  virtual bool Receive(std::string* datagram, int timeout_ms) = 0;
};

// Opens one session's channel to the receiver, once per connection attempt.
class UplinkConnector {
 public:
  virtual ~UplinkConnector() = default;
  // A channel, or nullptr with *error saying why: a configuration error
  // (unreadable TLS material, say) after which the client stops trying.
  virtual std::unique_ptr<UplinkChannel> Open(std::string* error) = 0;
  virtual std::string Describe() const = 0;  // where it connects, for messages
  // A datagram path to `port` on the receiver's host, or nullptr with *error
  // (this transport has none, the address cannot be used).
  virtual std::unique_ptr<DatagramPath> OpenDatagrams(int port, std::string* error) {
    (void)port;
    *error = "this transport carries no datagrams";
    return nullptr;
  }
};

class SenderClient {
 public:
  // Over gRPC to options.target (TLS or plaintext, keepalive, the bearer token as metadata).
  SenderClient(SenderOptions options, CodecLayout layout);
  // Over whatever `connector` opens.
  SenderClient(SenderOptions options, CodecLayout layout, std::unique_ptr<UplinkConnector> connector);
  ~SenderClient();  // stops
  void Start();     // connects in the background and keeps reconnecting
  // Never blocks: queues the frame, dropping the oldest if the queue is full.
  // Invalid frames (NaN, out of range) are counted and not sent.
  void Submit(const FrameParams& frame);
  // Sends Bye (if streaming) and stops.
  void Stop(const std::string& reason = "done");
  SenderCounters counters() const;
  // Blocks until streaming (welcomed) or the timeout; true if streaming.
  bool WaitStreaming(double timeout_s) const;
  // Blocks until the queue is empty and everything queued was written, or the timeout.
  bool Flush(double timeout_s) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headcast
