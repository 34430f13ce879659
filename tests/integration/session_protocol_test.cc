// The protocol without sockets: the real SenderClient and ReceiverSessions
// joined by in-memory channels — streaming, rejection, the session limit,
// reconnection after a broken link, narrow-link pacing, and a failing frame
// observer that ends only its own session.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <deque>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>

#include "common/headmodel/synthetic_motion.h"
#include "proto/convert.h"
#include "proto/datagram.h"
#include "proto/protocol.h"
#include "receiver/receiver_sessions.h"
#include "sender/session_client.h"
#include "tests/integration/session_helpers.h"

namespace headcast {
namespace {

const HeadModel& Model() { return testing::SessionModel(); }
const CodecLayout& Layout() { return testing::SessionLayout(); }

ReceiverSessionOptions ReceiverOptions(int max_sessions = 4) {
  ReceiverSessionOptions o;
  o.tokens = {"secret-token"};
  o.stats_interval_s = 0.1;
  o.max_sessions = max_sessions;
  return o;
}

std::map<std::string, AvatarEntry> Avatars() { return testing::SessionAvatars(); }

SenderOptions Options() {
  SenderOptions o;
  o.target = "127.0.0.1:0";  // not dialled: the in-memory connector ignores it
  o.plaintext = true;
  o.avatar_id = "demo";
  o.queue_frames = 1000;
  o.reconnect_initial_s = 0.05;
  o.reconnect_max_s = 0.1;
  return o;
}

using testing::WaitFor;

// A datagram network in memory between senders and `receiver`: uplink
// datagrams go straight into TakeDatagram unless `lose` says the network lost
// them; the receiver's answers queue for the path they are addressed to.
class InMemoryDatagrams {
 public:
  explicit InMemoryDatagrams(ReceiverSessions& receiver) : receiver_(receiver) {
    receiver.EnableDatagrams(4242, [this](const std::string& peer, const std::string& d) {
      std::lock_guard<std::mutex> lock(mutex_);
      inbox_[peer].push_back(d);
      ++answers_;
      cv_.notify_all();
      return true;
    });
  }
  // Given the uplink datagram's index (from 0, over every path): true to lose it.
  std::function<bool(int)> lose = [](int) { return false; };

  class Path : public DatagramPath {
   public:
    Path(InMemoryDatagrams& net, std::string name) : net_(net), name_(std::move(name)) {}
    bool Send(const std::string& d) override {
      int index = 0;
      {
        std::lock_guard<std::mutex> lock(net_.mutex_);
        index = net_.sent_++;
        net_.uplink_.push_back(d);
      }
      if (!net_.lose(index)) net_.receiver_.TakeDatagram(d, name_);
      return true;
    }
    bool Receive(std::string* d, int timeout_ms) override {
      std::unique_lock<std::mutex> lock(net_.mutex_);
      auto& q = net_.inbox_[name_];
      if (!net_.cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] { return !q.empty(); })) return false;
      *d = q.front();
      q.pop_front();
      return true;
    }

   private:
    InMemoryDatagrams& net_;
    std::string name_;
  };
  std::unique_ptr<DatagramPath> Open(int port) {
    EXPECT_EQ(port, 4242);
    std::lock_guard<std::mutex> lock(mutex_);
    return std::make_unique<Path>(*this, "peer" + std::to_string(paths_++));
  }
  std::vector<std::string> uplink() {
    std::lock_guard<std::mutex> lock(mutex_);
    return uplink_;
  }
  int answers() {
    std::lock_guard<std::mutex> lock(mutex_);
    return answers_;
  }

 private:
  ReceiverSessions& receiver_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::map<std::string, std::deque<std::string>> inbox_;
  std::vector<std::string> uplink_;
  int sent_ = 0, paths_ = 0, answers_ = 0;
};

// Each Open makes a channel pair and serves the receiver's end on its own
// thread, as a transport adapter would. Break() cuts the current link.
class InMemoryConnector : public UplinkConnector {
 public:
  InMemoryConnector(ReceiverSessions& receiver, std::string token, InMemoryDatagrams* datagrams = nullptr)
      : receiver_(receiver), token_(std::move(token)), datagrams_(datagrams) {}
  ~InMemoryConnector() override {
    for (auto& t : threads_) t.join();
  }
  std::unique_ptr<UplinkChannel> Open(std::string*) override {
    InMemoryChannelPair pair = MakeInMemoryChannelPair(token_);
    std::shared_ptr<DownlinkChannel> end(std::move(pair.receiver));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      current_ = end;
      ++opened_;
    }
    threads_.emplace_back([this, end] {
      const SessionEnd e = receiver_.Serve(*end);
      end->CloseWrites();  // the end of the call, as gRPC's status would end it
      std::lock_guard<std::mutex> lock(mutex_);
      ends_.push_back(e);
    });
    return std::move(pair.sender);
  }
  std::string Describe() const override { return "in-memory"; }
  std::unique_ptr<DatagramPath> OpenDatagrams(int port, std::string* error) override {
    if (!datagrams_) return UplinkConnector::OpenDatagrams(port, error);
    return datagrams_->Open(port);
  }
  void Break() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (current_) current_->Cancel();
  }
  std::vector<SessionEnd> ends() {
    std::lock_guard<std::mutex> lock(mutex_);
    return ends_;
  }
  int opened() {
    std::lock_guard<std::mutex> lock(mutex_);
    return opened_;
  }

 private:
  ReceiverSessions& receiver_;
  std::string token_;
  InMemoryDatagrams* datagrams_;
  std::mutex mutex_;
  std::shared_ptr<DownlinkChannel> current_;
  std::vector<SessionEnd> ends_;
  std::vector<std::thread> threads_;
  int opened_ = 0;
};

struct Client {
  Client(ReceiverSessions& receiver, const std::string& token, const SenderOptions& o = Options(),
         InMemoryDatagrams* datagrams = nullptr, const CodecLayout& layout = Layout()) {
    auto c = std::make_unique<InMemoryConnector>(receiver, token, datagrams);
    connector = c.get();
    client = std::make_unique<SenderClient>(o, layout, std::move(c));
  }
  InMemoryConnector* connector;  // owned by the client
  std::unique_ptr<SenderClient> client;
};

// Keeps every frame `receiver` decodes.
struct Collector {
  explicit Collector(ReceiverSessions& receiver) {
    receiver.SetFrameObserver([this](const std::string&, const FrameParams& f) {
      std::lock_guard<std::mutex> lock(mutex);
      frames.push_back(f);
    });
  }
  std::mutex mutex;
  std::vector<FrameParams> frames;
  size_t size() {
    std::lock_guard<std::mutex> lock(mutex);
    return frames.size();
  }
};

TEST(SessionProtocol, FramesArriveInOrderAndStatsComeBack) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Collector got(receiver);
  Client c(receiver, "secret-token");
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5)) << c.client->counters().last_error;
  ASSERT_EQ(receiver.Sessions().size(), 1u);
  for (int i = 0; i < 60; ++i) {
    FrameParams f = SyntheticTalkingHead(Model(), i);
    f.sequence = static_cast<uint64_t>(i);
    c.client->Submit(f);
  }
  ASSERT_TRUE(WaitFor([&] { return got.size() == 60; }, 5)) << got.size();
  for (int i = 0; i < 60; ++i) {
    EXPECT_EQ(got.frames[i].sequence, static_cast<uint64_t>(i));
    const FrameParams truth = SyntheticTalkingHead(Model(), i);
    EXPECT_LT((got.frames[i].expression - truth.expression).cwiseAbs().maxCoeff(), 0.05);
  }
  EXPECT_TRUE(WaitFor([&] { return c.client->counters().receiver_frames == 60; }, 5)) << "Stats report the frames";
  c.client->Stop("test over");
  EXPECT_TRUE(WaitFor([&] { return receiver.Sessions().empty(); }, 5));
  EXPECT_EQ(receiver.counters().frames_received, 60u);
}

TEST(SessionProtocol, WrongTokenUnknownAvatarAndOldVersionsAreRejected) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Client wrong(receiver, "guess");
  wrong.client->Start();
  EXPECT_FALSE(wrong.client->WaitStreaming(0.5));
  // A refusal that retrying cannot heal ends the client's attempts, with the receiver's reason.
  EXPECT_TRUE(WaitFor([&] { return wrong.client->counters().gave_up; }, 5));
  EXPECT_NE(wrong.client->counters().last_rejection.find("UNAUTHENTICATED"), std::string::npos)
      << wrong.client->counters().last_rejection;
  EXPECT_EQ(wrong.client->counters().last_error, wrong.client->counters().last_rejection);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));  // several back-off periods
  EXPECT_EQ(wrong.connector->opened(), 1);
  EXPECT_EQ(wrong.client->counters().rejections, 1u);
  wrong.client->Stop();
  ASSERT_FALSE(wrong.connector->ends().empty());
  EXPECT_EQ(wrong.connector->ends()[0].code, SessionEndCode::kUnauthenticated);

  SenderOptions o = Options();
  o.avatar_id = "nobody";
  Client unknown(receiver, "secret-token", o);
  unknown.client->Start();
  EXPECT_TRUE(WaitFor([&] { return unknown.client->counters().gave_up; }, 5));
  EXPECT_NE(unknown.client->counters().last_rejection.find("UNKNOWN_AVATAR"), std::string::npos);
  unknown.client->Stop();
  EXPECT_EQ(unknown.connector->opened(), 1);

  // A hand-made Hello of another protocol version.
  InMemoryChannelPair pair = MakeInMemoryChannelPair("secret-token");
  std::thread serve([&] { EXPECT_EQ(receiver.Serve(*pair.receiver).code, SessionEndCode::kFailedPrecondition); });
  v1::Uplink hello;
  hello.mutable_hello()->set_protocol_version(99);
  ASSERT_TRUE(pair.sender->Write(hello));
  v1::Downlink reply;
  ASSERT_TRUE(pair.sender->Read(&reply));
  ASSERT_TRUE(reply.has_reject());
  EXPECT_NE(reply.reject().message().find("version 99"), std::string::npos);
  serve.join();
  EXPECT_EQ(receiver.counters().sessions_rejected, 3u);  // one attempt each: no retries
  EXPECT_EQ(receiver.counters().sessions_started, 0u);
}

TEST(SessionProtocol, TheSessionOverTheLimitIsRefusedAndTheReceiverGoesOn) {
  ReceiverSessions receiver(ReceiverOptions(/*max_sessions=*/1), Avatars());
  Client first(receiver, "secret-token");
  first.client->Start();
  ASSERT_TRUE(first.client->WaitStreaming(5));
  Client second(receiver, "secret-token");
  second.client->Start();
  ASSERT_TRUE(WaitFor([&] { return !second.client->counters().last_rejection.empty(); }, 5))
      << "the busy path must answer, not hang";
  EXPECT_NE(second.client->counters().last_rejection.find("BUSY"), std::string::npos);
  // Busy heals: the second sender keeps trying with back-off.
  EXPECT_TRUE(WaitFor([&] { return second.client->counters().rejections >= 2; }, 5));
  EXPECT_FALSE(second.client->counters().gave_up);
  // The receiver is not stuck: it lists sessions and the first one still streams.
  EXPECT_EQ(receiver.Sessions().size(), 1u);
  first.client->Submit(SyntheticTalkingHead(Model(), 0));
  EXPECT_TRUE(WaitFor([&] { return first.client->counters().sent == 1; }, 5));
  second.client->Stop();
  first.client->Stop();
  EXPECT_TRUE(WaitFor([&] { return receiver.Sessions().empty(); }, 5));
  EXPECT_EQ(receiver.counters().frames_received, 1u);
}

TEST(SessionProtocol, StreamsWithoutHelloAndSilentSessionsAreClosed) {
  ReceiverSessionOptions o = ReceiverOptions();
  o.hello_timeout_s = 0.3;
  o.idle_timeout_s = 0.6;
  ReceiverSessions receiver(o, Avatars());
  // A client that connects and never says Hello holds nothing for long.
  InMemoryChannelPair mute = MakeInMemoryChannelPair("secret-token");
  SessionEnd mute_end;
  std::thread mute_serve([&] { mute_end = receiver.Serve(*mute.receiver); });
  // An authenticated client that says Hello, then nothing.
  InMemoryChannelPair idle = MakeInMemoryChannelPair("secret-token");
  SessionEnd idle_end;
  std::thread idle_serve([&] { idle_end = receiver.Serve(*idle.receiver); });
  v1::Uplink hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  hello.mutable_hello()->set_avatar_id("demo");
  ToProto(Layout(), 30, hello.mutable_hello()->mutable_layout());
  ASSERT_TRUE(idle.sender->Write(hello));
  const auto start = std::chrono::steady_clock::now();
  mute_serve.join();
  const double mute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(mute_end.code, SessionEndCode::kDeadlineExceeded) << mute_end.message;
  EXPECT_LT(mute_s, 2.0);
  EXPECT_EQ(receiver.Sessions().size(), 1u);
  idle_serve.join();
  EXPECT_EQ(idle_end.code, SessionEndCode::kDeadlineExceeded) << idle_end.message;
  EXPECT_TRUE(receiver.Sessions().empty());
  EXPECT_EQ(receiver.counters().hello_timeouts, 1u);
  EXPECT_EQ(receiver.counters().idle_timeouts, 1u);
  // A sender that keeps streaming is not idle, however long it runs.
  Client c(receiver, "secret-token");
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  for (int i = 0; i < 40; ++i) {
    c.client->Submit(SyntheticTalkingHead(Model(), i));
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  }
  EXPECT_EQ(c.client->counters().connects, 1u);
  EXPECT_EQ(receiver.counters().idle_timeouts, 1u);
  c.client->Stop();
}

TEST(SessionProtocol, AFullReceiverLetsANewSenderDisplaceASilentSession) {
  ReceiverSessionOptions o = ReceiverOptions();
  o.max_sessions = 1;
  o.idle_timeout_s = 0;  // only the displacement may end the silent session
  o.evict_silent_s = 0.3;
  ReceiverSessions receiver(o, Avatars());
  // An authenticated session that says Hello, then nothing, holds the only slot.
  InMemoryChannelPair silent = MakeInMemoryChannelPair("secret-token");
  SessionEnd silent_end;
  std::thread silent_serve([&] { silent_end = receiver.Serve(*silent.receiver); });
  v1::Uplink hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  hello.mutable_hello()->set_avatar_id("demo");
  ToProto(Layout(), 30, hello.mutable_hello()->mutable_layout());
  ASSERT_TRUE(silent.sender->Write(hello));
  ASSERT_TRUE(WaitFor([&] { return receiver.Sessions().size() == 1; }, 5));
  // A sender arriving before the silence is long enough is refused BUSY...
  Client early(receiver, "secret-token");
  early.client->Start();
  EXPECT_TRUE(WaitFor([&] { return early.client->counters().rejections >= 1; }, 5));
  early.client->Stop();
  EXPECT_EQ(receiver.counters().evictions, 0u);
  // ...one arriving after it takes the slot, and the silent session is told why it ended.
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  Client real(receiver, "secret-token");
  real.client->Start();
  ASSERT_TRUE(real.client->WaitStreaming(5));
  silent_serve.join();
  EXPECT_EQ(silent_end.code, SessionEndCode::kDeadlineExceeded) << silent_end.message;
  EXPECT_NE(silent_end.message.find("new sender"), std::string::npos) << silent_end.message;
  EXPECT_EQ(receiver.counters().evictions, 1u);
  EXPECT_EQ(receiver.counters().idle_timeouts, 0u);
  real.client->Submit(SyntheticTalkingHead(Model(), 0));
  EXPECT_TRUE(WaitFor([&] { return real.client->counters().sent == 1; }, 5));
  const auto shown = receiver.Sessions();
  ASSERT_EQ(shown.size(), 1u);
  EXPECT_NE(shown[0].id, "s1");
  // A streaming session is never displaced: the next sender is refused.
  Client late(receiver, "secret-token");
  late.client->Start();
  int frame = 1;
  EXPECT_TRUE(WaitFor(
      [&] {
        real.client->Submit(SyntheticTalkingHead(Model(), frame++));  // keeps streaming meanwhile
        return late.client->counters().rejections >= 1;
      },
      5));
  late.client->Stop();
  EXPECT_EQ(receiver.counters().evictions, 1u);
  real.client->Stop();
}

TEST(SessionProtocol, ABrokenLinkIsReconnected) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Client c(receiver, "secret-token");
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  c.connector->Break();
  ASSERT_TRUE(WaitFor([&] { return c.client->counters().connects >= 2; }, 5))
      << "connects " << c.client->counters().connects << ", " << c.client->counters().last_error;
  EXPECT_GE(c.connector->opened(), 2);
  c.client->Submit(SyntheticTalkingHead(Model(), 1));
  EXPECT_TRUE(WaitFor([&] { return c.client->counters().sent == 1; }, 5));
  c.client->Stop();
}

TEST(SessionProtocol, ANarrowLinkBatchesFramesWithinTheBudget) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  SenderOptions o = Options();
  o.max_kbps = 4;  // 500 B/s: about two messages a second with their wire overhead
  o.stats_interval_s = 5;
  o.session_start_bytes = 0;  // in memory: no handshakes
  Client c(receiver, "secret-token", o);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < 90; ++i) {  // 3 s at 30 fps
    c.client->Submit(SyntheticTalkingHead(Model(), i));
    std::this_thread::sleep_until(start + std::chrono::milliseconds(33 * (i + 1)));
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const SenderCounters n = c.client->counters();
  c.client->Stop();
  ASSERT_GT(n.messages, 0u);
  const double frames_per_message = static_cast<double>(n.sent) / n.messages;
  const double wire_kbps = 8e-3 * (n.payload_bytes + n.messages * o.wire_overhead_bytes) / seconds;
  EXPECT_GT(frames_per_message, 4) << n.sent << " frames in " << n.messages << " messages";
  EXPECT_LT(wire_kbps, 1.3 * o.max_kbps) << "paced to the budget";
  EXPECT_EQ(n.submitted, 90u);
  EXPECT_GT(n.sent, 45u) << "the budget carries 30 fps in batches";
}

TEST(SessionProtocol, FreshestOnlySendsOneNewFramePerMessageAndDropsTheRest) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  SenderOptions o = Options();
  o.max_kbps = 4;
  o.stats_interval_s = 5;
  o.freshest_only = true;
  o.session_start_bytes = 0;
  Client c(receiver, "secret-token", o);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < 90; ++i) {
    c.client->Submit(SyntheticTalkingHead(Model(), i));
    std::this_thread::sleep_until(start + std::chrono::milliseconds(33 * (i + 1)));
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const SenderCounters n = c.client->counters();
  c.client->Stop();
  ASSERT_GT(n.messages, 2u);
  EXPECT_EQ(n.sent, n.messages) << "one frame per message";
  EXPECT_GT(n.dropped, 45u) << "the frames the budget cannot carry are skipped, not queued";
  const double wire_kbps = 8e-3 * (n.payload_bytes + n.messages * o.wire_overhead_bytes) / seconds;
  EXPECT_LT(wire_kbps, 1.3 * o.max_kbps) << "paced to the budget";
  // Every frame sent arrives (none is lost for being alone in its message).
  ASSERT_TRUE(WaitFor([&] { return receiver.counters().frames_received >= n.sent; }, 5));
}

TEST(SessionProtocol, ANarrowLinkPaysForTheSessionsStartBeforeItsFirstFrame) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Collector collector(receiver);
  SenderOptions o = Options();
  o.max_kbps = 8;  // 1000 B/s
  o.stats_interval_s = 5;
  o.session_start_bytes = 1000;  // with the Hello and a message's overhead: over 1.2 s of the budget
  Client c(receiver, "secret-token", o);
  const auto start = std::chrono::steady_clock::now();
  c.client->Start();
  std::atomic<double> first_arrival_s{-1};
  std::thread watch([&] {
    if (WaitFor([&] { return collector.size() > 0; }, 10))
      first_arrival_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  });
  for (int i = 0; i < 75; ++i) {  // 2.5 s at 30 fps
    c.client->Submit(SyntheticTalkingHead(Model(), i));
    std::this_thread::sleep_until(start + std::chrono::milliseconds(33 * (i + 1)));
  }
  watch.join();
  const SenderCounters n = c.client->counters();
  c.client->Stop();
  EXPECT_GT(first_arrival_s.load(), 1.1) << "the start-up's bytes are paid for first";
  std::lock_guard<std::mutex> lock(collector.mutex);
  ASSERT_FALSE(collector.frames.empty());
  EXPECT_GE(collector.frames.front().sequence, 30u) << "the first message carries the newest frame, not the oldest";
  EXPECT_GE(n.dropped, 30u);
}

// A hand-driven session: Hello, then whatever the test writes; the receiver
// serves it on its own thread.
struct RawSession {
  RawSession(ReceiverSessions& receiver, v1::Uplink hello) : pair(MakeInMemoryChannelPair("secret-token")) {
    serve = std::thread([this, &receiver] {
      end = receiver.Serve(*pair.receiver);
      pair.receiver->CloseWrites();
    });
    pair.sender->Write(hello);
    pair.sender->Read(&first_reply);
  }
  ~RawSession() {
    pair.sender->CloseWrites();
    serve.join();
  }
  static v1::Uplink Hello(const std::string& avatar = "demo", const std::string& name = "raw") {
    v1::Uplink u;
    u.mutable_hello()->set_protocol_version(kProtocolVersion);
    u.mutable_hello()->set_avatar_id(avatar);
    u.mutable_hello()->set_sender_name(name);
    ToProto(Layout(), 30, u.mutable_hello()->mutable_layout());
    return u;
  }
  // The next Error the receiver sends back.
  std::string NextError() {
    v1::Downlink d;
    while (pair.sender->Read(&d))
      if (d.has_error()) return d.error().message();
    return "(stream ended)";
  }
  InMemoryChannelPair pair;
  v1::Downlink first_reply;
  SessionEnd end;
  std::thread serve;
};

TEST(SessionProtocol, EmptyPacketsWrongCountsAndAbsurdTimesAreRefused) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Collector got(receiver);
  RawSession raw(receiver, RawSession::Hello());
  ASSERT_TRUE(raw.first_reply.has_welcome());
  ParamEncoder encoder(Layout());
  const std::string good = encoder.Encode(SyntheticTalkingHead(Model(), 0));
  auto frames = [](const std::string& payload, uint32_t count, double first_capture = 0) {
    v1::Uplink u;
    u.mutable_frames()->set_payload(payload);
    u.mutable_frames()->set_count(count);
    u.mutable_frames()->set_first_capture_time_s(first_capture);
    return u;
  };
  // A megabyte of zero-length packets: refused as a whole, nothing stored for them.
  raw.pair.sender->Write(frames(std::string(1 << 20, '\0'), 1 << 20));
  EXPECT_NE(raw.NextError().find("empty packet"), std::string::npos);
  raw.pair.sender->Write(frames(PackPackets({good}), 3));
  EXPECT_NE(raw.NextError().find("says 3 frames and carries 1"), std::string::npos);
  raw.pair.sender->Write(frames(PackPackets({good}), 1, std::numeric_limits<double>::infinity()));
  EXPECT_NE(raw.NextError().find("not a time"), std::string::npos);
  raw.pair.sender->Write(frames(PackPackets({good}), 1, 1e300));
  EXPECT_NE(raw.NextError().find("not a time"), std::string::npos);
  EXPECT_EQ(got.size(), 0u);
  // The session goes on: a good frame is taken.
  raw.pair.sender->Write(frames(PackPackets({good}), 1));
  EXPECT_TRUE(WaitFor([&] { return got.size() == 1; }, 5));
}

TEST(SessionProtocol, WhatARejectOrALogLineRepeatsIsBounded) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  const std::string huge = std::string(100000, 'x') + "\nforged log line";
  RawSession unknown(receiver, RawSession::Hello(huge));
  ASSERT_TRUE(unknown.first_reply.has_reject());
  const std::string& message = unknown.first_reply.reject().message();
  EXPECT_LT(message.size(), 400u) << "a 100 kB avatar id comes back bounded";
  EXPECT_EQ(message.find('\n'), std::string::npos);
  EXPECT_NE(message.find("more bytes"), std::string::npos) << message;
  RawSession named(receiver, RawSession::Hello("demo", "evil\nname" + std::string(5000, 'y')));
  ASSERT_TRUE(named.first_reply.has_welcome());
  ASSERT_EQ(receiver.Sessions().size(), 1u);
  const std::string shown = receiver.Sessions()[0].sender_name;
  EXPECT_LT(shown.size(), 100u);
  EXPECT_EQ(shown.rfind("evil?name", 0), 0u) << shown;
}

TEST(SessionProtocol, AFailingObserverEndsOnlyItsSession) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  std::atomic<bool> fail{true};
  receiver.SetFrameObserver([&](const std::string&, const FrameParams&) {
    if (fail) throw std::runtime_error("disk full");
  });
  Client c(receiver, "secret-token");
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  c.client->Submit(SyntheticTalkingHead(Model(), 0));
  ASSERT_TRUE(WaitFor([&] { return !c.connector->ends().empty(); }, 5));
  EXPECT_EQ(c.connector->ends()[0].code, SessionEndCode::kInternal);
  EXPECT_NE(c.connector->ends()[0].message.find("disk full"), std::string::npos);
  fail = false;  // the sender reconnects and streams again
  ASSERT_TRUE(WaitFor([&] { return c.client->counters().connects >= 2; }, 5));
  c.client->Submit(SyntheticTalkingHead(Model(), 1));
  EXPECT_TRUE(WaitFor([&] { return c.client->counters().sent == 2; }, 5));
  c.client->Flush(2);
  c.client->Stop();
  EXPECT_TRUE(WaitFor([&] { return receiver.Sessions().empty(); }, 5));
  EXPECT_GE(receiver.counters().frames_received, 1u);
}

// Frames submitted a few milliseconds apart, so that most go alone (one per datagram).
void SubmitSpaced(SenderClient& client, int first, int count) {
  for (int i = first; i < first + count; ++i) {
    FrameParams f = SyntheticTalkingHead(Model(), i);
    f.sequence = static_cast<uint64_t>(i);
    client.Submit(f);
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
  }
}

// Every decoded frame is the frame of its sequence number, within half a
// quantisation step, and no number comes twice: never garbage.
void ExpectTrueFrames(Collector& got) {
  const CodecLayout& l = Layout();
  std::lock_guard<std::mutex> lock(got.mutex);
  for (size_t i = 0; i < got.frames.size(); ++i) {
    const FrameParams& f = got.frames[i];
    if (i > 0) EXPECT_GT(f.sequence, got.frames[i - 1].sequence);
    const FrameParams truth = SyntheticTalkingHead(Model(), static_cast<int>(f.sequence));
    for (size_t k = 0; k < l.expression_components.size(); ++k)
      EXPECT_LE(std::abs(f.expression[k] - truth.expression[k]), 0.5f * l.steps[k] + 1e-6f)
          << "frame " << f.sequence << " component " << k;
    EXPECT_LE((f.cam_translation - truth.cam_translation).cwiseAbs().maxCoeff(),
              0.5f * l.steps[l.expression_components.size() + 17] + 1e-6f)
        << "frame " << f.sequence;
  }
}

SenderOptions DatagramOptions() {
  SenderOptions o = Options();
  o.datagrams = "on";
  return o;
}

TEST(SessionDatagrams, FramesGoAsDatagramsAndStatsComeBackTheSameWay) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  InMemoryDatagrams net(receiver);
  Collector got(receiver);
  Client c(receiver, "secret-token", DatagramOptions(), &net);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5)) << c.client->counters().last_error;
  SubmitSpaced(*c.client, 0, 60);
  ASSERT_TRUE(WaitFor([&] { return got.size() == 60; }, 5)) << got.size();
  ExpectTrueFrames(got);
  for (size_t i = 0; i < 60; ++i) EXPECT_EQ(got.frames[i].sequence, i);
  EXPECT_TRUE(WaitFor([&] { return c.client->counters().receiver_frames == 60; }, 5));
  const SenderCounters n = c.client->counters();
  EXPECT_TRUE(n.datagrams_active);
  EXPECT_EQ(n.datagrams, n.messages);
  EXPECT_EQ(receiver.counters().datagrams_received, n.datagrams);
  EXPECT_GT(net.answers(), 0) << "Stats came back as datagrams";
  c.client->Stop();
}

// A lost datagram breaks the delta chain: the frames after it are passed
// over (never decoded against the wrong reference) until the key frame the
// receiver asks for, and then every frame comes again.
TEST(SessionDatagrams, ALostDatagramCostsFramesUntilTheKeyFrameItAsksFor) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  InMemoryDatagrams net(receiver);
  net.lose = [](int i) { return i == 10 || i == 11; };
  Collector got(receiver);
  CodecLayout layout = Layout();
  layout.key_frame_interval = 100000;  // no periodic key frame comes to the rescue
  Client c(receiver, "secret-token", DatagramOptions(), &net, layout);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  SubmitSpaced(*c.client, 0, 80);
  ASSERT_TRUE(WaitFor([&] { return got.size() > 0 && got.frames.back().sequence == 79; }, 5));
  ASSERT_TRUE(WaitFor([&] { return c.client->counters().key_frame_requests >= 1; }, 5));
  ExpectTrueFrames(got);
  const size_t n = got.size();
  EXPECT_LT(n, 78u) << "frames after the gap waited for a key frame";
  EXPECT_GT(n, 40u) << "and then came again";
  EXPECT_TRUE(WaitFor([&] { return c.client->counters().receiver_datagrams_lost == 2; }, 5));
  EXPECT_EQ(receiver.counters().frames_bad, 0u) << "a gap is not corruption";
  c.client->Stop();
}

TEST(SessionDatagrams, ReplayedForgedAndForeignDatagramsAreRefusedAndTheSessionGoesOn) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  InMemoryDatagrams net(receiver);
  Collector got(receiver);
  Client c(receiver, "secret-token", DatagramOptions(), &net);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  SubmitSpaced(*c.client, 0, 10);
  ASSERT_TRUE(WaitFor([&] { return got.size() == 10; }, 5));
  const std::vector<std::string> seen = net.uplink();
  ASSERT_FALSE(seen.empty());
  EXPECT_FALSE(receiver.TakeDatagram(seen.front(), "attacker")) << "a replay";
  std::string forged = seen.back();
  forged[forged.size() / 2] ^= 0x10;
  EXPECT_FALSE(receiver.TakeDatagram(forged, "attacker"));
  // Well formed, under a key of its own: an unknown connection.
  EXPECT_FALSE(
      receiver.TakeDatagram(SealDatagram(DatagramKey::Random(), DatagramDirection::kUplink, 1000, "x"), "attacker"));
  EXPECT_FALSE(receiver.TakeDatagram(std::string(5, '\x01'), "attacker"));
  EXPECT_FALSE(receiver.TakeDatagram({}, "attacker"));
  EXPECT_EQ(receiver.counters().datagrams_refused, 5u);
  SubmitSpaced(*c.client, 10, 10);
  ASSERT_TRUE(WaitFor([&] { return got.size() == 20; }, 5)) << "the session goes on";
  ExpectTrueFrames(got);
  EXPECT_EQ(receiver.counters().frames_bad, 0u);
  c.client->Stop();
}

// UDP blocked on the way (a firewall): the receiver's Stats, which still come
// on the stream, say nothing arrived, and the frames go back to the stream.
TEST(SessionDatagrams, WhenNoDatagramArrivesFramesGoBackToTheStream) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  InMemoryDatagrams net(receiver);
  net.lose = [](int) { return true; };
  Collector got(receiver);
  Client c(receiver, "secret-token", DatagramOptions(), &net);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  // Numbered on across the retries: a loaded machine takes several rounds
  // before the sender gives up on datagrams, and each frame keeps its own number.
  int next = 0;
  ASSERT_TRUE(WaitFor(
      [&] {
        SubmitSpaced(*c.client, next, 5);
        next += 5;
        return !c.client->counters().datagrams_active;
      },
      6));
  const size_t before = got.size();
  SubmitSpaced(*c.client, next, 10);
  ASSERT_TRUE(WaitFor([&] { return got.size() >= before + 10; }, 5)) << got.size();
  ExpectTrueFrames(got);
  EXPECT_EQ(receiver.counters().datagrams_received, 0u);
  c.client->Stop();
}

// The codec's chain bits wrap after 32 packets; the datagram counter sees a
// gap of any length: the frames after it wait for a key frame (asked for as a
// datagram to where the session's datagrams come from) and are never decoded
// against the wrong reference.
TEST(SessionDatagrams, AGapOfAWholeChainWaitsForTheKeyFrameItAsksFor) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  std::mutex mutex;
  std::vector<std::string> answers;
  receiver.EnableDatagrams(4242, [&](const std::string&, const std::string& d) {
    std::lock_guard<std::mutex> lock(mutex);
    answers.push_back(d);
    return true;
  });
  Collector got(receiver);
  v1::Uplink hello = RawSession::Hello();
  hello.mutable_hello()->set_datagrams(true);
  RawSession raw(receiver, hello);
  ASSERT_TRUE(raw.first_reply.has_welcome());
  const v1::DatagramOffer& offer = raw.first_reply.welcome().datagrams();
  EXPECT_EQ(offer.port(), 4242u);
  DatagramKey key;
  std::string why;
  ASSERT_TRUE(DatagramKey::FromBytes(offer.connection_id(), offer.key(), &key, &why)) << why;
  CodecLayout layout = Layout();
  layout.key_frame_interval = 100000;
  ParamEncoder encoder(layout);
  auto datagram = [&](int frame) {
    FrameParams f = SyntheticTalkingHead(Model(), frame);
    f.sequence = static_cast<uint64_t>(frame);
    v1::Frames m;
    m.set_payload(PackPackets({encoder.Encode(f)}));
    m.set_count(1);
    return SealDatagram(key, DatagramDirection::kUplink, static_cast<uint32_t>(frame + 1), m.SerializeAsString());
  };
  EXPECT_TRUE(receiver.TakeDatagram(datagram(0), "peer"));
  for (int i = 1; i <= 32; ++i) datagram(i);  // 32 datagrams lost: the chain bits wrap around
  EXPECT_TRUE(receiver.TakeDatagram(datagram(33), "peer")) << "authentic, so taken";
  EXPECT_TRUE(receiver.TakeDatagram(datagram(34), "peer"));
  ASSERT_TRUE(WaitFor(
      [&] {
        std::lock_guard<std::mutex> lock(mutex);
        return !answers.empty();
      },
      5));
  v1::Downlink request;
  {
    std::lock_guard<std::mutex> lock(mutex);
    uint32_t counter = 0;
    std::string plaintext;
    ASSERT_TRUE(OpenDatagram(key, DatagramDirection::kDownlink, answers.front(), &counter, &plaintext, &why)) << why;
    ASSERT_TRUE(request.ParseFromString(plaintext));
  }
  ASSERT_TRUE(request.has_key_frame_request()) << "the answer went to the datagram's peer";
  EXPECT_EQ(request.key_frame_request().last_sequence(), 0u);
  EXPECT_EQ(got.size(), 1u) << "frames 33 and 34 were not decoded against frame 0";
  encoder.ForceKeyFrame();
  EXPECT_TRUE(receiver.TakeDatagram(datagram(35), "peer"));
  ASSERT_TRUE(WaitFor([&] { return got.size() == 2; }, 5));
  ExpectTrueFrames(got);
}

// An overrun link drops datagrams rather than queueing them: the receiver's
// count of lost ones lowers the sender's budget as a backlog would.
TEST(SessionDatagrams, ManyLostDatagramsLowerTheBudget) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  InMemoryDatagrams net(receiver);
  net.lose = [](int i) { return i % 3 == 0; };
  Collector got(receiver);
  SenderOptions o = DatagramOptions();
  o.max_kbps = 16;
  o.session_start_bytes = 0;
  // Until the first datagram arrives Stats come on the stream and cost the
  // budget their ACKs: not ten a second on a narrow link.
  o.stats_interval_s = 0.5;
  Client c(receiver, "secret-token", o, &net);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  for (int i = 0; i < 150 && c.client->counters().budget_kbps >= 16; ++i) SubmitSpaced(*c.client, 5 * i, 5);
  EXPECT_LT(c.client->counters().budget_kbps, 16) << c.client->counters().receiver_datagrams_lost << " lost";
  EXPECT_GT(c.client->counters().receiver_datagrams_lost, 0u);
  ExpectTrueFrames(got);
  c.client->Stop();
}

// A receiver that offers no datagrams (none enabled): frames stay on the stream.
TEST(SessionDatagrams, WithoutAnOfferFramesStayOnTheStream) {
  ReceiverSessions receiver(ReceiverOptions(), Avatars());
  Collector got(receiver);
  InMemoryDatagrams* none = nullptr;
  Client c(receiver, "secret-token", DatagramOptions(), none);
  c.client->Start();
  ASSERT_TRUE(c.client->WaitStreaming(5));
  SubmitSpaced(*c.client, 0, 10);
  ASSERT_TRUE(WaitFor([&] { return got.size() == 10; }, 5));
  EXPECT_FALSE(c.client->counters().datagrams_active);
  EXPECT_EQ(c.client->counters().datagrams, 0u);
  c.client->Stop();
}

}  // namespace
}  // namespace headcast
