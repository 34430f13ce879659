// Sessions end to end through real gRPC on 127.0.0.1: every frame arrives in
// order within the quantisation step; bad input ends only the session that
// sent it; eight concurrent sessions; a receiver restart is survived.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <thread>

#include "common/headmodel/synthetic_motion.h"
#include "proto/convert.h"
#include "proto/headcast.grpc.pb.h"
#include "proto/protocol.h"
#include "receiver/session_server.h"
#include "sender/session_client.h"
#include "tests/integration/session_helpers.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Model() { return testing::SessionModel(); }
const CodecLayout& Layout() { return testing::SessionLayout(); }

ReceiverServerOptions ServerOptions(int port = 0) {
  ReceiverServerOptions o;
  o.listen = "127.0.0.1:" + std::to_string(port);
  o.plaintext = true;
  o.tokens = {"secret-token"};
  o.stats_interval_s = 0.2;
  return o;
}

std::map<std::string, AvatarEntry> Avatars() { return testing::SessionAvatars(); }

SenderOptions ClientOptions(int port) {
  SenderOptions o;
  o.target = "127.0.0.1:" + std::to_string(port);
  o.plaintext = true;
  o.token = "secret-token";
  o.avatar_id = "demo";
  o.queue_frames = 1000;  // tests want every frame; the product default drops
  return o;
}

// Collects decoded frames per session.
struct Collector {
  std::mutex mutex;
  std::map<std::string, std::vector<FrameParams>> frames;
  void operator()(const std::string& id, const FrameParams& f) {
    std::lock_guard<std::mutex> lock(mutex);
    frames[id].push_back(f);
  }
  size_t Total() {
    std::lock_guard<std::mutex> lock(mutex);
    size_t n = 0;
    for (auto& [id, v] : frames) n += v.size();
    return n;
  }
};

using testing::WaitFor;

class SessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = std::make_unique<ReceiverServer>(ServerOptions(), Avatars());
    server_->SetFrameObserver([this](const std::string& id, const FrameParams& f) { collector_(id, f); });
    server_->Start();
  }
  // A raw stream with a hand-made Hello, to send what a good sender would not.
  struct RawSession {
    std::unique_ptr<v1::Headcast::Stub> stub;
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<v1::Uplink, v1::Downlink>> stream;
  };
  std::unique_ptr<RawSession> Raw(const std::string& token = "secret-token") {
    auto r = std::make_unique<RawSession>();
    r->stub = v1::Headcast::NewStub(
        grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
    if (!token.empty()) r->context.AddMetadata("authorization", "Bearer " + token);
    r->context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    r->stream = r->stub->Session(&r->context);
    return r;
  }
  static v1::Uplink Hello(uint32_t version = kProtocolVersion, const std::string& avatar = "demo") {
    v1::Uplink u;
    u.mutable_hello()->set_protocol_version(version);
    u.mutable_hello()->set_avatar_id(avatar);
    ToProto(Layout(), 30, u.mutable_hello()->mutable_layout());
    return u;
  }
  // Sends Hello and returns the first reply.
  v1::Downlink HelloReply(RawSession* r, const v1::Uplink& hello) {
    EXPECT_TRUE(r->stream->Write(hello));
    v1::Downlink d;
    EXPECT_TRUE(r->stream->Read(&d));
    return d;
  }
  // The server still serves a normal session afterwards.
  void ExpectServerStillServes() {
    SenderClient client(ClientOptions(server_->port()), Layout());
    client.Start();
    ASSERT_TRUE(client.WaitStreaming(5)) << client.counters().last_error;
    const size_t before = collector_.Total();
    for (int i = 0; i < 5; ++i) client.Submit(SyntheticTalkingHead(Model(), i));
    EXPECT_TRUE(WaitFor([&] { return collector_.Total() >= before + 5; }, 5));
  }
  // The collector outlives the server: a session may still be delivering
  // frames while the server shuts down (a sender cancels its stream right
  // after Bye, and the receiver drains what it already holds).
  Collector collector_;
  std::unique_ptr<ReceiverServer> server_;
};

// Streams 120 frames (and two invalid ones) with `options` and checks that
// every valid frame arrived once, in order, within the quantisation step.
void StreamAndCheck(Collector& collector, const SenderOptions& options, SenderCounters* counters) {
  SenderClient client(options, Layout());
  client.Start();
  ASSERT_TRUE(client.WaitStreaming(5)) << client.counters().last_error;
  std::vector<FrameParams> sent;
  for (int i = 0; i < 120; ++i) {
    sent.push_back(SyntheticTalkingHead(Model(), i));
    client.Submit(sent.back());
    if (i % 10 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  // NaN and infinite parameters never leave the sender.
  FrameParams nan_frame = sent.back(), inf_frame = sent.back();
  nan_frame.expression[2] = std::nanf("");
  inf_frame.cam_translation.x() = std::numeric_limits<float>::infinity();
  client.Submit(nan_frame);
  client.Submit(inf_frame);
  ASSERT_TRUE(client.Flush(10));
  ASSERT_TRUE(WaitFor([&] { return collector.Total() >= 120; }, 10));
  EXPECT_EQ(client.counters().invalid, 2u);
  const SenderCounters c = client.counters();
  client.Stop("test done");
  std::lock_guard<std::mutex> lock(collector.mutex);
  ASSERT_EQ(collector.frames.size(), 1u);
  const auto& got = collector.frames.begin()->second;
  ASSERT_EQ(got.size(), 120u);
  const CodecLayout& l = Layout();
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].sequence, i);
    // Capture times travel in whole milliseconds (twice rounded: frame and batch origin).
    EXPECT_NEAR(got[i].capture_time_s, sent[i].capture_time_s - sent[0].capture_time_s, 0.0011);
    for (size_t k = 0; k < l.expression_components.size(); ++k)
      EXPECT_LE(std::abs(got[i].expression[k] - sent[i].expression[k]), 0.5f * l.steps[k] + 1e-6f);
    EXPECT_LE((got[i].cam_translation - sent[i].cam_translation).cwiseAbs().maxCoeff(),
              0.5f * l.steps[l.expression_components.size() + 17] + 1e-6f);
    EXPECT_LE((got[i].jaw - sent[i].jaw).cwiseAbs().maxCoeff(), 0.5f * l.steps[l.expression_components.size()] + 1e-6f);
  }
  EXPECT_EQ(c.sent, 120u);
  EXPECT_EQ(c.dropped, 0u);
  EXPECT_LE(c.messages, 120u);
  *counters = c;
}

TEST_F(SessionTest, EveryFrameArrivesInOrderWithinTheStep) {
  SenderOptions o = ClientOptions(server_->port());
  o.datagrams = "off";
  SenderCounters c;
  StreamAndCheck(collector_, o, &c);
  EXPECT_EQ(c.datagrams, 0u);
}

// The same over UDP beside the stream: the receiver's datagram port (the
// gRPC port's number when free), sealed datagrams, Stats back as datagrams.
TEST_F(SessionTest, EveryFrameArrivesAsDatagramsOnTheirOwnSocket) {
  ASSERT_GT(server_->datagram_port(), 0);
  SenderOptions o = ClientOptions(server_->port());
  o.datagrams = "on";
  SenderCounters c;
  StreamAndCheck(collector_, o, &c);
  EXPECT_TRUE(c.datagrams_active);
  EXPECT_GT(c.datagrams, 0u);
  EXPECT_EQ(c.datagrams_unsent, 0u);
  EXPECT_EQ(server_->counters().datagrams_received, c.datagrams);
  EXPECT_EQ(server_->counters().datagrams_refused, 0u);
}

// A receiver without datagrams (--no-datagrams, or an older one) offers none:
// the sender keeps its frames on the stream.
TEST(ReceiverServer, WithoutDatagramsFramesStayOnTheStream) {
  ReceiverServerOptions so = ServerOptions();
  so.datagrams = false;
  ReceiverServer server(so, Avatars());
  server.Start();
  EXPECT_EQ(server.datagram_port(), 0);
  SenderOptions o = ClientOptions(server.port());
  o.datagrams = "on";
  SenderClient client(o, Layout());
  client.Start();
  ASSERT_TRUE(client.WaitStreaming(5)) << client.counters().last_error;
  for (int i = 0; i < 10; ++i) client.Submit(SyntheticTalkingHead(Model(), i));
  ASSERT_TRUE(client.Flush(5));
  EXPECT_TRUE(WaitFor([&] { return client.counters().receiver_frames == 10; }, 5));
  EXPECT_FALSE(client.counters().datagrams_active);
  EXPECT_EQ(client.counters().datagrams, 0u);
  client.Stop();
}

// Narrow links ask for fewer Stats: the receiver takes the larger interval
// (never below its own, at most a minute) and says which in Welcome.
TEST_F(SessionTest, StatsComeAsOftenAsTheSenderAsked) {
  auto raw = Raw();
  v1::Uplink hello = Hello();
  hello.mutable_hello()->set_stats_interval_s(0.6);
  v1::Downlink d = HelloReply(raw.get(), hello);
  ASSERT_TRUE(d.has_welcome());
  EXPECT_DOUBLE_EQ(d.welcome().stats_interval_s(), 0.6);
  const auto start = std::chrono::steady_clock::now();
  int stats = 0;
  while (stats < 3 && raw->stream->Read(&d))
    if (d.has_stats()) ++stats;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(stats, 3);
  EXPECT_GT(seconds, 1.6);  // three at 0.6 s, not at the server's 0.2 s
  raw->context.TryCancel();
  for (double asked : {0.01, std::nan(""), 1e9}) {
    auto r = Raw();
    v1::Uplink h = Hello();
    h.mutable_hello()->set_stats_interval_s(asked);
    const v1::Downlink w = HelloReply(r.get(), h);
    ASSERT_TRUE(w.has_welcome());
    EXPECT_DOUBLE_EQ(w.welcome().stats_interval_s(), asked > 1e6 ? 60.0 : 0.2) << asked;
    r->context.TryCancel();
  }
}

TEST_F(SessionTest, RefusalsSayWhy) {
  struct Case {
    std::string token;
    v1::Uplink hello;
    v1::Reject::Reason reason;
    std::string text;
  };
  v1::Uplink bad_layout = Hello();
  bad_layout.mutable_hello()->mutable_layout()->set_steps(0, std::nanf(""));
  v1::Uplink wrong_size = Hello();
  wrong_size.mutable_hello()->mutable_layout()->set_num_expression(53);
  v1::Uplink huge = Hello();  // reported as sent, not as clamped
  huge.mutable_hello()->mutable_layout()->set_num_expression(4000000000u);
  v1::Uplink not_hello;
  not_hello.mutable_frames()->set_payload("x");
  // Another model with the same number of expression components, and a sender that names none.
  v1::Uplink other_model = Hello();
  other_model.mutable_hello()->mutable_layout()->set_head_model_fingerprint("another-model-0123");
  v1::Uplink no_model = Hello();
  no_model.mutable_hello()->mutable_layout()->clear_head_model_fingerprint();
  const std::vector<Case> cases = {
      {"secret-token", Hello(2), v1::Reject::PROTOCOL_VERSION, "protocol version 2"},
      {"secret-token", Hello(kProtocolVersion, "nobody"), v1::Reject::UNKNOWN_AVATAR, "no avatar 'nobody'"},
      {"", Hello(), v1::Reject::UNAUTHENTICATED, "no bearer token"},
      {"guess", Hello(), v1::Reject::UNAUTHENTICATED, "wrong bearer token"},
      {"secret-token", bad_layout, v1::Reject::BAD_LAYOUT, "step"},
      {"secret-token", wrong_size, v1::Reject::BAD_LAYOUT, "avatar 'demo' has 13"},
      {"secret-token", not_hello, v1::Reject::PROTOCOL, "must start with Hello"},
      {"secret-token", huge, v1::Reject::BAD_LAYOUT, "num_expression 4000000000 is out of range"},
      {"secret-token", other_model, v1::Reject::BAD_LAYOUT, "fits head model another-model-0123"},
      {"secret-token", no_model, v1::Reject::BAD_LAYOUT, "names no head model"},
  };
  for (const Case& c : cases) {
    auto raw = Raw(c.token);
    const v1::Downlink d = HelloReply(raw.get(), c.hello);
    ASSERT_TRUE(d.has_reject()) << c.text;
    EXPECT_EQ(d.reject().reason(), c.reason) << c.text;
    EXPECT_NE(d.reject().message().find(c.text), std::string::npos) << d.reject().message();
  }
  EXPECT_EQ(server_->counters().sessions_rejected, cases.size());
  ExpectServerStillServes();
}

TEST_F(SessionTest, BadFramesAreRefusedAndTheSessionGoesOn) {
  auto raw = Raw();
  ASSERT_TRUE(HelloReply(raw.get(), Hello()).has_welcome());
  ParamEncoder encoder(Layout());
  const std::string good = encoder.Encode(SyntheticTalkingHead(Model(), 0));
  // A truncated packet, garbage bytes, a value out of range (cam 500 m away).
  FrameParams far = SyntheticTalkingHead(Model(), 1);
  far.cam_translation.z() = 500;
  ParamEncoder far_encoder(Layout());
  for (const std::string& payload :
       {PackPackets({good}).substr(0, 4), std::string("\x07garbage", 8), PackPackets({far_encoder.Encode(far)})}) {
    v1::Uplink u;
    u.mutable_frames()->set_payload(payload);
    u.mutable_frames()->set_count(1);
    ASSERT_TRUE(raw->stream->Write(u));
  }
  v1::Uplink u;
  u.mutable_frames()->set_payload(PackPackets({good}));
  u.mutable_frames()->set_count(1);
  ASSERT_TRUE(raw->stream->Write(u));
  ASSERT_TRUE(WaitFor([&] { return collector_.Total() >= 1; }, 5));
  int errors = 0;
  v1::Downlink d;
  while (errors < 3 && raw->stream->Read(&d))
    if (d.has_error()) ++errors;
  EXPECT_EQ(errors, 3);
  // The sender vanishes mid-stream (no Bye): the session ends, the server lives on.
  raw->context.TryCancel();
  raw.reset();
  ASSERT_TRUE(WaitFor([&] { return server_->Sessions().empty(); }, 5));
  EXPECT_GE(server_->counters().frames_bad, 3u);
  ExpectServerStillServes();
}

TEST_F(SessionTest, GarbageBytesOnTheStreamEndOnlyThatSession) {
  auto channel =
      grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials());
  grpc::GenericStub generic(channel);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer secret-token");
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::CompletionQueue cq;
  auto call = generic.PrepareCall(&context, "/headcast.v1.Headcast/Session", &cq);
  void* tag;
  bool ok;
  call->StartCall(reinterpret_cast<void*>(1));
  ASSERT_TRUE(cq.Next(&tag, &ok));
  const char bytes[] = "\xff\xfe\x00 not a protobuf \x01\x02\x03";
  grpc::Slice junk(bytes, sizeof bytes - 1);  // the bytes without the literal's closing zero
  grpc::ByteBuffer buffer(&junk, 1);
  call->Write(buffer, reinterpret_cast<void*>(2));
  ASSERT_TRUE(cq.Next(&tag, &ok));
  call->WritesDone(reinterpret_cast<void*>(3));
  cq.Next(&tag, &ok);
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(4));
  while (cq.Next(&tag, &ok) && tag != reinterpret_cast<void*>(4)) {
  }
  EXPECT_FALSE(status.ok());
  ExpectServerStillServes();
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
}

TEST_F(SessionTest, EightConcurrentSessions) {
  std::vector<std::unique_ptr<SenderClient>> clients;
  for (int c = 0; c < 8; ++c) {
    SenderOptions o = ClientOptions(server_->port());
    o.sender_name = "client" + std::to_string(c);
    clients.push_back(std::make_unique<SenderClient>(o, Layout()));
    clients.back()->Start();
  }
  for (auto& c : clients) ASSERT_TRUE(c->WaitStreaming(10)) << c->counters().last_error;
  EXPECT_EQ(server_->Sessions().size(), 8u);
  for (int i = 0; i < 30; ++i) {
    for (int c = 0; c < 8; ++c) {
      SyntheticMotionOptions m;
      m.seed = c + 1;
      clients[c]->Submit(SyntheticTalkingHead(Model(), i, m));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
  }
  for (auto& c : clients) EXPECT_TRUE(c->Flush(10));
  ASSERT_TRUE(WaitFor([&] { return collector_.Total() >= 240; }, 10));
  std::lock_guard<std::mutex> lock(collector_.mutex);
  EXPECT_EQ(collector_.frames.size(), 8u);
  for (auto& [id, frames] : collector_.frames) EXPECT_EQ(frames.size(), 30u) << id;
}

TEST_F(SessionTest, SenderStreamsAgainWithinTwoSecondsOfAReceiverRestart) {
  const int port = server_->port();
  SenderClient client(ClientOptions(port), Layout());
  client.Start();
  ASSERT_TRUE(client.WaitStreaming(5));
  client.Submit(SyntheticTalkingHead(Model(), 0));
  ASSERT_TRUE(WaitFor([&] { return collector_.Total() >= 1; }, 5));
  server_->Shutdown();  // the receiver dies
  ASSERT_TRUE(WaitFor([&] { return !client.counters().streaming; }, 5));
  server_ = std::make_unique<ReceiverServer>(ServerOptions(port), Avatars());
  server_->SetFrameObserver([this](const std::string& id, const FrameParams& f) { collector_(id, f); });
  const auto restarted = std::chrono::steady_clock::now();
  server_->Start();
  // Frames keep coming from the capture side; streaming must resume quickly.
  int i = 1;
  const size_t before = collector_.Total();
  ASSERT_TRUE(WaitFor(
      [&] {
        client.Submit(SyntheticTalkingHead(Model(), i++));
        return collector_.Total() > before;
      },
      5));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - restarted).count();
  EXPECT_LT(seconds, 2.0);
  EXPECT_GE(client.counters().connects, 2u);
  RecordProperty("restart_to_streaming_s", std::to_string(seconds));
}

TEST(ReceiverServerOptions, RefuseInsecureSetups) {
  ReceiverServerOptions o = ServerOptions();
  o.listen = "0.0.0.0:50051";
  EXPECT_THROW(o.Check(), std::invalid_argument);  // plaintext off loopback
  o = ServerOptions();
  o.tokens.clear();
  EXPECT_THROW(o.Check(), std::invalid_argument);  // no tokens
  o.allow_no_token = true;
  EXPECT_NO_THROW(o.Check());
  SenderOptions s = ClientOptions(1);
  s.target = "10.0.0.1:50051";
  EXPECT_THROW(s.Check(), std::invalid_argument);
  EXPECT_TRUE(IsLoopbackAddress("127.0.0.1:5"));
  EXPECT_TRUE(IsLoopbackAddress("[::1]:5"));
  EXPECT_TRUE(IsLoopbackAddress("localhost:5"));
  EXPECT_FALSE(IsLoopbackAddress("128.0.0.1:5"));
  // A name is not an address: these would carry the token in clear text off the machine.
  EXPECT_FALSE(IsLoopbackAddress("127.attacker.example:5"));
  EXPECT_FALSE(IsLoopbackAddress("127.0.0.1.nip.io:5"));
  EXPECT_FALSE(IsLoopbackAddress("[::ffff:10.0.0.1]:5"));
  s.target = "127.attacker.example:50051";
  EXPECT_THROW(s.Check(), std::invalid_argument);
}

std::string CheckMessage(const std::function<void()>& check) {
  try {
    check();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "accepted";
}

TEST(ReceiverServerOptions, AddressesNeedAPortInRange) {
  for (const char* listen : {"127.0.0.1:99999", "127.0.0.1", "[::1]", "::1:50051", ":50051", "127.0.0.1:5x"}) {
    ReceiverServerOptions o = ServerOptions();
    o.listen = listen;
    const std::string message = CheckMessage([&] { o.Check(); });
    EXPECT_NE(message.find("is not host:port"), std::string::npos) << listen << ": " << message;
  }
  for (const char* listen : {"127.0.0.1:0", "[::1]:50051", "localhost:65535"}) {
    ReceiverServerOptions o = ServerOptions();
    o.listen = listen;
    EXPECT_EQ(CheckMessage([&] { o.Check(); }), "accepted") << listen;
  }
  SenderOptions s = ClientOptions(1);
  s.target = "127.0.0.1";  // gRPC would quietly dial port 443
  EXPECT_NE(CheckMessage([&] { s.Check(); }).find("no port"), std::string::npos);
}

TEST(SenderOptions, MissingTlsFilesAreRefusedBeforeConnecting) {
  SenderOptions s = ClientOptions(50051);
  s.plaintext = false;
  s.tls_ca = "/nonexistent/ca.pem";
  EXPECT_NE(CheckMessage([&] { s.Check(); }).find("cannot read /nonexistent/ca.pem"), std::string::npos);
  const std::string dir = testing::TempDir("tlsfiles");
  std::ofstream(dir + "/ca.pem") << "x";
  s.tls_ca = dir + "/ca.pem";
  EXPECT_EQ(CheckMessage([&] { s.Check(); }), "accepted");
  s.tls_client_cert = dir + "/ca.pem";  // a certificate without its key
  EXPECT_NE(CheckMessage([&] { s.Check(); }).find("go together"), std::string::npos);
  // The client refuses at construction, not in its worker thread.
  EXPECT_THROW(SenderClient(s, Layout()), std::invalid_argument);
}

TEST(TokenFile, LineEndingsCommentsAndBlanksAreNotTokens) {
  const std::string dir = testing::TempDir("tokens");
  std::ofstream(dir + "/crlf.txt", std::ios::binary)
      << "# made with openssl rand -hex 16\r\n\r\n  0123456789abcdef0123  \r\n   \r\nfedcba9876543210\r\n";
  EXPECT_EQ(ReadTokenFile(dir + "/crlf.txt"), (std::vector<std::string>{"0123456789abcdef0123", "fedcba9876543210"}));
  auto refusal = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir + "/" + name, std::ios::binary) << content;
    try {
      ReadTokenFile(dir + "/" + name);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(refusal("short.txt", "0123456789abcdef\nshort\n").find("short.txt: line 2: a token needs at least 16"),
            std::string::npos);
  EXPECT_NE(refusal("empty.txt", "# only a comment\n\n").find("no token"), std::string::npos);
  EXPECT_NE(refusal("binary.txt", std::string("\x7f"
                                              "ELF\x01\x00\x00garbage-garbage-garbage",
                                              27))
                .find("printable"),
            std::string::npos);
  EXPECT_NE(refusal("spaces.txt", "0123456789 abcdef0123\n").find("printable ASCII without blanks"), std::string::npos);
}

int ProcessThreads() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("Threads:", 0) == 0) return std::stoi(line.substr(8));
  return -1;
}

TEST(ReceiverServer, StreamsThatNeverSayHelloHoldBoundedThreadsBriefly) {
  ReceiverServerOptions o = ServerOptions();
  o.max_sessions = 4;
  o.hello_timeout_s = 1;
  ReceiverServer server(o, Avatars());
  server.Start();
  const int before = ProcessThreads();
  auto stub = v1::Headcast::NewStub(
      grpc::CreateChannel("127.0.0.1:" + std::to_string(server.port()), grpc::InsecureChannelCredentials()));
  struct Mute {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<v1::Uplink, v1::Downlink>> stream;
  };
  std::vector<std::unique_ptr<Mute>> mutes(100);
  for (auto& m : mutes) {
    m = std::make_unique<Mute>();
    m->context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    m->stream = stub->Session(&m->context);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  // gRPC's client side adds a few threads of its own; the server may add at most its quota.
  EXPECT_LT(ProcessThreads() - before, MaxServerThreads(o) + 8);
  // Every one is refused (thread quota) or closed at the Hello deadline (the
  // server cancels it), long before the client's own 20 s deadline.
  const auto start = std::chrono::steady_clock::now();
  int closed = 0;
  for (auto& m : mutes) {
    v1::Downlink d;
    while (m->stream->Read(&d)) {
    }
    closed += !m->stream->Finish().ok();
  }
  EXPECT_EQ(closed, 100);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 5.0);
  EXPECT_GT(server.counters().hello_timeouts, 0u);
}

TEST(ReceiverServer, ABusyPortIsRefused) {
  ReceiverServer first(ServerOptions(), Avatars());
  first.Start();
  ReceiverServer second(ServerOptions(first.port()), Avatars());
  EXPECT_THROW(second.Start(), std::runtime_error);
}

}  // namespace
}  // namespace headcast
